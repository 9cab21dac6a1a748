"""Bad parameters and inputs are refused with a logged message naming them; the host never crashes."""
from __future__ import annotations

import re

import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2Error

from fmus.variables import VR, friction_parameters

BAD_PARAMETERS = [
    ({"robot.I1": -0.01}, "robot.I1 = -0.01"),
    ({"robot.m2": 0.0}, "robot.m2 = 0"),
    ({"robot.L1": -0.3}, "robot.L1 = -0.3"),
    ({"robot.Jm[2]": -1e-3}, "robot.Jm[2] = -0.001"),
    ({"rk4_step": 0.0}, "rk4_step = 0"),
    ({"rk4_step": -1e-5}, "rk4_step = -1e-05"),
    ({"inertia_mismatch.scale": 0.0}, "inertia_mismatch.scale = 0"),
    ({"actuator_lag.time_constant_s": -0.01}, "actuator_lag.time_constant_s = -0.01"),
    ({"torque_sensor_lag.time_constant_s": -1.0}, "torque_sensor_lag.time_constant_s = -1"),
    ({"transmission_compliance.k_t[1]": -5.0}, "transmission_compliance.k_t[1] = -5"),
    ({"interface_compliance.c_s[2]": -1.0}, "interface_compliance.c_s[2] = -1"),
    ({**friction_parameters(2), "friction.Fs[1]": 0.1}, "friction.Fs[1] = 0.1"),   # Fs < Fc
    ({**friction_parameters(2), "friction.ws": 0.0}, "friction.ws = 0"),
    ({"friction.Fs[1]": 0.2}, "friction.Fc[1] = 0"),                                 # Fs > 0 with Fc = 0
    ({"interface_compliance.k_s[1]": 100.0}, "interface_compliance.k_s[2] = 0"),
    ({"transmission_compliance.k_t[1]": 100.0, "robot.Jm[1]": 0.0}, "robot.Jm[1] = 0"),
    ({"arm.M_h[1,1]": -0.5}, "singular or not positive definite"),
]


@pytest.mark.parametrize("params,fragment", BAD_PARAMETERS, ids=[b[1] for b in BAD_PARAMETERS])
def test_bad_parameter_refused_in_exit_initialization(make_slave, params, fragment):
    slave, log = make_slave()
    slave.setupExperiment(startTime=0.0)
    slave.setReal([VR[k] for k in params], list(params.values()))
    slave.enterInitializationMode()
    with pytest.raises(FMICallException) as exc:
        slave.exitInitializationMode()
    assert exc.value.status == fmi2Error
    assert fragment in log.text(), log.text()
    slave.reset()  # usable again


def _started(make_slave, params=None):
    slave, log = make_slave()
    slave.setupExperiment(startTime=0.0)
    if params:
        slave.setReal([VR[k] for k in params], list(params.values()))
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave, log


def test_communication_step_not_a_multiple_of_rk4_step(make_slave):
    slave, log = _started(make_slave)
    with pytest.raises(FMICallException):
        slave.doStep(0.0, 1.5e-5)
    msg = log.text()
    assert ("communication step size 1.5e-05 s (1.5 rk4_step) is not a whole multiple of "
            "rk4_step = 1e-05 s") in msg
    assert "the step would end at t = 1.5e-05 s, -5e-06 s from the nearest point" in msg


def test_communication_point_must_match_internal_time(make_slave):
    slave, log = _started(make_slave)
    slave.doStep(0.0, 1e-3)
    with pytest.raises(FMICallException):
        slave.doStep(0.00099, 1e-3)
    assert "expected communication point 0.001 but got 0.00099" in log.text()


def test_rounded_master_clock_is_accepted(make_slave):
    """t = k * H computed by the master differs from ours by rounding only: accepted."""
    slave, _ = _started(make_slave)
    t = 0.0
    for _ in range(100):
        slave.doStep(t, 0.001)
        t += 0.001  # accumulated on purpose: rounding error ~1e-17
    assert slave.getRealStatus(2) == pytest.approx(0.1, abs=1e-15)


def test_non_positive_step_size(make_slave):
    slave, log = _started(make_slave)
    with pytest.raises(FMICallException):
        slave.doStep(0.0, 0.0)
    assert "communication step size must be finite and > 0, got 0" in log.text()


def test_non_finite_input_refused(make_slave):
    slave, log = _started(make_slave)
    with pytest.raises(FMICallException):
        slave.setReal([VR["tau_m[2]"]], [float("nan")])
    assert "tau_m[2] = nan is not finite" in log.text()


def test_huge_torque_stops_step_naming_state_and_time(make_slave):
    slave, log = _started(make_slave)
    slave.doStep(0.0, 1e-3)
    slave.setReal([VR["tau_m[1]"]], [1e300])
    with pytest.raises(FMICallException) as exc:
        slave.doStep(1e-3, 1e-3)
    assert exc.value.status == fmi2Error
    m = re.search(r"state (\S+) became non-finite \((\S+)\) in the RK4 step from t = (\S+) s", log.text())
    assert m, log.text()
    assert m.group(1) in {"theta_link[1]", "theta_link[2]", "omega_link[1]", "omega_link[2]"}
    assert 1e-3 <= float(m.group(3)) < 2e-3


def test_absurd_parameter_blows_up_with_message(make_slave):
    """An (allowed) absurd LuGre stiffness with a coarse step diverges: error, no crash."""
    params = {**friction_parameters(3), "friction.sigma0": 1e12, "rk4_step": 1e-4}
    slave, log = _started(make_slave, params)
    slave.setReal([VR["tau_m[1]"], VR["tau_m[2]"]], [2.0, 1.0])
    with pytest.raises(FMICallException):
        for k in range(100):
            slave.doStep(k * 1e-3, 1e-3)
    assert "became non-finite" in log.text()


def test_variable_communication_steps_and_start_time(make_slave):
    """Whole multiples of rk4_step of any size, from any start time; the clock is exact."""
    slave, _ = make_slave()
    slave.setupExperiment(startTime=10.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    t = 10.0
    for H in (1e-3, 2e-3, 5e-4, 1e-5, 0.0123):
        slave.doStep(t, H)
        t += H
    assert slave.getRealStatus(2) == pytest.approx(10.0 + 0.01581, abs=1e-12)


def test_same_trajectory_whatever_the_communication_grid(make_slave):
    """Constant input: 1 x 10 ms, 10 x 1 ms and 1000 x 10 us give the same state (same RK4 steps)."""
    out = []
    for n, H in ((1, 1e-2), (10, 1e-3), (1000, 1e-5)):
        slave, _ = _started(make_slave, friction_parameters(3))
        slave.setReal([VR["tau_m[1]"], VR["tau_m[2]"]], [0.8, -0.5])
        for k in range(n):
            slave.doStep(k * H, H)
        out.append(slave.getReal([VR[v] for v in ("theta[1]", "theta[2]", "omega[1]", "z[2]")]))
    assert out[0] == out[1] == out[2]
