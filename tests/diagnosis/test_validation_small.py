"""A small validation in the default suite: withheld effects diagnosed blind.

Three sets of two 10 s trials (one per joint) made by the project's simulator; the
diagnosis tries a reduced list of effects to stay within the suite's time budget (the
full catalogue is validated by bench/bench_diagnosis.py).
"""

import json
import shutil

import pytest

pytest.importorskip("orchestrator")

from diagnosis import VERDICT_EFFECT, VERDICT_NONE, DiagnosisConfig, diagnose  # noqa: E402
from diagnosis.catalogue import relative_parameter_error  # noqa: E402
from diagnosis.validation import SetSpec, make_set, read_truth  # noqa: E402

CONFIG = DiagnosisConfig(effects=("gravity", "sensor_noise", "friction"),
                         grid_points=4, refine_iterations=4)
SPECS = {
    "nominal": SetSpec("nominal", (), seeds=(41,), duration_s=10.0, resolution_level=1),
    "gravity": SetSpec("gravity", (("gravity", {"tilt_deg": 3.0}),), seeds=(43,),
                       duration_s=10.0),
    "sensor_noise": SetSpec("sensor_noise", (("sensor_noise", {"theta_noise_std_rad": 1.5e-5,
                                                               "tau_noise_std_nm": 0.01}),),
                            seeds=(47,), duration_s=10.0),
}


@pytest.fixture(scope="module")
def sets(tmp_path_factory):
    root = tmp_path_factory.mktemp("validation")
    return {name: make_set(spec, root) for name, spec in SPECS.items()}


@pytest.fixture(scope="module")
def reports(sets, tmp_path_factory):
    out = tmp_path_factory.mktemp("reports")
    return {name: diagnose(folder, out / name, config=CONFIG, progress=False)
            for name, folder in sets.items()}


def test_nothing_withheld_raises_no_alarm(reports):
    assert reports["nominal"].verdict == VERDICT_NONE
    assert reports["nominal"].named == []


@pytest.mark.parametrize("name", ["gravity", "sensor_noise"])
def test_withheld_effect_is_named_fitted_and_closes_the_held_out_gap(name, reports, sets):
    report = reports[name]
    truth = read_truth(sets[name])["effects"][0]
    assert report.verdict == VERDICT_EFFECT
    assert report.named == [truth["name"]]
    errors = relative_parameter_error(name, report.fitted[name], truth["params"],
                                      scored_only=True)
    assert max(errors.values()) <= 0.2, (report.fitted, truth)
    assert report.gap["named_held_out_reduction"] >= 0.7


def test_report_folder_has_page_json_and_plots(reports, tmp_path_factory):
    report = reports["gravity"]
    saved = json.loads((report_dir(report)).joinpath("report.json").read_text())
    assert saved["verdict"] == report.verdict
    assert saved["named_effects"] == ["gravity"]
    for png in ("gap_where.png", "gap_ranking.png", "frf_compare.png", "noise_spectra.png"):
        assert (report_dir(report) / png).stat().st_size > 1000
    assert "Verdict" in (report_dir(report) / "report.md").read_text()


def report_dir(report):
    from pathlib import Path
    return Path(report.out_dir)


def test_result_does_not_depend_on_the_truth_files(sets, reports, tmp_path):
    """A copy of the set without its truth files gives the same diagnosis (to round-off)."""
    blind = tmp_path / "blind"
    shutil.copytree(sets["gravity"], blind)
    deleted = list(blind.glob("*.truth.json"))
    assert deleted
    for f in deleted:
        f.unlink()
    first = reports["gravity"].to_dict()
    again = diagnose(blind, config=CONFIG, progress=False).to_dict()
    assert again["verdict"] == first["verdict"]
    assert again["named_effects"] == first["named_effects"]
    for effect, params in first["fitted_parameters"].items():
        assert again["fitted_parameters"][effect] == pytest.approx(params, rel=1e-9)
    for key in ("nominal_all", "nominal_held_out", "named_held_out"):
        assert again["gap"][key] == pytest.approx(first["gap"][key], rel=1e-9, abs=1e-12)
    assert [r["effects"] for r in again["ranking"]] == [r["effects"] for r in first["ranking"]]
