"""modelica/ArmExo follows the Modelica Standard Library layout."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2] / "modelica" / "ArmExo"
MO_FILES = sorted(ROOT.rglob("*.mo"))


@pytest.mark.parametrize("path", MO_FILES, ids=[str(p.relative_to(ROOT)) for p in MO_FILES])
def test_one_class_per_file_starting_with_within(path):
    text = path.read_text()
    first = next(line for line in text.splitlines() if line.strip())
    rel = path.relative_to(ROOT.parent)
    parent = ".".join(rel.parts[:-2] if path.name == "package.mo" else rel.parts[:-1])
    assert first.strip() == (f"within {parent};" if parent else "within;")
    name = path.parent.name if path.name == "package.mo" else path.stem
    assert re.search(rf"^end {name};\s*$", text, re.M), f"{path.name} must end with 'end {name};'"


@pytest.mark.parametrize("pkg", sorted({p.parent for p in MO_FILES}), ids=lambda p: str(p.relative_to(ROOT.parent)))
def test_package_order_lists_every_class(pkg):
    order = (pkg / "package.order").read_text().split()
    classes = {p.stem for p in pkg.glob("*.mo") if p.name != "package.mo"} | {d.name for d in pkg.iterdir() if (d / "package.mo").exists()}
    assert sorted(order) == sorted(classes)


def test_examples_have_experiment_annotations():
    for path in (ROOT / "Examples").glob("*.mo"):
        if path.name != "package.mo":
            assert "experiment(" in path.read_text(), path.name


def test_lugre_documentation_cites_canudas_de_wit():
    assert "Canudas de Wit" in (ROOT / "Components" / "LuGreFriction.mo").read_text()


def test_omc_export_says_clearly_when_omc_is_missing(monkeypatch):
    from fmus import export_omc

    monkeypatch.setattr(export_omc.shutil, "which", lambda name: None)
    with pytest.raises(export_omc.OmcNotFound, match="python -m fmus.build"):
        export_omc.export_fmu()
    script = export_omc.mos_script("ArmExo.ArmExoPlant", Path("/x/ArmExo/package.mo"))
    assert 'buildModelFMU(ArmExo.ArmExoPlant, version = "2.0", fmuType = "cs"' in script


@pytest.mark.slow
@pytest.mark.skipif(__import__("shutil").which("omc") is None, reason="OpenModelica (omc) not installed")
def test_omc_export_validates(tmp_path):
    from fmpy.validation import validate_fmu

    from fmus import export_omc

    fmu = export_omc.export_fmu(tmp_path)
    assert validate_fmu(str(fmu)) == []
