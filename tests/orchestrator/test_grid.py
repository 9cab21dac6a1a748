"""The paper grid: naming, seeds, resume, failures, local processes and a Dask cluster."""

import json

import numpy as np
import pytest

from orchestrator import grid_tasks, run_grid, trial_name
from trialformat import read_trial, trial_exists

SMALL = {"friction_levels": [0], "resolution_levels": [1], "perturbation_levels": [1],
         "dofs": [1, 2], "duration_s": 8.2}


def test_full_grid_is_96_trials_with_shared_seeds():
    tasks = grid_tasks()
    assert len(tasks) == 96 and len({t["name"] for t in tasks}) == 96
    assert trial_name(3, 2, 1, 2) == "fric3_res2_pert1_dof2"
    seeds = {}
    for t in tasks:  # one seed per (perturbation level, joint), whatever F and R
        seeds.setdefault((t["perturbation_level"], t["perturbed_dof"]), set()).add(t["seed"])
    assert all(len(s) == 1 for s in seeds.values()) and len(seeds) == 6
    assert len({next(iter(s)) for s in seeds.values()}) == 6


def test_grid_in_process_writes_trials_manifest_and_resumes(reference_fmu, tmp_path):
    m = run_grid(tmp_path, workers=1, progress=False, fmu_path=reference_fmu, **SMALL)
    assert m["n_done"] == 2 and m["n_failed"] == 0
    for name in ("fric0_res1_pert1_dof1", "fric0_res1_pert1_dof2"):
        assert trial_exists(tmp_path / name)
    trial = read_trial(tmp_path / "fric0_res1_pert1_dof2.csv")
    assert trial.perturbed_dof == 2 and trial.meta["perturbation"]["seed"] == 12
    manifest = json.loads((tmp_path / "grid.json").read_text())
    assert manifest["n_trials"] == 2 and manifest["options"]["fmu"] == reference_fmu.name
    assert json.loads((tmp_path / "failures.json").read_text()) == {"failures": []}
    again = run_grid(tmp_path, workers=1, progress=False, fmu_path=reference_fmu, **SMALL)
    assert again["n_skipped"] == 2 and again["n_done"] == 0


def test_failed_trial_reported_and_others_complete(reference_fmu, tmp_path, joint_two_diverges):
    m = run_grid(tmp_path, workers=1, progress=False, fmu_path=reference_fmu, **SMALL)
    assert m["n_done"] == 1 and m["n_failed"] == 1
    failures = json.loads((tmp_path / "failures.json").read_text())["failures"]
    assert [f["name"] for f in failures] == ["fric0_res1_pert1_dof2"]
    assert "DivergenceError" in failures[0]["error"]
    assert failures[0]["friction_level"] == 0 and failures[0]["perturbation_level"] == 1
    assert not trial_exists(tmp_path / "fric0_res1_pert1_dof2")  # no log of a failed run


def test_grid_on_two_local_processes(reference_fmu, tmp_path):
    m = run_grid(tmp_path, workers=2, progress=False, fmu_path=reference_fmu, **SMALL)
    assert m["n_done"] == 2, m


def test_grid_on_dask_local_cluster(reference_fmu, tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(host="127.0.0.1", protocol="tcp", n_workers=1,
                                  processes=False, threads_per_worker=1,
                                  dashboard_address=None) as cluster:
        m = run_grid(tmp_path, scheduler=cluster.scheduler_address, progress=False,
                     fmu_path=reference_fmu, **{**SMALL, "dofs": [1]})
    assert m["n_done"] == 1, m
    local = run_grid(tmp_path / "local", workers=1, progress=False, fmu_path=reference_fmu,
                     **{**SMALL, "dofs": [1]})
    assert local["n_done"] == 1
    a = read_trial(tmp_path / "fric0_res1_pert1_dof1.csv")
    b = read_trial(tmp_path / "local" / "fric0_res1_pert1_dof1.csv")
    np.testing.assert_array_equal(a.theta, b.theta)  # same result wherever it ran
