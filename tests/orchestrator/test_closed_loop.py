"""The closed loop: exact timing against a second implementation, the realised impedance,
what TDE compensates, communication step, divergence, effects and metadata."""

import numpy as np
import pytest
from scipy.signal import cont2discrete, dlsim

from orch_helpers import band, frf, rel_error
from orchestrator import IMBIC, DivergenceError, Setup, SetupError, simulate_trial
from orchestrator.plants.linear_arm import _M_R
from trialformat import read_trial, reference, write_trial

ZERO = np.zeros((2, 2))
TS = 1e-3


# ----------------------------------------------------------------------------- exact timing
def independent_closed_loop(setup, tau_delta, perturbed_dof):
    """Second implementation of the sampled loop on the linear plant: ZOH-discretised
    (M_r + M_h) theta'' + B_h theta' + K_h theta = tau_m, outputs at the left limit."""
    m_h, b_h, k_h = setup.arm
    m_tot = np.array(_M_R) + m_h
    m_inv = np.linalg.inv(m_tot)
    a = np.block([[ZERO, np.eye(2)], [-m_inv @ k_h, -m_inv @ b_h]])
    b = np.vstack([ZERO, m_inv])
    ad, bd, *_ = cont2discrete((a, b, np.eye(4), np.zeros((4, 2))), TS, method="zoh")
    ctl = IMBIC(setup.controller_config(), perturbed_dof)
    x, held = np.zeros(4), np.zeros(2)
    rows = []
    for d in tau_delta:
        acc = m_inv @ (held - b_h @ x[2:] - k_h @ x[:2])
        tau_h = m_h @ acc + b_h @ x[2:] + k_h @ x[:2]
        tau_m = ctl.step(list(x[:2]) + list(tau_h), list(d))
        rows.append(np.concatenate([x[:2], tau_h, tau_m]))
        held = np.array(tau_m)
        x = ad @ x + bd @ held
    return np.array(rows)


@pytest.mark.parametrize("perturbed_dof", [1, None])
def test_master_matches_second_implementation_on_linear_plant(linear_plant, perturbed_dof):
    setup = Setup.reference()
    trial = simulate_trial(setup, perturbed_dof=perturbed_dof, duration_s=2.0, seed=3,
                           plant=linear_plant)
    want = independent_closed_loop(setup, trial.tau_delta, perturbed_dof)
    got = np.hstack([trial.theta, trial.tau_h, trial.tau_m])
    scale = np.abs(want).max(axis=0)
    assert np.all(np.abs(got - want) <= 1e-8 * scale)


# ----------------------------------------------------------------------------- impedance
def ideal_response(tau_delta, m, b, k):
    """theta of 1/(m s^2 + b s + k) driven by tau_delta (bilinear, error ~(w Ts)^2/12)."""
    num, den, _ = cont2discrete(([1.0], [m, b, k]), TS, method="bilinear")
    return dlsim((np.ravel(num), den, TS), tau_delta)[1][:, 0]


def realised_error(trial, k, m, b, k_):
    """Relative FRF error of tau_delta_k -> theta_k against 1/(m s^2 + b s + k_) with the
    same Welch estimator on both (so the estimator's own bias cancels), 0-15 Hz."""
    x = trial.tau_delta[:, k - 1]
    f, r_sim = frf(x, trial.theta[:, k - 1])
    _, r_ideal = frf(x, ideal_response(x, m, b, k_))
    sel = band(f)
    return rel_error(r_sim[sel], r_ideal[sel]), f[sel], r_sim[sel]


CTL = reference.controller()
M_H, B_H, K_H = reference.arm_matrices()

#: Tolerance of the realised FRF: the internal model is integrated with semi-implicit
#: Euler at 1 kHz (0.4-0.6 % from 1/Z_rd up to 15 Hz, computed from its z-transform) and
#: the robot tracks it through TDE one sample late (the left-limit sampling and the
#: backward differences): a phase lag that grows with frequency, about 3 % at 15 Hz.
MAX_REL_ERROR, MEDIAN_REL_ERROR = 0.05, 0.015


