"""labsim's other elements against second implementations written here (loops, scipy's
lsim), and every draw kind: it simulates, its truth says what it holds, its ranges."""

import numpy as np
import pytest
from scipy import signal

import labsim

FS = 1000.0


def ideal(**kw):
    base = dict(duration_s=10.0, servo=labsim.Servo(kind="ideal"),
                sensors=labsim.Sensors(antialias=None))
    base.update(kw)
    return labsim.RecordingSpec(**base)


def play_loop(x, w):
    y, out = 0.0, np.empty_like(x)
    for i, v in enumerate(x):
        y = min(max(y, v - w), v + w)
        out[i] = y
    return out


def test_stiffening_spring_elastic_torque_and_truth():
    k3 = 2e5
    rec = labsim.simulate(ideal(limb=labsim.Limb(K=50.0, k3=k3)))
    x = rec.trial.theta[:, 0]
    np.testing.assert_allclose(rec.truth["arrays"]["tau_elastic"], 50.0 * x + k3 * x ** 3,
                               rtol=1e-12, atol=1e-12)
    # the truth's K is the local stiffness at the slow angle (0 here: K0)
    np.testing.assert_allclose(rec.truth["arrays"]["K"], 50.0)


def test_short_range_stiffness_is_a_spring_that_slips():
    rec = labsim.simulate(ideal(limb=labsim.Limb(K=50.0, srs_K=40.0, srs_limit_rad=0.005)))
    x = rec.trial.theta[:, 0]
    # bounded by the elastic limit, reached; and a loop's play over the samples agrees
    # (it misses only what happens between samples)
    srs = rec.truth["arrays"]["tau_srs"]
    assert np.max(np.abs(srs)) <= 40.0 * 0.005 * (1 + 1e-12)
    assert np.max(np.abs(srs)) > 0.99 * 40.0 * 0.005
    ref = 40.0 * (x - play_loop(x, 0.005))
    late = rec.trial.t > 0.5  # the loop starts at rest at t = 0, the simulator before
    assert np.max(np.abs(srs - ref)[late]) < 0.1 * 40.0 * 0.005


def test_backlash_footplate_follows_the_play_through_the_contact():
    """Limb side = K x_f with x_f the play operator (loop) through the contact's
    2nd-order low-pass (scipy lsim): a second implementation of the footplate."""
    b, fc = 0.002, 150.0
    spec = ideal(limb=labsim.Limb(K=80.0, B=0.0, I=0.0),
                 footplate=labsim.Footplate(backlash_rad=b, contact_hz=fc), oversample=10)
    rec = labsim.simulate(spec)
    x = rec.trial.theta[:, 0]
    # a play loop and lsim over the samples (coarser than the simulator's fine grid)
    wc = 2 * np.pi * fc
    _, xf, _ = signal.lsim(([wc * wc], [1, 1.4 * wc, wc * wc]), play_loop(x, b),
                           rec.trial.t)
    tau = rec.trial.tau_h[:, 0]
    assert np.max(np.abs(tau - 80.0 * xf)) < 0.02 * np.max(np.abs(tau))
    # and it is not the rigid footplate
    assert np.max(np.abs(tau - 80.0 * x)) > 0.5 * 80.0 * b


def test_backlash_on_the_pd_servo_converges_and_sensor_equals_limb():
    spec = labsim.RecordingSpec(duration_s=4.0,
                                footplate=labsim.Footplate(backlash_rad=0.002))
    rec = labsim.simulate(spec)
    assert rec.truth["solver"]["residual"] < 1e-7
    assert rec.truth["solver"]["limb_vs_sensor_max_nm"] < 1e-6 * rec.truth["rms"]["tau_h"]


def test_contact_clipping_limits_the_negative_torque_only():
    L = 2.0
    rec = labsim.simulate(ideal(footplate=labsim.Footplate(contact_limit_nm=L)))
    tau = rec.trial.tau_h[:, 0]
    free = tau - rec.truth["arrays"]["tau_contact"]
    assert tau.min() > -L and free.min() < -1.5 * L
    high = free > 0
    assert np.max(np.abs(tau[high] - free[high])) < 0.01 * L


def test_voluntary_torque_level_band_and_incoherence():
    vol = labsim.Voluntary(fraction=0.3, band_hz=2.0)
    rec = labsim.simulate(labsim.RecordingSpec(duration_s=40.0, voluntary=vol))
    subj = -rec.truth["arrays"]["tau_subject"]
    scale = rec.truth["perturbation_torque_rms_nm"]
    assert np.sqrt(np.mean(subj ** 2)) == pytest.approx(0.3 * scale, rel=0.02)
    assert rec.spec.voluntary.level_nm == pytest.approx(0.3 * scale)
    f, p = signal.welch(subj, FS, nperseg=8192)
    assert np.sum(p[f < 4]) > 0.995 * np.sum(p)  # 4th-order Butterworth at 2 Hz
    f, coh = signal.coherence(rec.trial.theta_ref[:, 0], subj, FS, nperseg=2048)
    assert np.max(coh[(f > 0.2) & (f < 2)]) < 0.3  # 38 averages: chance level ~0.03


