"""labsim against independent answers: analytic transfer functions computed here, FRFs
estimated from the simulated data with scipy's csd/welch, the truth against the spec.

Short trials (10-20 s) keep the file fast.
"""

import numpy as np
import pytest
from scipy import signal

import labsim
from labsim.lti import StateSpace, affine_scan, play_scan

FS = 1000.0


def frf_at_lines(theta, tau, fs, period_s):
    """H = S_theta,tau / S_theta,theta with a boxcar window of one period (whole periods:
    no leakage), at every frequency bin; frequencies [Hz]."""
    n = int(round(period_s * fs))
    f, pxy = signal.csd(theta, tau, fs, window="boxcar", nperseg=n, noverlap=0)
    _, pxx = signal.welch(theta, fs, window="boxcar", nperseg=n, noverlap=0)
    keep = pxx > 1e-12 * pxx.max()  # the excited lines
    return f[keep], pxy[keep] / pxx[keep]


def periodic_spec(**kw):
    pert = labsim.Perturbation(kind="multisine", amplitude_rad=0.02, band_hz=[0.5, 40.0],
                               period_s=5.0)
    base = dict(duration_s=20.0, fs=FS, perturbation=pert, preroll_s=5.0)
    base.update(kw)
    return labsim.RecordingSpec(**base)


def excited(f, lo=0.5, hi=40.0):
    return (f >= lo - 1e-9) & (f <= hi + 1e-9)


@pytest.mark.parametrize("servo", ["ideal", "pd"])
def test_linear_limb_frf_is_k_b_i(servo):
    K, B, I = 120.0, 1.7, 0.021
    spec = periodic_spec(servo=labsim.Servo(kind=servo), limb=labsim.Limb(K=K, B=B, I=I))
    rec = labsim.simulate(spec)
    f, H = frf_at_lines(rec.trial.theta[:, 0], rec.trial.tau_h[:, 0], FS, 5.0)
    sel = excited(f)
    w = 2 * np.pi * f[sel]
    Z = K + 1j * w * B - w ** 2 * I
    np.testing.assert_allclose(H[sel], Z, rtol=2e-6)


def test_welch_frf_of_noise_perturbation_within_two_percent():
    K, B, I = 60.0, 0.9, 0.013
    spec = labsim.RecordingSpec(duration_s=30.0, limb=labsim.Limb(K=K, B=B, I=I),
                                perturbation=labsim.Perturbation(kind="noise",
                                                                 band_hz=[0.0, 45.0]))
    rec = labsim.simulate(spec)
    x, y = rec.trial.theta[:, 0], rec.trial.tau_h[:, 0]
    f, pxy = signal.csd(x, y, FS, nperseg=4096)
    _, pxx = signal.welch(x, FS, nperseg=4096)
    sel = (f >= 0.5) & (f <= 40)
    w = 2 * np.pi * f[sel]
    Z = K + 1j * w * B - w ** 2 * I
    assert np.max(np.abs(pxy[sel] / pxx[sel] / Z - 1)) < 0.02


def test_pd_servo_is_loaded_by_the_limb_as_its_closed_loop_says():
    """theta / theta_ref of the PD servo with actuator lag T, from the loop's equations:
    x/r = Kp / ((1 + T s)(M s^2 + B s + K) + Kp + Kd s), M = J_m + I."""
    K, B, I, Jm, T = 150.0, 2.0, 0.02, 0.03, 0.0008
    servo = labsim.Servo(kind="pd", f_hz=40.0, damping=0.7, motor_inertia=Jm,
                         actuator_lag_s=T)
    # the recorded reference is digital: no anti-alias filter on the angle either here
    rec = labsim.simulate(periodic_spec(servo=servo, limb=labsim.Limb(K=K, B=B, I=I),
                                        sensors=labsim.Sensors(antialias=None)))
    f, H = frf_at_lines(rec.trial.theta_ref[:, 0], rec.trial.theta[:, 0], FS, 5.0)
    sel = excited(f)
    s = 2j * np.pi * f[sel]
    M = Jm + I
    w = 2 * np.pi * 40.0
    Kp, Kd = M * w * w, 2 * 0.7 * M * w
    expected = Kp / ((1 + T * s) * (M * s * s + B * s + K) + Kp + Kd * s)
    np.testing.assert_allclose(H[sel], expected, rtol=1e-5)
    # the servo is finitely stiff: the joint does not follow the reference exactly
    assert np.max(np.abs(H[sel] - 1)) > 0.05
    assert rec.truth["servo"]["Kp"][0] == pytest.approx(Kp)