@pytest.mark.parametrize("k", [1, 2])
def test_closed_loop_realises_desired_impedance_without_arm(reference_plant, k):
    setup = Setup.reference(0, 0).with_arm(ZERO, ZERO, ZERO)
    trial = simulate_trial(setup, perturbed_dof=k, duration_s=20.0, seed=k,
                           plant=reference_plant)
    m, b, kk = CTL["M_rd"][k - 1], CTL["B_rd"][k - 1], CTL["K_rd"][k - 1]
    err, f, r_sim = realised_error(trial, k, m, b, kk)
    assert err.max() < MAX_REL_ERROR and np.median(err) < MEDIAN_REL_ERROR
    # directly against the analytic 1/Z_rd (includes Welch's bias near the resonance)
    w = 2 * np.pi * f
    r_true = 1.0 / (kk - m * w**2 + 1j * b * w)
    vaf = 100 * (1 - np.sum(np.abs(r_sim - r_true) ** 2) / np.sum(np.abs(r_true) ** 2))
    assert vaf > 97.0
    assert np.abs(trial.theta[:, 2 - k]).max() < 1e-3  # the other joint is held


@pytest.mark.parametrize("k", [1, 2])
def test_with_arm_r_kk_is_one_over_z_rd_plus_z_h(reference_plant, k):
    trial = simulate_trial(Setup.reference(0, 0), perturbed_dof=k, duration_s=20.0, seed=k,
                           plant=reference_plant)
    j = k - 1
    err, _, _ = realised_error(trial, k, CTL["M_rd"][j] + M_H[j, j], CTL["B_rd"][j] + B_H[j, j],
                               CTL["K_rd"][j] + K_H[j, j])
    assert err.max() < MAX_REL_ERROR and np.median(err) < MEDIAN_REL_ERROR


def test_tde_compensates_friction(reference_plant):
    """Friction level 3: with TDE the realised R_11 is as good as without friction; without
    TDE the PD law lets friction distort it several times more."""
    setup = Setup.reference(3, 0)
    j = 0
    target = (CTL["M_rd"][j] + M_H[j, j], CTL["B_rd"][j] + B_H[j, j], CTL["K_rd"][j] + K_H[j, j])
    on = simulate_trial(setup, perturbed_dof=1, duration_s=20.0, seed=1, plant=reference_plant)
    off = simulate_trial(setup.with_controller(time_delay_estimation=False), perturbed_dof=1,
                         duration_s=20.0, seed=1, plant=reference_plant)
    err_on = realised_error(on, 1, *target)[0]
    err_off = realised_error(off, 1, *target)[0]
    print(f"friction 3, R_11 relative error: TDE on median {np.median(err_on):.4f} max "
          f"{err_on.max():.4f}; TDE off median {np.median(err_off):.4f} max {err_off.max():.4f}")
    assert err_on.max() < MAX_REL_ERROR
    assert np.median(err_off) > 3 * np.median(err_on)
    assert off.meta["controller"]["time_delay_estimation"] is False


# ----------------------------------------------------------------------------- comm step
def test_communication_step_1e5_gives_identical_trajectories(reference_plant):
    """The reference plant integrates RK4 at 1e-5 s from its own step counter, so 100
    steps of 1e-5 s and one of 1e-3 s with the input held do the same arithmetic:
    bit-identical."""
    setup = Setup.reference(3, 3)
    a = simulate_trial(setup, perturbed_dof=1, duration_s=1.0, plant=reference_plant)
    b = simulate_trial(setup, perturbed_dof=1, duration_s=1.0, plant=reference_plant,
                       communication_step_s=1e-5)
    for sig in ("theta", "tau_h", "tau_m"):
        np.testing.assert_array_equal(a.signal(sig), b.signal(sig))
    assert b.meta["simulation"]["communication_step_s"] == pytest.approx(1e-5)