def test_rest_period_has_no_perturbation():
    pert = labsim.Perturbation(rest=[[4.0, 7.0]], taper_s=0.2)
    rec = labsim.simulate(labsim.RecordingSpec(duration_s=10.0, perturbation=pert))
    t, ref = rec.trial.t, rec.trial.theta_ref[:, 0]
    inside = (t > 4.2) & (t < 6.8)
    assert np.all(ref[inside] == 0.0) and np.std(ref[t < 3.9]) > 0.015
    np.testing.assert_array_equal(rec.truth["arrays"]["perturbed"][inside], 0.0)
    assert {e["name"] for e in rec.truth["effects"]} >= {"rest_periods"}


def test_two_joints_frf_matrix_is_k_b_i():
    """Two runs, one perturbing each joint (periodic multisine): per line the two runs'
    spectra give Z = Y X^-1 exactly, whichever way the loaded servo lets the other joint
    move."""
    K = [[30.0, 6.0], [6.0, 20.0]]
    B = [[1.0, 0.2], [0.2, 0.6]]
    I = [[0.25, 0.06], [0.06, 0.07]]
    X, Y = [], []
    for joint in (1, 2):
        pert = labsim.Perturbation(kind="multisine", amplitude_rad=0.01, band_hz=[0.4, 20.0],
                                   period_s=5.0, joints=[joint])
        spec = labsim.RecordingSpec(duration_s=10.0, preroll_s=5.0, n_dof=2, perturbation=pert,
                                    servo=labsim.Servo(kind="pd", f_hz=40.0, motor_inertia=0.1),
                                    limb=labsim.Limb(K=K, B=B, I=I))
        rec = labsim.simulate(spec)
        assert rec.trial.meta["perturbed_dof"] == joint
        # the held joint moves a little: the servo is loaded through the coupling
        other = rec.trial.theta[:, 2 - joint]
        assert 1e-5 < np.std(other) < 0.2 * np.std(rec.trial.theta[:, joint - 1])
        X.append(np.fft.rfft(rec.trial.theta[5000:].T, axis=1))
        Y.append(np.fft.rfft(rec.trial.tau_h[5000:].T, axis=1))
    f = np.fft.rfftfreq(5000, 1 / FS)
    lines = np.nonzero((f >= 0.4) & (f <= 20.0))[0]
    Km, Bm, Im = (np.array(v) for v in (K, B, I))
    for k in lines:
        Xk = np.column_stack([X[0][:, k], X[1][:, k]])
        Yk = np.column_stack([Y[0][:, k], Y[1][:, k]])
        w = 2 * np.pi * f[k]
        Z = Km + 1j * w * Bm - w * w * Im
        np.testing.assert_allclose(Yk @ np.linalg.inv(Xk), Z, rtol=0, atol=1e-5 * np.abs(Z).max())


def test_reflex_fraction_sets_the_gain():
    rx = labsim.Reflex(gain=0.0, fraction=0.4, rectify="none")
    rec = labsim.simulate(ideal(reflex=rx, duration_s=10.0))
    assert rec.spec.reflex.fraction is None and rec.spec.reflex.gain > 0
    sd = np.std(rec.truth["arrays"]["tau_reflex"])
    assert sd == pytest.approx(0.4 * rec.truth["perturbation_torque_rms_nm"], rel=0.01)


def test_movement_removed_is_the_perturbed_less_the_unperturbed_trial():
    mov = labsim.Movement(kind="sine", range_rad=[-0.3, 0.1], period_s=5.0)
    base = dict(duration_s=10.0, movement=mov, limb=labsim.Limb(
        K=60.0, K_var=labsim.Variation(angle="exp", angle_coef=2.0)))
    full = labsim.simulate(labsim.RecordingSpec(**base))
    removed = labsim.simulate(labsim.RecordingSpec(**base, movement_removed=True))
    # the reference less the movement is the perturbation alone
    sv = removed.trial.extra["sv"]
    np.testing.assert_allclose(removed.trial.theta_ref[:, 0], full.trial.theta_ref[:, 0] - sv,
                               atol=1e-12)
    assert np.std(removed.trial.theta) < 0.05 and np.ptp(full.trial.theta) > 0.35
    assert "movement_removed" in removed.truth
    # the torque left is the perturbation's: its slow part (the elastic torque of the
    # movement) is gone
    assert abs(np.mean(removed.trial.tau_h)) < 0.1 * abs(np.mean(full.trial.tau_h)) + 0.5


