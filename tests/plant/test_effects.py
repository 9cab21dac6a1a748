"""Each plant-side effect does what its equation says (docs/spec/effects.md)."""
from __future__ import annotations

import numpy as np
import pytest

from .helpers import run_plain
from .pymodel import Plant
from .test_physics import TS, phasor, zoh


@pytest.mark.parametrize("which", ["actuator_lag", "torque_sensor_lag"])
def test_first_order_lag_at_its_corner_frequency(slave, which):
    """At w = 1/T: magnitude 1/sqrt(2), phase -45 deg.

    actuator_lag: tau_act against tau_m.  torque_sensor_lag: tau_h with the lag against
    tau_h of the same run without it (the plant motion does not depend on the sensor);
    an actuator lag of 1 ms in both runs makes tau_h continuous.  T = 50 ms, f = 3.18 Hz,
    10 s; the ratio of the sampled phasors, with the hold's half-sample delay removed for
    tau_m, is compared with 1/(1 + j).  Tolerance: actuator lag 2e-3 relative (the hold's
    aliases are of order (w Ts)^2 = 4e-4), sensor lag 5e-3 in magnitude and 0.5 deg.
    """
    T = 0.05
    w = 1.0 / T
    periods = 10
    n = int(round(periods * 2 * np.pi / w / TS))
    f = periods / (n * TS)  # exactly an integer number of periods
    w = 2 * np.pi * f
    t = np.arange(n) * TS
    u = np.column_stack([0.5 * np.sin(w * t), 0.3 * np.cos(w * t)])
    if which == "actuator_lag":
        run = run_plain(slave, {"actuator_lag.time_constant_s": 1.0 / w},
                        u, outputs=("tau_act[1]", "tau_act[2]"))
        k0 = n // 2  # after the transient (e^-25)
        for j in (0, 1):
            y = run.y[f"tau_act[{j + 1}]"][k0 + 1:]
            ratio = phasor(y, f) / (phasor(u[k0:, j], f) * zoh(w)) * np.exp(-1j * w * TS)
            assert abs(ratio - 1 / (1 + 1j)) < 2e-3, ratio
            assert np.degrees(np.angle(ratio)) == pytest.approx(-45.0, abs=0.1)
            assert abs(ratio) == pytest.approx(1 / np.sqrt(2), rel=2e-3)
    else:
        base = {"actuator_lag.time_constant_s": 1e-3}
        a = run_plain(slave, base, u, outputs=("tau_h[1]", "tau_h[2]"))
        b = run_plain(slave, {**base, "torque_sensor_lag.time_constant_s": 1.0 / w}, u, outputs=("tau_h[1]", "tau_h[2]"))
        k0 = n // 2
        for j in (1, 2):
            ratio = phasor(b.y[f"tau_h[{j}]"][k0 + 1:], f) / phasor(a.y[f"tau_h[{j}]"][k0 + 1:], f)
            # the ripple of the held input in tau_h (direct feedthrough M_h theta'') aliases
            # differently with and without the lag: a few 1e-3 here
            assert abs(ratio) == pytest.approx(1 / np.sqrt(2), rel=5e-3)
            assert np.degrees(np.angle(ratio)) == pytest.approx(-45.0, abs=0.5)


def test_gravity_static_torque_equals_G_at_posture(slave):
    """tau_m = G(q0) holds the posture; tau_m = 0 lets it fall with a = -(M + M_h)^-1 G(q0)."""
    params = {"gravity.tilt_deg": 25.0}
    plant = Plant(params)
    G0 = plant.gravity(plant.q0)
    assert np.all(np.abs(G0) > 0.1)
    hold = run_plain(slave, params, np.tile(G0, (1000, 1)))
    for j in (1, 2):
        assert np.max(np.abs(hold.y[f"theta[{j}]"])) < 1e-12
        assert np.max(np.abs(hold.y[f"tau_h[{j}]"])) < 1e-12
    t = 1e-4  # one short step: theta = a t^2 / 2 + O(t^3), relative O(B t / M) ~ 2e-4
    fall = run_plain(slave, params, np.zeros((1, 2)), Ts=t)
    acc = -np.linalg.solve(plant.M_r(plant.q0[1]) + plant.Mh, G0)
    np.testing.assert_allclose([fall.y["theta[1]"][-1], fall.y["theta[2]"][-1]], 0.5 * acc * t**2, rtol=1e-3)


def test_transmission_compliance_encoder_reads_motor_side(slave):
    """Steady torque: the motor leads the link by tau_t / k_t; theta (encoder) is the motor."""
    kt = np.array([80.0, 60.0])
    params = {"transmission_compliance.k_t[1]": kt[0], "transmission_compliance.k_t[2]": kt[1],
              "transmission_compliance.c_t[1]": 0.5, "transmission_compliance.c_t[2]": 0.5}
    tau = np.array([0.4, -0.3])
    run = run_plain(slave, params, np.tile(tau, (20000, 1)),
                    outputs=("theta[1]", "theta[2]", "theta_link[1]", "theta_link[2]", "tau_h[1]", "tau_h[2]"))
    motor = np.array([run.y["theta[1]"][-1], run.y["theta[2]"][-1]])
    link = np.array([run.y["theta_link[1]"][-1], run.y["theta_link[2]"][-1]])
    plant = Plant(params)
    # static: K_h theta_link = tau, k_t (motor - link) = tau
    np.testing.assert_allclose(link, np.linalg.solve(plant.Kh, tau), rtol=1e-6)
    np.testing.assert_allclose(motor - link, tau / kt, rtol=1e-6)
    np.testing.assert_allclose([run.y["tau_h[1]"][-1], run.y["tau_h[2]"][-1]], tau, rtol=1e-6)


