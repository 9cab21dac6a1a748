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