def test_time_profiles_against_their_formulas():
    T = 20.0
    t = np.arange(0, T, 0.01)
    from labsim.limb import time_factor
    cases = {
        "linear": (labsim.Variation(time="linear", ratio=2.0), 1 + t / T),
        "saturating": (labsim.Variation(time="saturating", ratio=3.0, tau_s=5.0),
                       1 + 2 * (1 - np.exp(-t / 5.0))),
        "sine": (labsim.Variation(time="sine", ratio=1.4, period_s=8.0),
                 1 + 0.4 * np.sin(2 * np.pi * t / 8.0)),
    }
    for name, (var, expected) in cases.items():
        np.testing.assert_allclose(time_factor(var, t, T), expected, rtol=1e-12, err_msg=name)


@pytest.mark.parametrize("kind", labsim.KINDS)
def test_every_kind_simulates_and_its_truth_names_it(kind):
    rng = np.random.default_rng(11)
    spec = labsim.draw(kind + "+reflex", rng, duration_s=2.0)
    assert spec.reflex is not None and spec.kind == kind + "+reflex"
    assert 0.040 <= spec.reflex.delay_s <= 0.050
    rec = labsim.simulate(spec)
    names = {e["name"] for e in rec.truth["effects"]}
    expected = {
        "voluntary": "voluntary_torque", "footplate_friction": "footplate_friction",
        "wobbling_other_damping": "wobbling_mass", "antialias_filter": "channel_filter",
        "linear_drift": "time_varying_K", "saturating_drift": "time_varying_K",
        "switching": "time_varying_K", "modulated": "time_varying_K",
        "moving_angle_dependent": "angle_dependent_K", "moving_linear": "movement",
        "channel_delay": "channel_delay", "rest_period": "rest_periods",
        "stiffening_spring": "stiffening_spring",
        "short_range_stiffness": "short_range_stiffness", "backlash": "backlash",
        "contact_clipping": "contact_clipping", "nominal_coloured_noise": "coloured_noise",
        "moving_pilot": "angle_dependent_K", "torque_dependent": "torque_dependent_K",
    }.get(kind)
    assert "reflex" in names and "servo_dynamics" in names
    if expected:
        assert expected in names
    if kind == "moving_linear":
        assert rec.truth["varies"] == ["G"] or rec.truth["varies"] == []
    tr = rec.truth
    K0 = tr["nominal"]["K"]
    assert 20 <= K0 <= 200 and 0.5 <= tr["nominal"]["B"] <= 3 and 0.01 <= tr["nominal"]["I"] <= 0.03
    assert np.all(np.isfinite(rec.trial.tau_h)) and np.all(np.isfinite(rec.trial.theta))


def test_draw_refuses_an_unknown_kind_naming_the_kinds():
    with pytest.raises(ValueError, match="unknown kind 'wobble'.*nominal"):
        labsim.draw("wobble", np.random.default_rng(0))


def test_draw_two_joints():
    spec = labsim.draw("switching+reflex", np.random.default_rng(2), n_dof=2, duration_s=4.0)
    rec = labsim.simulate(spec)
    assert rec.trial.n_dof == 2 and np.asarray(rec.truth["arrays"]["K"]).shape == (4000, 2, 2)
    K = np.asarray(rec.truth["nominal"]["K"])
    assert np.allclose(K, K.T) and np.all(np.linalg.eigvalsh(K) > 0)


@pytest.mark.parametrize("change, message", [
    (dict(servo=labsim.Servo(f_hz=-3.0)), r"servo.f_hz must be a finite number > 0.*-3.0"),
    (dict(perturbation=labsim.Perturbation(band_hz=[0, 600.0])),
     r"perturbation.band_hz\[1\] .* < 500.*600"),
    (dict(perturbation=labsim.Perturbation(kind="chirp")), r"perturbation.kind must be one of"),
    (dict(reflex=labsim.Reflex(form="fourth")), r"reflex.form must be one of .*'fourth'"),
    (dict(reflex=labsim.Reflex(delay_s=5.0)), r"reflex.delay_s .* <= 3.*5.0"),
    (dict(limb=labsim.Limb(I=-0.01)), r"limb.I must be positive semi-definite"),
    (dict(limb=labsim.Limb(K_var=labsim.Variation(time="steps"))), r"limb.K_var.time"),
    (dict(sensors=labsim.Sensors(torque_sign=2)), r"sensors.torque_sign must be 1 or -1"),
    (dict(perturbation=labsim.Perturbation(rest=[[5.0, 3.0]])), r"perturbation.rest\[0\]"),
    (dict(servo=labsim.Servo(kind="ideal"), perturbation=labsim.Perturbation(kind="prbs")),
     r"ideal servo needs a smooth reference.*prefilter_hz"),
    (dict(n_dof=2, limb=labsim.Limb(K=[1.0, 2.0, 3.0])), r"2x2"),
])
def test_bad_spec_values_are_refused_by_name(change, message):
    spec = labsim.RecordingSpec(duration_s=2.0, **change)
    with pytest.raises(ValueError, match=message):
        labsim.simulate(spec)


def test_spec_from_dict_refuses_unknown_keys_by_name():
    with pytest.raises(TypeError, match=r"limb: unknown key\(s\) \['stiffness'\]"):
        labsim.spec_from_dict({"limb": {"stiffness": 3}})
