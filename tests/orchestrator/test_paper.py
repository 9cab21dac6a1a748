"""The all-joints grid mode and ``armimp paper``: trials, report, resume, failures."""

import json

import numpy as np
import pytest

import orchestrator.paper
import orchestrator.trial
from orchestrator import SetupError, grid_seed, grid_tasks, parse_dof, run_grid, run_paper
from orchestrator.cli import main
from trialformat import read_trial
from trialformat import reference as ref

#: One condition, trials long enough for 3 Welch segments of 8192 samples.
TINY = {"friction_levels": [3], "resolution_levels": [3], "perturbation_levels": [3],
        "duration_s": 12.3}
REPORT_FILES = {"fig2_impedance.png", "fig3_accuracy.png", "fig4_coherence.png",
                "fig3_accuracy_decomposition.png", "fig4_coherence_decomposition.png",
                "table_conditions.csv", "table_conditions.md", "table_parameters.csv",
                "table_parameters.md", "table_summary.csv", "table_summary.md",
                "report.json"}


def test_all_joints_tasks_names_and_seed_rule():
    tasks = grid_tasks(dofs=[1, 2, "all"])
    assert len(tasks) == 144 and len({t["name"] for t in tasks}) == 144
    alls = [t for t in tasks if t["perturbed_dof"] is None]
    assert len(alls) == 48 and all(t["name"].endswith("_dofall") for t in alls)
    # k = 0 for all joints: one seed per level, never a decomposition trial's seed
    assert {t["seed"] for t in alls} == {10, 20, 30}
    assert not {t["seed"] for t in alls} & {t["seed"] for t in tasks if t not in alls}
    assert grid_seed(100, 2, None) == 120 and grid_seed(100, 2, 1) == 121
    assert parse_dof("all") is None and parse_dof(None) is None and parse_dof("2") == 2
    for bad in ("x", 0, 1.5):
        with pytest.raises(SetupError, match="1-based joint or 'all'"):
            parse_dof(bad)
    with pytest.raises(SetupError, match="twice"):
        grid_tasks(dofs=[None, "all"])


def test_all_joints_grid_trial_has_independent_perturbations(reference_fmu, tmp_path, capsys):
    rc = main(["grid", str(tmp_path), "--workers", "1", "--friction", "0", "--resolution",
               "1", "--perturbation", "1", "--dofs", "all", "--duration", "8.2",
               "--fmu", str(reference_fmu), "--no-progress"])
    assert rc == 0 and "1 done" in capsys.readouterr().out
    trial = read_trial(tmp_path / "fric0_res1_pert1_dofall.csv")
    assert trial.n_samples >= 8192
    assert trial.perturbed_dof is None and trial.meta["perturbation"]["seed"] == 10
    d = trial.tau_delta
    np.testing.assert_allclose(np.abs(d).max(axis=0), ref.perturbation_peak(1))
    rho = np.corrcoef(d.T)[0, 1]
    assert abs(rho) < 0.25, rho  # independent draws (15 Hz band: ~250 dof, sd ~0.06)
    manifest = json.loads((tmp_path / "grid.json").read_text())
    assert manifest["options"]["dofs"] == ["all"] and "0 for all joints" in manifest["seeds"]
    assert manifest["trials"][0]["perturbed_dof"] is None