def test_communication_step_on_linear_plant_agrees_to_rounding(linear_plant):
    """The linear plant steps with expm(A h): 100 products of expm(A 1e-5) equal
    expm(A 1e-3) only to rounding, so here the match is ~1e-12, not bit-identical."""
    setup = Setup.reference()
    a = simulate_trial(setup, perturbed_dof=2, duration_s=0.3, plant=linear_plant)
    b = simulate_trial(setup, perturbed_dof=2, duration_s=0.3, plant=linear_plant,
                       communication_step_s=1e-5)
    for sig in ("theta", "tau_h", "tau_m"):
        scale = np.abs(a.signal(sig)).max()
        np.testing.assert_allclose(b.signal(sig), a.signal(sig), rtol=0, atol=1e-10 * scale)


# ----------------------------------------------------------------------------- divergence
def test_extra_delay_with_reference_tuning_diverges(reference_plant, tmp_path):
    setup = Setup.reference(3, 3)
    with pytest.raises(DivergenceError) as info:
        simulate_trial(setup, perturbed_dof=1, duration_s=10.0, plant=reference_plant,
                       effects={"delay": {"samples": 1}}, name="fric3_delay1")
    msg = str(info.value)
    assert "fric3_delay1" in msg and "friction level 3" in msg and "delay" in msg
    assert "at t=" in msg and "tau_m[" in msg


def test_robust_tuning_survives_three_samples_delay(reference_plant):
    trial = simulate_trial(Setup.reference(3, 3, "robust"), perturbed_dof=1, duration_s=5.0,
                           plant=reference_plant, effects={"delay": {"samples": 3}})
    assert np.all(np.isfinite(trial.theta)) and np.abs(trial.theta).max() < 1.0
    assert trial.meta["simulation"]["effects"] == {"delay": {"samples": 3}}
    assert "delay" not in str(trial.meta["controller"])


# ----------------------------------------------------------------------------- effects
def test_sensor_noise_seeded_and_quantisation_effect(reference_plant):
    setup = Setup.reference(0, 0)
    eff = {"sensor_noise": {"theta_noise_std_rad": 1e-5, "tau_noise_std_nm": 0.01},
           "quantization": {"encoder_resolution_deg": 0.01, "torque_resolution_nm": 0.05}}
    a = simulate_trial(setup, perturbed_dof=2, duration_s=1.0, seed=4, plant=reference_plant,
                       effects=eff)
    b = simulate_trial(setup, perturbed_dof=2, duration_s=1.0, seed=4, plant=reference_plant,
                       effects=eff)
    np.testing.assert_array_equal(a.theta, b.theta)
    r = np.radians(0.01)
    np.testing.assert_allclose(a.theta / r, np.round(a.theta / r), atol=1e-9)
    np.testing.assert_allclose(a.tau_h / 0.05, np.round(a.tau_h / 0.05), atol=1e-9)
    declared = dict(a.meta["sensors"])
    assert declared.pop("torque_sampling") == "left_limit"  # the sampler's convention
    assert declared == reference.sensor_level(0)  # declared stays ideal
    assert a.meta["simulation"]["noise_seed"] == [4, 1]


def test_plant_side_effect_reaches_the_fmu(reference_plant):
    setup = Setup.reference(0, 0)
    base = simulate_trial(setup, perturbed_dof=1, duration_s=1.0, plant=reference_plant)
    tilted = simulate_trial(setup, perturbed_dof=1, duration_s=1.0, plant=reference_plant,
                            effects={"gravity": {"tilt_deg": 10.0}})
    assert tilted.meta["simulation"]["parameters"] == {"gravity.tilt_deg": 10.0}
    assert not np.allclose(base.tau_m, tilted.tau_m)
    assert tilted.meta["robot"]["gravity_tilt_deg"] == 0.0


