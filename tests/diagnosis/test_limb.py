"""diagnosis.limb against independent answers: analytic transfer functions at steady-state
sinusoids, closed-form torques of the drift and amplitude effects, and named errors."""

import numpy as np
import pytest

from diagnosis.limb import LimbModel, limb_torque, servo_response

FS = 1000.0
T = np.arange(40_000) / FS
LIMB = LimbModel(100.0, 1.0, 0.02)


def _frf(f, effects, *, subtract_nominal=True, limb=LIMB):
    """Measured tau/theta at f [Hz] by projection on exp(-j w t) over whole periods after
    10 s of settling (first joint)."""
    th = 0.01 * np.sin(2 * np.pi * f * T)
    tau = limb_torque(th, FS, limb, effects)[:, 0]
    if subtract_nominal:
        tau = tau - limb_torque(th, FS, limb, {})[:, 0]
    n = int(round(FS / f)) * int(f * 25)
    sl = slice(10_000, 10_000 + n)
    e = np.exp(-2j * np.pi * f * T[sl])
    return (tau[sl] @ e) / (th[sl] @ e)


def _check(measured, analytic, f, rel=0.02, deg=0.5):
    # central differences cost (sin(wT)/(wT))^k in magnitude: < 2 % below 30 Hz at 1 kHz
    assert abs(measured) / abs(analytic) == pytest.approx(1.0, rel=rel), f
    assert abs(np.degrees(np.angle(measured / analytic))) < deg, f


@pytest.mark.parametrize("delay", [0.030, 0.0435, 0.060])
@pytest.mark.parametrize("f", [0.5, 2.0, 4.0, 9.0, 20.0])
def test_reflex_frf_is_the_analytic_delayed_velocity_lowpass(delay, f):
    G, fr, z = 3.0, 4.0, 0.7
    s, w = 2j * np.pi * f, 2 * np.pi * fr
    analytic = G * s * np.exp(-s * delay) * w ** 2 / (s ** 2 + 2 * z * w * s + w ** 2)
    got = _frf(f, {"stretch_reflex": {"gain": G, "delay_s": delay, "frequency_hz": fr,
                                      "damping": z}})
    _check(got, analytic, f)


@pytest.mark.parametrize("f", [1.0, 5.0, 7.0, 12.0])
def test_wobbling_mass_frf_is_mass_on_a_spring_damper(f):
    m, fw, z = 0.01, 6.0, 0.3
    s, w = 2j * np.pi * f, 2 * np.pi * fw
    k, c = m * w ** 2, 2 * z * m * w
    analytic = m * s ** 2 * (c * s + k) / (m * s ** 2 + c * s + k)
    _check(_frf(f, {"wobbling_mass": {"mass": m, "frequency_hz": fw}}), analytic, f)


@pytest.mark.parametrize("f", [1.0, 8.0, 25.0])
def test_channel_effects_multiply_the_intrinsic_impedance(f):
    s = 2j * np.pi * f
    Z = 100.0 + 1.0 * s + 0.02 * s ** 2
    lag = _frf(f, {"torque_sensor_lag": {"time_constant_s": 0.003}}, subtract_nominal=False)
    _check(lag, Z / (0.003 * s + 1), f)
    delay = _frf(f, {"channel_delay": {"delay_s": 0.0042}}, subtract_nominal=False)
    _check(delay, Z * np.exp(-s * 0.0042), f)


def test_servo_bandwidth_is_a_second_order_tracking_filter():
    f, fb, z = 6.0, 15.0, 0.7
    ref = 0.01 * np.sin(2 * np.pi * f * T)
    theta, tau = servo_response(ref, FS, LIMB, {"servo_bandwidth": {"bandwidth_hz": fb}})
    sl = slice(10_000, 10_000 + int(FS / f) * 100)
    e = np.exp(-2j * np.pi * f * T[sl])
    got = (theta[sl, 0] @ e) / (ref[sl] @ e)
    s, w = 2j * np.pi * f, 2 * np.pi * fb
    _check(got, w ** 2 / (s ** 2 + 2 * z * w * s + w ** 2), f, rel=1e-3, deg=0.05)
    np.testing.assert_allclose(tau, limb_torque(theta, FS, LIMB, {}))


def test_rectified_reflex_answers_only_stretch():
    """A monotonic shortening (negative velocity) gives no rectified reflex; the same
    lengthening gives the linear one."""
    th = -0.02 * T[:5000] / T[4999]
    p = {"gain": 2.0, "delay_s": 0.04, "frequency_hz": 3.0, "rectified": True}
    nominal = limb_torque(th, FS, LIMB, {})
    np.testing.assert_allclose(limb_torque(th, FS, LIMB, {"stretch_reflex": p}), nominal,
                               atol=1e-12)
    lin = {**p, "rectified": False}
    np.testing.assert_allclose(limb_torque(-th, FS, LIMB, {"stretch_reflex": p}),
                               limb_torque(-th, FS, LIMB, {"stretch_reflex": lin}))


def test_drift_and_amplitude_scale_the_stiffness_torque():
    limb = LimbModel(100.0, 0.0, 0.0)
    th = np.full(60_000, 0.02)
    tau = limb_torque(th, FS, limb, {"stiffness_drift": {"rate_per_min": 0.3}})[:, 0]
    np.testing.assert_allclose(tau, 100.0 * 0.02 * (1 + 0.3 * np.arange(60_000) / 60_000))
    # a constant angle has RMS |theta|: K (|theta| / A_ref)^-alpha
    tau = limb_torque(th, FS, limb, {"stiffness_amplitude": {"exponent": 0.4}})[:, 0]
    np.testing.assert_allclose(tau, 100.0 * 0.02 * (0.02 / 0.01) ** -0.4)