def test_transmission_compliance_adds_a_resonance():
    """The motor-side resonance appears near sqrt(k_t / Jm) in the linear model (and the FMU
    equals that model: test_physics)."""
    kt = 400.0
    plant = Plant({"transmission_compliance.k_t[1]": kt, "transmission_compliance.k_t[2]": kt})
    A, *_ = plant.linearise(np.zeros(2))
    wn = np.abs(np.linalg.eigvals(A))
    expected = np.sqrt(kt / 0.01)  # 200 rad/s; the link inertia raises it slightly
    assert np.any((wn > expected) & (wn < 1.2 * expected))
    base, *_ = Plant({}).linearise(np.zeros(2))
    assert np.max(np.abs(np.linalg.eigvals(base))) < 20.0


def test_interface_compliance_spring_relation(slave):
    """tau_h = k_s (theta - theta_h) at every sample (c_s = 0), and the arm lags the robot."""
    ks = np.array([150.0, 120.0])
    params = {"interface_compliance.k_s[1]": ks[0], "interface_compliance.k_s[2]": ks[1]}
    t = np.arange(2000) * TS
    u = np.column_stack([0.5 * np.sin(2 * np.pi * 3 * t), 0.3 * np.sin(2 * np.pi * 5 * t)])
    run = run_plain(slave, params, u, outputs=("theta[1]", "theta[2]", "theta_arm[1]", "theta_arm[2]",
                                               "tau_h[1]", "tau_h[2]", "theta_link[1]", "theta_link[2]"))
    for j in (1, 2):
        rel = run.y[f"theta[{j}]"] - run.y[f"theta_arm[{j}]"]
        np.testing.assert_allclose(run.y[f"tau_h[{j}]"], ks[j - 1] * rel, rtol=1e-12, atol=1e-14)
        np.testing.assert_array_equal(run.y[f"theta[{j}]"], run.y[f"theta_link[{j}]"])  # encoder on the robot
        assert np.max(np.abs(rel)) > 1e-5


def test_friction_level_zero_has_no_friction_state(slave):
    run = run_plain(slave, {}, np.tile([0.3, 0.2], (100, 1)), outputs=("tau_f[1]", "z[1]", "tau_f[2]", "z[2]"))
    for k in run.y.values():
        assert np.all(k == 0.0)


@pytest.mark.parametrize("level", [1, 2, 3])
def test_lugre_friction_sticks_below_coulomb_level(slave, level):
    """A constant torque 0.5 Fc: presliding only (|theta| ~ tau / sigma0), |z| <= Fs / sigma0,
    and the torque balance tau_m = tau_f + tau_h + M theta'' holds: averaged over the last
    second (the bristle oscillation, 57 rad/s, zeta 0.03, averages out) tau_f + tau_h = tau_m."""
    from fmus.variables import FRICTION_LEVELS, friction_parameters

    fl = FRICTION_LEVELS[level]
    params = friction_parameters(level)
    run = run_plain(slave, params, np.tile([0.5 * fl["Fc"], 0.0], (3000, 1)),
                    outputs=("theta[1]", "z[1]", "tau_f[1]", "tau_h[1]"))
    assert np.max(np.abs(run.y["theta[1]"])) < 2 * fl["Fs"] / 1e3
    assert np.max(np.abs(run.y["z[1]"])) <= fl["Fs"] / 1e3 + 1e-12
    balance = np.mean(run.y["tau_f[1]"][-1000:] + run.y["tau_h[1]"][-1000:])
    assert balance == pytest.approx(0.5 * fl["Fc"], rel=2e-3)
    assert np.mean(run.y["tau_f[1]"][-1000:]) > 0.9 * 0.5 * fl["Fc"]


@pytest.mark.parametrize("joint", [1, 2])
@pytest.mark.parametrize("extra", [{}, {"actuator_lag.time_constant_s": 1e-3}], ids=["fast_path", "general_path"])
def test_lugre_on_one_joint_only(slave, joint, extra):
    """Friction on one joint: its z and tau_f carry a stuck torque, the other joint has none."""
    other = 3 - joint
    params = {f"friction.Fc[{joint}]": 0.4, f"friction.Fs[{joint}]": 0.6, f"friction.sigma2[{joint}]": 0.08, **extra}
    u = np.zeros((3000, 2))
    u[:, joint - 1] = 0.2
    names = tuple(f"{v}[{j}]" for v in ("z", "tau_f", "tau_h") for j in (1, 2))
    run = run_plain(slave, params, u, outputs=names)
    balance = np.mean(run.y[f"tau_f[{joint}]"][-1000:] + run.y[f"tau_h[{joint}]"][-1000:])
    assert balance == pytest.approx(0.2, rel=2e-3)
    assert np.mean(run.y[f"z[{joint}]"][-1000:]) * 1e3 == pytest.approx(np.mean(run.y[f"tau_f[{joint}]"][-1000:]), rel=0.05)
    assert np.all(run.y[f"z[{other}]"] == 0.0) and np.all(run.y[f"tau_f[{other}]"] == 0.0)
