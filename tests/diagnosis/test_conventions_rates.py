"""Conventions found in the files (issue 8, item 2) and any sample rate / numerical
failures of the plant (item 3)."""

import copy
import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from diagnosis.conventions import apply_declared, check_angles, check_time, check_torque_sign

orchestrator = pytest.importorskip("orchestrator")
from orchestrator import Setup  # noqa: E402
from orchestrator.errors import RateError  # noqa: E402
from orchestrator.trial import check_rk4_step, rk4_step_for  # noqa: E402

from diagnosis.simulate import NUMERICAL_RETRY_FACTOR, simulate_like  # noqa: E402


def posture_rad(trial):
    return np.radians(np.asarray(trial.meta["posture_deg"], dtype=float))


def test_deviations_as_declared_raise_no_finding(make_linear_trial):
    trials = [make_linear_trial(perturbed_dof=k, name=f"j{k}") for k in (1, 2)]
    out, found = check_angles(trials)
    assert found == [] and out is trials
    assert check_time(trials) == []


def test_absolute_angles_are_found_and_the_posture_removed(make_linear_trial):
    trials = [make_linear_trial(perturbed_dof=k, name=f"j{k}") for k in (1, 2)]
    absolute = [dataclasses.replace(t, theta=t.theta + posture_rad(t)) for t in trials]
    out, found = check_angles(absolute)
    assert [f.name for f in found] == ["angles absolute"]
    np.testing.assert_allclose(out[0].theta, trials[0].theta, atol=1e-12)


def test_angles_in_degrees_are_found_and_converted(make_linear_trial):
    trials = [make_linear_trial(perturbed_dof=k, name=f"j{k}") for k in (1, 2)]
    degrees = [dataclasses.replace(t, theta=np.degrees(t.theta)) for t in trials]
    out, found = check_angles(degrees)
    assert [f.name for f in found] == ["angles in degrees"]
    np.testing.assert_allclose(out[1].theta, trials[1].theta, atol=1e-12)


def test_declared_conventions_are_applied(make_linear_trial):
    t = make_linear_trial()
    t.meta["angles"] = "absolute"
    t.meta["sensors"] = dict(t.meta["sensors"], torque_sign=-1)
    raw = dataclasses.replace(t, theta=t.theta + posture_rad(t), tau_h=-t.tau_h)
    (out,), found = apply_declared([raw])
    assert {f.name for f in found} == {"declared: angles absolute", "declared: torque_sign -1"}
    assert out is raw  # the reader converted them already: never twice


def test_rounded_time_column_is_a_finding(make_linear_trial):
    t = make_linear_trial()
    t = dataclasses.replace(t, meta=dict(t.meta, fs=2048.0),
                            t=np.round(np.arange(t.n_samples) / 2048.0, 6))
    (finding,) = check_time([t])
    assert finding.name == "t rounded" and "6 decimals" in finding.evidence


def test_a_negative_arm_stiffness_that_turns_positive_is_a_reversed_torque_sign(
        make_linear_trial):
    trials = [make_linear_trial()]

    def arm(k):
        return SimpleNamespace(K=np.diag([k, k]))

    def estimate(flipped):  # the estimate of the flipped trials: positive stiffness
        assert np.allclose(flipped[0].tau_h, -trials[0].tau_h)
        return arm(8.0)

    out, arm_f, found = check_torque_sign(trials, arm(-8.0), estimate)
    assert [f.name for f in found] == ["torque sign reversed"] and arm_f.K[0, 0] == 8.0
    assert check_torque_sign(trials, arm(8.0), estimate)[2] == []


@pytest.mark.parametrize("fs, n", [(1000.0, 100), (500.0, 200), (1024.0, 98), (2048.0, 49)])
def test_rk4_step_divides_the_period_near_the_reference(fs, n):
    step = rk4_step_for(1.0 / fs)
    assert step == pytest.approx(1.0 / fs / n)
    assert abs(step - 1e-5) / 1e-5 < 0.01


def test_an_rk4_step_that_does_not_divide_the_period_is_refused_with_both_values():
    with pytest.raises(RateError, match=r"3e-05.*0\.0009765625"):
        check_rk4_step(3e-5, 1.0 / 1024.0)


def test_a_non_finite_plant_state_is_retried_with_a_smaller_step_and_reported(
        make_linear_trial):
    """LuGre sigma0 = 1e6 N m/rad at the 1e-5 s step: the plant state becomes non-finite;
    at 1e-5 / NUMERICAL_RETRY_FACTOR it runs. Reported as numerical, not as a model."""
    setup = Setup.reference(3, 0)
    friction = copy.deepcopy(setup.friction)
    friction["sigma0"] = 1e6
    setup = dataclasses.replace(setup, friction=friction)
    trial = make_linear_trial()
    sim = simulate_like(trial, setup, {}, 400)
    assert sim is not None
    retry = sim.meta["simulation"]["numerical_retry"]
    assert retry["failed_rk4_step"] == pytest.approx(1e-5)
    assert retry["rk4_step"] == pytest.approx(1e-5 / NUMERICAL_RETRY_FACTOR)


@pytest.mark.parametrize("fs", [500.0, 1024.0, 2048.0])
def test_trials_at_other_rates_are_simulated_at_their_rate(fs, make_linear_trial):
    setup = dataclasses.replace(Setup.reference(1, 1), fs=fs)
    trial = make_linear_trial()
    trial = dataclasses.replace(trial, meta=dict(trial.meta, fs=fs))
    sim = simulate_like(trial, setup, {}, 600)
    assert sim is not None and sim.fs == fs and sim.n_samples == 600
    assert sim.meta["simulation"]["rk4_step"] == pytest.approx(rk4_step_for(1.0 / fs))


def test_rounded_time_column_read_from_a_file_is_a_finding(make_linear_trial, tmp_path):
    """The reader returns t as the exact grid; the stored values still reach the finding."""
    import pandas as pd

    from trialformat import read_trial, write_trial

    t = make_linear_trial()
    t = dataclasses.replace(t, meta=dict(t.meta, fs=2048.0), t=np.arange(t.n_samples) / 2048.0)
    csv = write_trial(tmp_path / "exact", t)
    frame = pd.read_csv(csv)
    frame.to_csv(tmp_path / "rounded.csv", index=False, float_format="%.6f")
    (tmp_path / "rounded.json").write_text((tmp_path / "exact.json").read_text())
    exact, rounded = read_trial(tmp_path / "exact"), read_trial(tmp_path / "rounded")
    assert exact.t_stored is None and check_time([exact]) == []
    np.testing.assert_array_equal(rounded.t, exact.t)
    (finding,) = check_time([rounded])
    assert finding.name == "t rounded" and "6 decimals" in finding.evidence