def test_two_joint_limb_couples_through_the_matrices():
    limb = LimbModel([[10.0, 2.0], [1.0, 8.0]], np.zeros((2, 2)), np.zeros((2, 2)))
    th = np.column_stack([np.full(100, 0.1), np.full(100, -0.2)])
    np.testing.assert_allclose(limb_torque(th, FS, limb)[0], [10 * 0.1 - 2 * 0.2,
                                                              0.1 - 8 * 0.2])


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="unknown limb/position effect 'reflex'"):
        limb_torque(np.zeros(100), FS, LIMB, {"reflex": {}})
    with pytest.raises(ValueError, match="missing parameter.*delay_s"):
        limb_torque(np.zeros(100), FS, LIMB, {"stretch_reflex": {"gain": 1,
                                                                 "frequency_hz": 3}})
    with pytest.raises(ValueError, match="unknown parameter.*tau"):
        limb_torque(np.zeros(100), FS, LIMB, {"torque_sensor_lag": {"time_constant_s": 1e-3,
                                                                    "tau": 1}})
    with pytest.raises(ValueError, match="2 joint column"):
        limb_torque(np.zeros((100, 2)), FS, LIMB)
    bad = np.zeros(100)
    bad[17] = np.nan
    with pytest.raises(ValueError, match="sample 17, joint 1"):
        limb_torque(bad, FS, LIMB)
    with pytest.raises(ValueError, match="differ in shape"):
        LimbModel(np.eye(2), 1.0, 1.0)


def test_fractional_delay_shifts_a_ramp_exactly_and_holds_the_edges():
    from diagnosis.limb import fractional_delay
    x = np.arange(20.0)[:, None]
    np.testing.assert_allclose(fractional_delay(x, 0.3)[1:, 0], x[1:, 0] - 0.3)
    np.testing.assert_allclose(fractional_delay(x, 1e-9)[:, 0], x[:, 0], atol=1e-8)
    np.testing.assert_allclose(fractional_delay(x, -2.5)[:17, 0], x[:17, 0] + 2.5)
    assert fractional_delay(x, 0.3)[0, 0] == 0.0 and fractional_delay(x, -2.5)[-1, 0] == 19.0


def test_sensor_lag_is_continuous_down_to_tiny_time_constants():
    """A time constant below 1/(pi fs) (corner above Nyquist) used to become the identity
    and then crash channel_apply in lfilter_zi; now the response is a smooth function of
    T that tends to the identity, and T == 0 is the identity exactly."""
    from diagnosis.limb import channel_apply, first_order_lowpass
    from scipy import signal as sps

    rng = np.random.default_rng(3)
    tau = np.cumsum(rng.standard_normal((2000, 2)), axis=0)
    prev = None
    for T in (2e-3, 4e-4, 3.2e-4, 3.1e-4, 1e-4, 5e-5, 1e-6):
        out = channel_apply(tau, FS, {"torque_sensor_lag": {"time_constant_s": T}})
        assert np.all(np.isfinite(out)), T
        step = np.abs(out - tau).max()
        if prev is not None:
            assert step < prev, T  # monotonically closer to the identity as T shrinks
        prev = step
        b, a = first_order_lowpass(T, FS)
        _, h = sps.freqz(b, a, [10.0], fs=FS)
        analytic = 1 / (2j * np.pi * 10.0 * T + 1)
        assert abs(h[0] / analytic - 1) < 1e-3, T
    assert prev < 1e-3 * np.abs(tau).max()
    # continuous across the old switch at 1/(pi fs)
    edge = 1 / (np.pi * FS)
    lo = channel_apply(tau, FS, {"torque_sensor_lag": {"time_constant_s": edge * 0.999}})
    hi = channel_apply(tau, FS, {"torque_sensor_lag": {"time_constant_s": edge * 1.001}})
    assert np.abs(hi - lo).max() < 1e-3 * np.abs(tau).max()
    np.testing.assert_array_equal(
        channel_apply(tau, FS, {"torque_sensor_lag": {"time_constant_s": 0.0}}), tau)
    with pytest.raises(ValueError, match="time_constant_s"):
        first_order_lowpass(-1e-3, FS)


def test_fractional_delay_is_the_linear_interpolation_bit_for_bit():
    """fractional_delay: (1 - frac) x[i0] + frac x[i1] with the edges held, the very
    numbers of that formula (its in-place form is a speed-up only), any dtype."""
    import numpy as np
    from diagnosis import limb as lm
    rng = np.random.default_rng(3)
    for shape in [(4000, 1), (3000, 3)]:
        for dtype in (float, np.float32):
            x = rng.standard_normal(shape).astype(dtype)
            n = shape[0]
            for d in (40.3, -3.7, 0.5, 2.0, 1e-9, 5000.2, -7.0):
                idx = np.arange(n) - d
                lo = np.floor(idx)
                frac = (idx - lo)[:, None]
                i0 = np.clip(lo.astype(int), 0, n - 1)
                i1 = np.clip(lo.astype(int) + 1, 0, n - 1)
                ref = (1.0 - frac) * x[i0] + frac * x[i1]
                got = lm.fractional_delay(x, d)
                assert got.dtype == ref.dtype
                np.testing.assert_array_equal(got, ref)
