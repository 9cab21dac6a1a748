"""Three joints and beyond: the 3dof reference, refusal of mismatched shapes, 3-joint trials
on the C FMU, the paper plan, the normalised errors and the n-joint chain of the
tractability study."""

import json

import numpy as np
import pytest

from orchestrator import Setup, SetupError, simulate_trial
from orchestrator import tractability as tr
from orchestrator.cli import main
from orchestrator.paper import normalized_errors, paper_plan
from trialformat import reference as ref


@pytest.fixture(scope="module")
def plant3(tmp_path_factory):
    fmus = pytest.importorskip("fmus")
    return fmus.build_fmu(tmp_path_factory.mktemp("fmu3"), n=3)


def test_reference_3dof_is_the_spec():
    """docs/spec/reference-3dof.md's numbers, read back through the Setup."""
    s = Setup.reference(3, 2, "robust", arm="3dof")
    assert s.n_dof == 3 and s.posture_deg == [62.708, 77.26, 10.0]
    assert s.arm[0][2].tolist() == [0.012, 0.010, 0.006] and s.arm[2][1, 2] == 0.6
    assert s.friction["Fc"] == pytest.approx([0.4, 0.4, 0.1])
    assert s.friction["sigma2"] == pytest.approx([0.08, 0.08, 0.02])
    assert s.controller["Mbar"] == [0.018, 0.014, 0.0035] and s.controller["wn"] == [25.0] * 3
    assert s.controller["M_rd"] == [0.2, 0.05, 0.02] and s.controller["K_rd"] == [10.0, 5.0, 2.0]
    assert ref.perturbation_peak(2, "3dof") == [6.0, 3.6, 1.2]
    p = s.plant_parameters()
    assert p["robot.m3"] == 0.6 and p["robot.lc3"] == 0.06 and p["robot.Jm[3]"] == 0.004
    assert Setup.reference().n_dof == 2  # the default is unchanged


@pytest.mark.parametrize("change,match", [
    (lambda s: s.with_arm(np.eye(2), np.eye(3), np.eye(3)), r"M_h must be a finite 3x3"),
    (lambda s: s.with_arm(np.eye(3), np.eye(3), np.ones((3, 2))), r"K_h must be a finite 3x3.*\(3, 2\)"),
    (lambda s: s.with_controller(Mbar=[0.1, 0.03]), r"controller Mbar has shape \(2,\).*expected shape \(3,\)"),
    (lambda s: Setup(**{**s.__dict__, "robot": {**s.robot, "Jm": [0.01] * 2}}), r"robot Jm .*\(3,\)"),
    (lambda s: Setup(**{**s.__dict__, "friction": {**s.friction, "Fs": [0.1] * 4}}), r"friction Fs .*\(3,\)"),
    (lambda s: Setup(**{**s.__dict__, "posture_deg": [1.0, 2.0]}), r"posture_deg .*\(3,\)"),
    (lambda s: Setup(**{**Setup.reference().__dict__, "robot": {**s.robot, "Jm": [0.01] * 2}}),
     r"robot has link 3 parameters for n_dof=2"),
])
def test_matrices_of_the_wrong_shape_are_refused_by_name(change, match):
    with pytest.raises(SetupError, match=match):
        change(Setup.reference(arm="3dof"))


def test_unknown_arm_is_refused():
    with pytest.raises(SetupError, match="arm must be one of"):
        Setup.reference(arm="4dof")
    with pytest.raises(SetupError, match="dofs \\[3\\] beyond the 2 joints"):
        from orchestrator import grid_tasks
        grid_tasks(dofs=[1, 3])