@pytest.mark.parametrize("form", ["second_order", "triple_pole", "cascade"])
def test_reflex_pathway_alone_is_its_transfer_function(form):
    """Without rectification: tau = G e^{-s d} LP(s) s theta, LP per form (unit DC)."""
    G, d, f0, zeta, tau_s = 25.0, 0.045, 2.5, 0.45, 0.03
    reflex = labsim.Reflex(gain=G, delay_s=d, rectify="none", form=form, f_hz=f0,
                           damping=zeta, tau_s=tau_s)
    spec = periodic_spec(servo=labsim.Servo(kind="ideal"), reflex=reflex,
                         limb=labsim.Limb(K=0.0, B=0.0, I=0.0))
    rec = labsim.simulate(spec)
    f, H = frf_at_lines(rec.trial.theta[:, 0], rec.trial.tau_h[:, 0], FS, 5.0)
    sel = excited(f)
    s = 2j * np.pi * f[sel]
    w = 2 * np.pi * f0
    second = w * w / (s * s + 2 * zeta * w * s + w * w)
    lp = {"second_order": second, "triple_pole": (w / (s + w)) ** 3,
          "cascade": second / (tau_s * s + 1)}[form]
    expected = G * np.exp(-s * d) * lp * s
    np.testing.assert_allclose(H[sel], expected, rtol=2e-5, atol=1e-6 * np.abs(expected).max())


def test_rectified_reflex_responds_to_stretch_only():
    reflex = labsim.Reflex(gain=30.0, delay_s=0.04, rectify="positive", threshold_rad_s=0.1)
    spec = periodic_spec(servo=labsim.Servo(kind="ideal"), reflex=reflex,
                         limb=labsim.Limb(K=0.0, B=0.0, I=0.0))
    rec = labsim.simulate(spec)
    r = rec.truth["arrays"]["tau_reflex"]
    assert r.min() > -1e-9 * r.max()  # a positive-velocity rectifier: never negative
    assert r.max() > 0.1


def test_square_wave_stiffness_truth_and_data():
    K0, ratio, period = 50.0, 3.0, 8.0
    var = labsim.Variation(time="switching", ratio=ratio, period_s=period)
    spec = labsim.RecordingSpec(duration_s=16.0, servo=labsim.Servo(kind="ideal"),
                                limb=labsim.Limb(K=K0, B=1.0, I=0.015, K_var=var),
                                sensors=labsim.Sensors(antialias=None),
                                perturbation=labsim.Perturbation(kind="noise", band_hz=[0, 20]))
    rec = labsim.simulate(spec)
    t, K = rec.truth["arrays"]["t"], rec.truth["arrays"]["K"]
    expected = np.where(np.floor(t / (period / 2)) % 2 == 1, ratio * K0, K0)
    np.testing.assert_array_equal(K, expected)
    assert rec.truth["varies"] == ["K"]
    # the data carry it: a least-squares K per half-period (B, I known) from the angle
    x, y = rec.trial.theta[:, 0], rec.trial.tau_h[:, 0]
    v = np.gradient(x, 1 / FS)
    a = np.gradient(v, 1 / FS)
    rest = y - 1.0 * v - 0.015 * a
    for k in range(4):
        blk = slice(int((k * period / 2 + 0.2) * FS), int(((k + 1) * period / 2 - 0.2) * FS))
        k_hat = np.dot(x[blk], rest[blk]) / np.dot(x[blk], x[blk])
        assert k_hat == pytest.approx(K0 * (ratio if k % 2 else 1.0), rel=0.01)


def test_moving_joint_slow_angle_has_the_range_asked():
    mov = labsim.Movement(kind="sine", range_rad=[-0.4, 0.2], period_s=8.0)
    var = labsim.Variation(angle="exp", angle_coef=3.0)
    spec = labsim.RecordingSpec(duration_s=16.0, movement=mov,
                                limb=labsim.Limb(K=60.0, K_var=var),
                                perturbation=labsim.Perturbation(amplitude_rad=0.01))
    rec = labsim.simulate(spec)
    sv = rec.trial.extra["sv"]
    assert sv.min() == pytest.approx(-0.4, abs=1e-5) and sv.max() == pytest.approx(0.2, abs=1e-5)
    np.testing.assert_array_equal(sv, rec.truth["arrays"]["sv"])
    # the joint moves through the range with the perturbation on top
    th = rec.trial.theta[:, 0]
    assert th.min() < -0.38 and th.max() > 0.18
    # K follows its angle law at the slow angle
    np.testing.assert_allclose(rec.truth["arrays"]["K"], 60.0 * np.exp(3.0 * sv), rtol=1e-12)
    assert rec.truth["K_of_rho"]["K"][0] == pytest.approx(60.0 * np.exp(3.0 * -0.4), rel=1e-6)