# ----------------------------------------------------------------------------- trials
def test_trial_metadata_and_round_trip(reference_plant, tmp_path):
    setup = Setup.reference(2, 1)
    trial = simulate_trial(setup, perturbed_dof=2, level=2, seed=12, duration_s=8.2,
                           plant=reference_plant, name="t")
    meta = trial.meta
    assert meta["perturbed_dof"] == 2 and meta["n_dof"] == 2 and meta["fs"] == 1000.0
    assert meta["perturbation"] == {"level": 2, "peak": [6.0, 3.6], "seed": 12,
                                    "cutoff_hz": 15.0, "order": 8}
    assert meta["friction"] == reference.friction_level(2)
    assert meta["sensors"] == dict(reference.sensor_level(1), torque_sampling="left_limit")
    assert meta["controller"]["tuning"] == "reference"
    sim = meta["simulation"]
    assert sim["arm"]["K_h"] == K_H.tolist() and sim["arm"]["M_h"] == M_H.tolist()
    assert sim["fmu"]["model_name"] == "ArmExoPlant" and sim["rk4_step"] == 1e-5
    assert "/" not in sim["fmu"]["file"]
    np.testing.assert_array_equal(trial.t, np.arange(8200) / 1000.0)
    assert not np.any(trial.tau_delta[:, 0])
    write_trial(tmp_path / "t", trial)
    back = read_trial(tmp_path / "t.csv")
    for sig in ("tau_delta", "theta", "tau_h", "tau_m"):
        np.testing.assert_array_equal(back.signal(sig), trial.signal(sig))
    assert Setup.from_metadata(back.meta).to_metadata() == setup.to_metadata()


def test_all_joints_perturbed_at_once(reference_plant):
    trial = simulate_trial(Setup.reference(), perturbed_dof=None, duration_s=2.0,
                           plant=reference_plant)
    assert trial.meta["perturbed_dof"] is None
    assert np.all(np.abs(trial.tau_delta).max(axis=0) > 0)
    assert np.all(np.abs(trial.theta).max(axis=0) > 1e-2)  # both joints move


def test_explicit_perturbation_array(reference_plant):
    tau = np.zeros((6000, 2))
    tau[100:, 0] = 1.0
    trial = simulate_trial(Setup.reference(), perturbed_dof=1, perturbation=tau,
                           plant=reference_plant)
    assert trial.n_samples == 6000 and trial.meta["perturbation"]["custom"] is True
    # a 1 N m step settles at 1 / (K_rd + K_h) on joint 1
    assert trial.theta[-1, 0] == pytest.approx(1 / (CTL["K_rd"][0] + K_H[0, 0]), rel=1e-3)


@pytest.mark.parametrize("kwargs,match", [
    ({"perturbed_dof": 3}, "perturbed_dof"), ({"perturbed_dof": 0}, "perturbed_dof"),
    ({"perturbed_dof": 1, "duration_s": 0}, "duration_s"),
    ({"perturbed_dof": 1, "perturbation": np.ones((10, 3))}, "perturbation"),
    ({"perturbed_dof": 1, "perturbation": np.ones((10, 2))}, "non-zero columns"),
    ({"perturbed_dof": 1, "communication_step_s": 3e-4}, "not an integer multiple")])
def test_bad_trial_input(reference_plant, kwargs, match):
    with pytest.raises(ValueError, match=match):
        simulate_trial(Setup.reference(), plant=reference_plant, **kwargs)


def test_bad_setup():
    with pytest.raises(SetupError, match="friction level"):
        Setup.reference(friction_level=5)
    with pytest.raises(SetupError, match="M_h"):
        Setup.reference().with_arm(np.eye(3), ZERO, ZERO)


@pytest.mark.parametrize("tuning", ["reference", "robust"])
def test_setup_from_metadata_without_tuning_key_infers_it(tuning):
    meta = Setup.reference(tuning=tuning).to_metadata()
    del meta["controller"]["tuning"]
    assert Setup.from_metadata(meta).controller["tuning"] == tuning
    meta["controller"]["Mbar"] = [0.5, 0.5]
    assert Setup.from_metadata(meta).controller["tuning"] == "custom"