def test_three_joint_decomposition_recovers_the_arm(plant3):
    """Three decomposition trials of 20 s on ArmExoPlant3 (friction 0, resolution 0): the
    held joints move < 2 % of the perturbed one, and T P^-1 (the bias-removing estimator,
    sampling and leakage corrected) recovers reference-3dof.md's arm: VAF >= 99.5 % on
    every element, M, B, K within 2/3/2 % (off-diagonal relative to sqrt(X_ii X_kk))."""
    from estimation.conditions import evaluate

    setup = Setup.reference(0, 0, arm="3dof")
    trials = [simulate_trial(setup, perturbed_dof=k, duration_s=20.0, seed=40 + k,
                             plant=plant3) for k in (1, 2, 3)]
    for k, t in enumerate(trials):
        amp = np.abs(t.theta).max(axis=0)
        assert np.all(np.delete(amp, k) < 0.02 * amp[k]), (k, amp)
    truth = ref.arm_matrices("3dof")
    row = evaluate(trials, truth=truth, variants=[("full_corrected", "full", True, True)])[0]
    err = normalized_errors(row, truth)
    assert row["vaf_min"] >= 99.5
    assert err["M"] <= 2.0 and err["B"] <= 3.0 and err["K"] <= 2.0, err


def test_normalized_errors_by_hand():
    truth = (np.array([[4.0, 1.0], [1.0, 1.0]]),) * 3
    row = {f"{p}_{i}{k}": v for p in "MBK" for (i, k), v in
           {(1, 1): 4.4, (1, 2): 1.1, (2, 1): 1.0, (2, 2): 0.95}.items()}
    # (4.4-4)/4 = 10 %, (1.1-1)/sqrt(4*1) = 5 %, (0.95-1)/1 = 5 %
    assert normalized_errors(row, truth) == pytest.approx({"M": 10.0, "B": 10.0, "K": 10.0})


def test_paper_plan_three_joints():
    plan = paper_plan(arm="3dof")
    assert plan["dofs"] == [1, 2, 3, "all"] and plan["arm"] == "3dof"
    assert paper_plan()["dofs"] == [1, 2, "all"]
    with pytest.raises(SetupError, match="arm must be one of"):
        paper_plan(arm="7dof")


def test_armimp_paper_3dof_one_condition(tmp_path, plant3, capsys):
    """``armimp paper --arm 3dof`` end to end on one condition (12.3 s trials)."""
    from orchestrator.paper import run_paper

    out = tmp_path / "p3"
    result = run_paper(out, arm="3dof", friction_levels=[0], resolution_levels=[0],
                       perturbation_levels=[3], duration_s=12.3, workers=1, progress=False,
                       fmu_path=plant3)
    assert result["grid"]["n_done"] == 4 and not result["skipped_conditions"]
    acc = {a["variant"]: a for a in result["acceptance"]}
    assert {"decomposition", "full_corrected", "closed_loop_corrected"} <= set(acc)
    saved = json.loads((out / "paper.json").read_text())
    assert saved["options"]["arm"] == "3dof"
    # resuming with the other arm is refused
    assert main(["paper", "--out", str(out), "--arm", "2dof", "--no-progress"]) == 1
    assert "arm: '3dof' there, '2dof' now" in capsys.readouterr().err


def test_chain_of_the_tractability_study():
    """The n-joint chain: reference matrices for joints 1-3, symmetric positive definite
    parts, no zero element; the planar mass matrix formula reproduces reference-3dof.md's
    printed M_r entries and the linear two-joint plant's M_r."""
    M3 = ref.arm_matrices("3dof")
    for n in (4, 7):
        arm = tr.chain_arm(n)
        for X, X3 in zip(arm, M3):
            assert X.shape == (n, n) and np.all(X != 0)
            np.testing.assert_array_equal(X[:3, :3], X3)
            assert np.linalg.eigvalsh(0.5 * (X + X.T)).min() > 0
        assert len(tr.chain_peaks(n)) == n and tr.chain_setup(n).n_dof == n
    # reference-3dof.md's formula, written out
    r = ref.robot("3dof")
    m1, m2, m3, L1, L2 = r["m1"], r["m2"], r["m3"], r["L1"], r["L2"]
    lc1, lc2, lc3, I1, I2, I3 = r["lc1"], r["lc2"], r["lc3"], r["I1"], r["I2"], r["I3"]
    a1 = I1 + m1 * lc1**2 + I2 + m2 * (L1**2 + lc2**2) + I3 + m3 * (L1**2 + L2**2 + lc3**2)
    a2, a3 = I2 + m2 * lc2**2 + I3 + m3 * (L2**2 + lc3**2), I3 + m3 * lc3**2
    b12, b13, b23 = m2 * L1 * lc2 + m3 * L1 * L2, m3 * L1 * lc3, m3 * L2 * lc3
    q = np.radians([62.708, 77.26, 10.0])
    c2, c3, c23 = np.cos(q[1]), np.cos(q[2]), np.cos(q[1] + q[2])
    J = r["Jm"]
    spec = np.array([[a1 + 2 * b12 * c2 + 2 * b13 * c23 + 2 * b23 * c3 + J[0],
                      a2 + b12 * c2 + b13 * c23 + 2 * b23 * c3, a3 + b13 * c23 + b23 * c3],
                     [0, a2 + 2 * b23 * c3 + J[1], a3 + b23 * c3], [0, 0, a3 + J[2]]])
    spec = np.triu(spec) + np.triu(spec, 1).T
    np.testing.assert_allclose(tr.chain_robot(3)[0], spec, rtol=1e-12)
    from orchestrator.plants import linear_arm
    np.testing.assert_allclose(tr.chain_robot(2)[0], linear_arm._M_R, rtol=1e-9)


