"""Grouping by metadata, the report files and the CLI, on short synthetic trials."""

import csv
import json

import pytest

import trialformat as tf
from estimation import condition_of, group_conditions
from estimation.cli import main
from estimation.report import make_report
from estimation.synthetic import synthetic_trial


@pytest.fixture(scope="module")
def grid_folder(tmp_path_factory):
    """Two conditions; the names lie about friction so only metadata can group them."""
    folder = tmp_path_factory.mktemp("grid")
    for fric in (0, 3):
        for k in (1, 2, None):
            trial = synthetic_trial(perturbed_dof=k, seed=k or 9, duration_s=12.0)
            trial.meta["friction"] = tf.reference.friction_level(fric)
            tf.write_trial(folder / f"fric{3 - fric}_res0_pert3_dof{k}", trial)
    return folder


def test_condition_from_metadata_not_names(grid_folder):
    trials = tf.read_trials(grid_folder)
    groups = group_conditions(trials)
    assert [(c.friction, c.resolution, c.perturbation, c.tuning) for c in groups] == \
        [(0, 0, 3, "reference"), (3, 0, 3, "reference")]
    assert all(len(g) == 3 for g in groups.values())
    trial = trials[0]
    trial.meta["friction"] = dict(trial.meta["friction"], Fc=[0.33, 0.33])
    assert condition_of(trial).friction == "custom"


def test_report_files_and_tables(grid_folder, tmp_path, capsys):
    assert main(["figures", str(grid_folder), "--out", str(tmp_path), "--compare",
                 "none"]) == 0
    names = {p.split("/")[-1] for p in capsys.readouterr().out.split()}
    assert names == {"fig2_impedance.png", "fig3_accuracy.png", "fig4_coherence.png",
                     "table_conditions.csv", "table_conditions.md", "table_parameters.csv",
                     "table_parameters.md", "table_summary.csv", "table_summary.md",
                     "report.json"}  # --compare none: no figures of the paper's variant
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["variant_in_figures"] == "full_corrected" and report["skipped"] == []
    summary = {r["variant"]: r for r in report["summary"]}
    assert len(summary) == 9 and summary["full"]["n_conditions"] == 2
    assert summary["full"]["vaf_min"] == min(r["vaf_min"] for r in report["rows"]
                                             if r["variant"] == "full")
    rows = list(csv.DictReader(open(tmp_path / "table_conditions.csv")))
    variants = {r["variant"] for r in rows}
    assert {"decomposition", "full_corrected", "closed_loop_corrected", "direct"} <= variants
    assert len(rows) == 2 * 9
    # These smooth-input trials have no left-limit sampling to compensate: leakage only.
    best = [r for r in rows if r["variant"] == "full"]
    assert all(float(r["vaf_min"]) > 99.9 for r in best), [r["vaf_min"] for r in best]
    assert "| friction |" in (tmp_path / "table_conditions.md").read_text()
    legend = (tmp_path / "table_summary.md").read_text()
    assert "against Table I, each element relative to its own true value" in legend
    assert "sqrt(X_ii X_kk)" in legend  # the other normalisation, named
    params = list(csv.DictReader(open(tmp_path / "table_parameters.csv")))
    assert float(params[0]["true_value"]) > 0


def test_cli_estimate_writes_json(grid_folder, tmp_path, capsys):
    out = tmp_path / "est.json"
    assert main(["estimate", str(grid_folder), "--method", "full", "--truth", "table1",
                 "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "F0R0P3" in text and "Z22" in text
    results = json.loads(out.read_text())
    assert len(results) == 2 and results[0]["leakage_removed"] is True


def test_report_refuses_unknown_variant_and_empty_folder(grid_folder, tmp_path):
    with pytest.raises(ValueError, match="unknown variant 'fast'"):
        make_report(grid_folder, tmp_path, variant="fast", progress=False)
    with pytest.raises(ValueError, match="no trial"):
        make_report(tmp_path, tmp_path / "out", progress=False)


def test_report_in_worker_processes_equals_in_process(grid_folder, tmp_path, monkeypatch):
    import estimation.report as report
    one = make_report(grid_folder, tmp_path / "one", progress=False, workers=1)
    monkeypatch.setattr(report, "PROCESS_MIN_TASKS", 0)  # use the pool on 2 conditions
    two = make_report(grid_folder, tmp_path / "two", progress=False, workers=2)
    assert one["rows"] == two["rows"]
    assert sorted(p.name for p in (tmp_path / "one").iterdir()) == \
        sorted(p.name for p in (tmp_path / "two").iterdir())
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp left