def test_noise_spectra_pink_slope_and_hum_lines():
    """Pink noise on the angle channel, hum (50 Hz and a half-amplitude 2nd harmonic) over
    a weak white floor on the torque channel."""
    pink = labsim.Channel(pink_std=1e-4)
    mains = labsim.Channel(white_std=1e-4, hum_std=0.02, hum_hz=50.0, hum_harmonics=[1.0, 0.5])
    spec = labsim.RecordingSpec(duration_s=60.0, sensors=labsim.Sensors(theta=pink, tau=mains),
                                perturbation=labsim.Perturbation(amplitude_rad=1e-12),
                                servo=labsim.Servo(kind="ideal"))
    rec = labsim.simulate(spec)
    f, p = signal.welch(rec.trial.theta[:, 0], FS, nperseg=8192)
    band = (f > 1) & (f < 300)
    slope = np.polyfit(np.log10(f[band]), np.log10(p[band]), 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.05)
    assert np.std(rec.trial.theta[:, 0]) == pytest.approx(1e-4, rel=0.01)
    hum = rec.trial.tau_h[:, 0]
    f, p = signal.welch(hum, FS, nperseg=8192)
    k50, k100, k150 = (np.argmin(np.abs(f - x)) for x in (50, 100, 150))
    assert p[k50] > 1e4 * np.median(p[k50 - 30:k50 - 10])
    assert p[k150] < 1e-3 * p[k50]  # no third harmonic was asked

    def line_power(k):
        return np.sum(p[k - 4:k + 5])
    assert line_power(k100) / line_power(k50) == pytest.approx(0.25, rel=0.01)
    assert np.std(hum) == pytest.approx(np.hypot(0.02, 1e-4), rel=0.01)


def test_channel_delay_is_a_pure_lag_between_channels():
    d = 0.0023
    spec = periodic_spec(servo=labsim.Servo(kind="ideal"),
                         sensors=labsim.Sensors(tau=labsim.Channel(delay_s=d)),
                         limb=labsim.Limb(K=80.0, B=1.2, I=0.015))
    rec = labsim.simulate(spec)
    f, H = frf_at_lines(rec.trial.theta[:, 0], rec.trial.tau_h[:, 0], FS, 5.0)
    sel = excited(f, hi=20.0)
    w = 2 * np.pi * f[sel]
    Z = (80.0 + 1j * w * 1.2 - w ** 2 * 0.015) * np.exp(-1j * w * d)
    np.testing.assert_allclose(H[sel], Z, rtol=2e-3)  # linear interpolation of the delay


def test_torque_sensor_filter_changes_the_frf_as_its_transfer_function():
    flt = labsim.Filter(kind="second_order", cutoff_hz=80.0, damping=0.6)
    spec = periodic_spec(servo=labsim.Servo(kind="ideal"),
                         sensors=labsim.Sensors(tau=labsim.Channel(filter=flt)),
                         limb=labsim.Limb(K=80.0, B=1.2, I=0.015))
    rec = labsim.simulate(spec)
    f, H = frf_at_lines(rec.trial.theta[:, 0], rec.trial.tau_h[:, 0], FS, 5.0)
    sel = excited(f)
    s = 2j * np.pi * f[sel]
    wn = 2 * np.pi * 80.0
    Z = (80.0 + s * 1.2 + s * s * 0.015) * wn ** 2 / (s * s + 1.2 * wn * s + wn ** 2)
    np.testing.assert_allclose(H[sel], Z, rtol=1e-5)


def test_wobbling_mass_frf():
    """tau_w / x = I_w s^2 (b s + k) / (I_w s^2 + b s + k) added to the rigid K-B-I."""
    Iw, fw, zw = 0.004, 15.0, 0.2
    spec = periodic_spec(servo=labsim.Servo(kind="pd"), limb=labsim.Limb(K=80, B=1.2, I=0.015),
                         wobbling=labsim.WobblingMass(inertia=Iw, f_hz=fw, damping=zw))
    rec = labsim.simulate(spec)
    f, H = frf_at_lines(rec.trial.theta[:, 0], rec.trial.tau_h[:, 0], FS, 5.0)
    sel = excited(f)
    s = 2j * np.pi * f[sel]
    wn = 2 * np.pi * fw
    k, b = Iw * wn * wn, 2 * zw * Iw * wn
    Z = 80 + 1.2 * s + 0.015 * s * s + Iw * s * s * (b * s + k) / (Iw * s * s + b * s + k)
    np.testing.assert_allclose(H[sel], Z, rtol=1e-5)