def test_study_tasks_are_at_equal_total_time():
    """Per (n, plant, T): n decomposition trials of T/n and one all-joints trial of T."""
    tasks = tr.study_tasks(ns=(2, 3, 5), totals_s=(70.0,))
    kinds = {(t["n"], t["plant"]) for t in tasks}
    assert kinds == {(2, "fmu"), (3, "fmu"), (3, "linear"), (5, "linear")}
    for n, plant in kinds:
        sel = [t for t in tasks if (t["n"], t["plant"]) == (n, plant)]
        dec = [t for t in sel if t["perturbed_dof"] is not None]
        mimo = [t for t in sel if t["perturbed_dof"] is None]
        assert sorted(t["perturbed_dof"] for t in dec) == list(range(1, n + 1))
        assert sum(t["duration_s"] for t in dec) == pytest.approx(70.0)
        assert [t["duration_s"] for t in mimo] == [70.0]
    assert len({t["name"] for t in tasks}) == len(tasks)
    assert tr.frfs_together("closed_loop", 7) == "98 (MIMO)"
    with pytest.raises(SetupError, match="n in 2..7"):
        tr.run_tractability("unused", ns=(8,))


@pytest.mark.slow
def test_tractability_quick_run(tmp_path):
    """``armimp tractability --quick``: n = 2, 3, 4 at T = 70 s, every estimator scored."""
    assert main(["tractability", "--quick", "--out", str(tmp_path), "--no-progress"]) == 0
    result = json.loads((tmp_path / "tractability.json").read_text())
    done = [r for r in result["rows"] if r["status"] == "done"]
    assert len(done) == 16
    n3 = {r["estimator"]: r for r in done if r["n"] == 3 and r["plant"] == "fmu"}
    assert n3["decomposition T P^-1"]["vaf_matrix"] > 99.9
    assert n3["decomposition T/R"]["cond_max"] == 1.0
    assert (tmp_path / "fig_tractability.png").stat().st_size > 0


def test_fmu_defaults_equal_the_3dof_reference():
    """The three-link FMU's defaults (fmus/variables.py) and trialformat's
    reference-3dof.json are the same numbers: every parameter the 3-joint Setup declares."""
    fmus_variables = pytest.importorskip("fmus.variables")
    starts = {v.name: v.start for v in fmus_variables.table(3).variables
              if v.causality == "parameter"}
    declared = Setup.reference(0, 0, arm="3dof").plant_parameters()
    assert set(declared) <= set(starts)
    assert {k: declared[k] for k in declared} == pytest.approx({k: starts[k] for k in declared})
    for level in range(4):
        fric = Setup.reference(level, 0, arm="3dof").plant_parameters()
        expected = fmus_variables.friction_parameters(level, 3)
        assert {k: fric[k] for k in expected} == pytest.approx(expected)