def test_paper_cli_writes_report_and_resumes(reference_fmu, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(orchestrator.paper, "QUICK_PLAN", TINY)
    args = ["paper", "--quick", "--out", str(tmp_path), "--workers", "1", "--no-progress",
            "--fmu", str(reference_fmu)]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "3 simulated, 0 already there, 0 failed" in text
    assert "decomposition" in text and "full_corrected" in text
    assert {p.name for p in (tmp_path / "report").iterdir()} >= REPORT_FILES
    record = json.loads((tmp_path / "paper.json").read_text())
    assert record["status"] == "done" and record["grid"]["n_done"] == 3
    summary = {r["variant"]: r for r in record["summary"]}
    # the MIMO baselines come from the grid's all-joints trial, beside the paper's T/R
    assert {"decomposition", "full_corrected", "closed_loop_corrected", "direct"} <= set(summary)
    # a real accuracy figure on the reference plant (50 s trials give 99.7 %; 12 s, 3
    # segments, coarsest sensors and most friction: still above 99 %)
    assert summary["full_corrected"]["vaf_min"] > 99.0, summary["full_corrected"]
    stamps = {p.name: p.stat().st_mtime_ns for p in (tmp_path / "trials").glob("*.csv")}
    assert len(stamps) == 3

    monkeypatch.setattr(orchestrator.trial, "simulate_trial", _must_not_simulate)
    assert main(args) == 0  # resume: nothing simulated, report rebuilt
    assert "0 simulated, 3 already there" in capsys.readouterr().out
    assert stamps == {p.name: p.stat().st_mtime_ns
                      for p in (tmp_path / "trials").glob("*.csv")}
    assert main(args + ["--duration", "14"]) == 1  # other options: refused
    assert "duration_s: 12.3 there, 14.0 now" in capsys.readouterr().err


def _must_not_simulate(*args, **kwargs):
    raise AssertionError("a resumed paper run simulated a trial")


def test_paper_failed_trial_reported_rest_completes(reference_fmu, tmp_path, joint_two_diverges):
    result = run_paper(tmp_path, workers=1, progress=False, fmu_path=reference_fmu, **TINY)
    assert result["grid"]["n_failed"] == 1 and result["grid"]["n_done"] == 2
    assert "DivergenceError" in result["grid"]["failures"][0]["error"]
    skipped = {s["method"] for s in result["skipped_conditions"]}
    assert skipped == {"decomposition", "full"}  # they need the failed joint-2 trial
    variants = {r["variant"] for r in result["summary"]}
    assert "closed_loop_corrected" in variants and "decomposition" not in variants
    text = "\n".join(orchestrator.paper.summary_lines(result))
    assert "FAILED fric3_res3_pert3_dof2" in text and "not estimated" in text


def test_summary_names_the_truth_and_each_block_normalisation():
    row = {"tuning": "reference", "variant": "full_corrected", "vaf_min": 99.0,
           "r2_min": 0.99, "err_M_max": 2.9, "err_B_max": 7.6, "err_K_max": 3.8,
           "n_conditions": 4}
    acc = {"tuning": "reference", "variant": "full_corrected", "vaf_min": 99.0,
           "err_M_max": 1.0, "err_B_max": 1.2, "err_K_max": 0.4, "meets": False,
           "worst": {}}
    result = {"grid": {"n_trials": 16, "n_done": 16, "n_skipped": 0, "n_failed": 0,
                       "failures": []},
              "wall_s": {"grid": 1.0, "report": 1.0, "total": 2.0},
              "skipped_conditions": [], "summary": [row], "acceptance": [acc],
              "report_dir": "report", "options": {"arm": "3dof"}}
    text = "\n".join(orchestrator.paper.summary_lines(result))
    assert "Table I" not in text and text.count("reference-3dof") == 2
    assert "relative to its own true value X_ik" in text
    assert "relative to sqrt(X_ii X_kk)" in text
    result["options"]["arm"] = "2dof"
    assert "vs Table I" in "\n".join(orchestrator.paper.summary_lines(result))


def test_paper_resumed_with_other_builtin_plant_refused(tmp_path, monkeypatch):
    from orchestrator.paper import paper_plan

    # a run recorded before the plant key (it ran the C plant), resumed on the Modelica one
    record = json.dumps({"status": "running",
                         "options": {**paper_plan(quick=True), "quick": True, "fmu": None}})
    (tmp_path / "paper.json").write_text(record)
    monkeypatch.setenv("ARMEXO_PLANT", "modelica")
    with pytest.raises(SetupError, match="plant: 'c' there, 'modelica' now"):
        run_paper(tmp_path, quick=True, workers=1, progress=False)
    assert (tmp_path / "paper.json").read_text() == record