def test_sensor_and_limb_torques_agree_in_a_nonlinear_loop():
    """The torque the sensor reads (motor side, u - J_m x'') equals the limb's own sum once
    the waveform relaxation has converged (friction, reflex, time variation at once)."""
    spec = labsim.RecordingSpec(
        duration_s=10.0, reflex=labsim.Reflex(),
        footplate=labsim.Footplate(friction="tanh", friction_fraction=0.1, v_s=0.05),
        limb=labsim.Limb(K_var=labsim.Variation(time="sine", ratio=1.5, period_s=4.0)))
    rec = labsim.simulate(spec)
    solver = rec.truth["solver"]
    assert solver["residual"] < 1e-7
    assert solver["limb_vs_sensor_max_nm"] < 1e-6 * rec.truth["rms"]["tau_h"]


def test_lugre_friction_against_an_ode_solver():
    """The scan's LuGre (exact step with v held) against scipy's RK45 on the same ODE,
    z' = v - sigma0 |v| z / g(v), for a velocity through reversals; and sliding: F = Fc."""
    from scipy.integrate import solve_ivp
    from labsim.limb import lugre
    fp = labsim.Footplate(friction="lugre", Fc=0.5, Fs=0.8, v_s=0.05, sigma0=1e4,
                          sigma1=0.3, sigma2=0.02)
    h = 1e-5
    t = np.arange(int(0.5 / h)) * h
    vel = lambda tt: 0.6 * np.sin(2 * np.pi * 3 * tt) + 0.2 * np.sin(2 * np.pi * 11 * tt)
    F = lugre(vel(t)[None, :], fp, h)[0]

    def rhs(tt, z):
        v = vel(tt)
        g = fp.Fc + (fp.Fs - fp.Fc) * np.exp(-(v / fp.v_s) ** 2)
        return v - fp.sigma0 * abs(v) * z / g

    sol = solve_ivp(rhs, (0, t[-1]), [0.0], t_eval=t, rtol=1e-10, atol=1e-14, method="LSODA")
    z = sol.y[0]
    v = vel(t)
    g = fp.Fc + (fp.Fs - fp.Fc) * np.exp(-(v / fp.v_s) ** 2)
    F_ref = fp.sigma0 * z + fp.sigma1 * (v - fp.sigma0 * np.abs(v) * z / g) + fp.sigma2 * v
    assert np.max(np.abs(F - F_ref)) < 1e-3 * fp.Fs
    sliding = np.abs(v) > 20 * fp.v_s
    np.testing.assert_allclose(F[sliding] - fp.sigma2 * v[sliding],
                               fp.Fc * np.sign(v[sliding]), rtol=2e-2)
    assert np.max(np.abs(fp.sigma0 * z)) <= fp.Fs * (1 + 1e-9)


def test_fine_grid_lti_is_exact_for_piecewise_linear_input():
    rng = np.random.default_rng(0)
    w = 2 * np.pi * 5
    for zeta in (0.3, 2.0):
        sys = StateSpace.from_tf([w * w], [1, 2 * zeta * w, w * w], derivatives=2)
        h = 1e-4
        t = np.arange(5000) * h
        u = rng.standard_normal(t.size)
        y = sys.simulate(u, h)
        _, ref, _ = signal.lsim((sys.A, sys.B, sys.C, sys.D), u, t)  # FOH, matrix exponential
        np.testing.assert_allclose(y.T, ref, atol=1e-12 * np.abs(ref).max())


def test_scans_equal_their_loops():
    rng = np.random.default_rng(1)
    c, d = rng.uniform(0, 1, 3000), rng.standard_normal(3000)
    x, ref = 0.3, []
    for k in range(3000):
        x = c[k] * x + d[k]
        ref.append(x)
    np.testing.assert_allclose(affine_scan(c, d, 0.3), ref, rtol=1e-12, atol=1e-12)
    xx = np.cumsum(rng.standard_normal(3000))
    y, ref = 0.0, []
    for v in xx:
        y = min(max(y, v - 0.7), v + 0.7)
        ref.append(y)
    np.testing.assert_array_equal(play_scan(xx, 0.7), ref)


def test_same_seed_same_bits_other_seed_other_noise():
    spec = labsim.draw("voluntary+reflex", np.random.default_rng(5), duration_s=5.0)
    a, b = labsim.simulate(spec), labsim.simulate(spec)
    for s in ("theta", "tau_h", "theta_ref"):
        assert np.array_equal(getattr(a.trial, s), getattr(b.trial, s))
    for k, v in a.truth["arrays"].items():
        assert np.array_equal(v, b.truth["arrays"][k]), k
    spec.seed += 1
    c = labsim.simulate(spec)
    assert not np.array_equal(a.trial.tau_h, c.trial.tau_h)
