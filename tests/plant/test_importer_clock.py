"""The plant driven the way third-party importers drive it (issue 9).

FMUComplianceChecker adds up its clock (``t += h``), OMSimulator ends a run with a residual
step of about 1e-13 s, fmpy computes ``step = next_point - time`` (which carries the rounding
of a large start time), and every importer hands its GUID to fmi2Instantiate. The FMU maps
communication points and step ends onto its own grid ``startTime + n rk4_step``; these tests
check it against an independent answer: the exact clock, one long doStep, a time-shifted run.
"""
from __future__ import annotations

import ctypes
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.fmi1 import FMICallException

from fmus.variables import VR

OUT = ("theta[1]", "theta[2]", "tau_h[1]", "tau_h[2]", "omega[1]", "omega[2]")
H = 1e-3


def _start(make_slave, start_time=0.0, params=None):
    slave, log = make_slave()
    slave.setupExperiment(startTime=start_time)
    if params:
        slave.setReal([VR[k] for k in params], [float(v) for v in params.values()])
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave, log


def _drive(slave, u, clock, t0=0.0):
    """Step the plant over len(u) H from t0 with u[k] held on [k H, (k + 1) H); returns the
    outputs after each step (len(u), 6) and the importer's final clock.

    clock 'exact': the point is t0 + k H. clock 'add': FMUComplianceChecker's loop, t += hs
    with the last step cut to the stop time (hs = stop - t), plus a residual step when the
    added-up clock ends short of the stop time.
    """
    vin = (ctypes.c_uint * 2)(VR["tau_m[1]"], VR["tau_m[2]"])
    uin = (ctypes.c_double * 2)()
    vout = (ctypes.c_uint * len(OUT))(*[VR[o] for o in OUT])
    yout = (ctypes.c_double * len(OUT))()
    c, set_real, get_real, do_step = (slave.component, slave.fmi2SetReal, slave.fmi2GetReal,
                                      slave.fmi2DoStep)
    stop = t0 + len(u) * H
    y = []
    t, k = t0, 0
    while (k < len(u)) if clock == "exact" else (t < stop):
        uin[0], uin[1] = u[min(k, len(u) - 1)]
        set_real(c, vin, 2, uin)
        tk, hs = (t0 + k * H, H) if clock == "exact" else (t, min(H, stop - t))
        status = do_step(c, tk, hs, 1)
        if status != 0:
            raise AssertionError(f"fmi2DoStep({tk!r}, {hs!r}) returned {status} at step {k}")
        get_real(c, vout, len(OUT), yout)
        y.append(yout[:])
        t, k = t + hs, k + 1
    return np.array(y), t


def _multisine(n, seed=3):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * H
    f = rng.uniform(0.2, 8.0, (6, 2))
    ph = rng.uniform(0, 2 * np.pi, (6, 2))
    return np.stack([np.sin(2 * np.pi * f[:, j, None] * t + ph[:, j, None]).sum(0) * 0.4
                     for j in (0, 1)], axis=1)


def test_accumulating_clock_over_50_s_gives_the_exact_clock_trajectory(make_slave):
    """FMUComplianceChecker's t += h over 50 s at 1 ms (it was refused at its last step)."""
    u = [tuple(r) for r in _multisine(50_000).tolist()]
    params = {"friction.Fc[1]": 0.4, "friction.Fs[1]": 0.6, "friction.sigma2[1]": 0.08}
    exact, _ = _drive(_start(make_slave, params=params)[0], u, "exact")
    slave, _ = _start(make_slave, params=params)
    added, _ = _drive(slave, u, "add")
    np.testing.assert_array_equal(added[:50_000], exact)
    np.testing.assert_array_equal(added[-1], exact[-1])  # a residual step changed nothing
    # fmi2LastSuccessfulTime: on the FMU's own grid, 5e6 * rk4_step
    assert slave.getRealStatus(2) == 5_000_000 * 1e-5


@pytest.mark.parametrize("t0, h_comm, n", [
    (1e6, 1e-3, 60_000),   # refused after 52.6 s before (OMSimulator --startTime=1e6); leads 2.8 us
    (1e6, 1e-4, 100_000),  # lags 5.3 us (more than rk4_step / 2): ends with a residual step
])
def test_added_up_clock_is_accepted_whatever_its_drift(make_slave, t0, h_comm, n):
    """Issue 16: a contiguous step (tc == previous tc + H, FMI 2.0 section 4.2.2) is accepted
    for as long as a run goes, although the added-up clock drifts beyond rk4_step / 4 from
    the FMU's grid; the trajectory equals the exact clock's (t0 + k H), bit for bit."""
    global H
    saved, H = H, h_comm
    try:
        t = t0
        for _ in range(n):
            t += h_comm
        drift = t - (t0 + n * h_comm)
        assert abs(drift) > 0.25e-5, drift  # the drift the old cap refused
        u = [tuple(r) for r in _multisine(n).tolist()]
        exact, _ = _drive(_start(make_slave, start_time=t0)[0], u, "exact", t0=t0)
        slave, _ = _start(make_slave, start_time=t0)
        added, clock = _drive(slave, u, "add", t0=t0)
    finally:
        H = saved
    np.testing.assert_array_equal(added[:n], exact)
    np.testing.assert_array_equal(added[-1], exact[-1])  # a residual step changed nothing
    assert len(added) == n + (drift < 0)                 # lagging: one residual step more
    assert slave.getRealStatus(2) == t0 + round(n * h_comm / 1e-5) * 1e-5


@pytest.mark.slow
def test_added_up_clock_from_0_over_20000_s_equals_one_long_step(make_slave):
    """t += 1 ms from 0 over 20 000 s (refused at 14 523 s before; drift 3.6 us): the state
    equals one doStep of 20 000 s (the same 2e9 RK4 steps)."""
    u = (0.3, -0.2)
    slave, _ = _start(make_slave)
    added = _drive_constant(slave, 20_000_000, u, "add")
    one, _ = _start(make_slave)
    one.setReal([VR["tau_m[1]"], VR["tau_m[2]"]], list(u))
    one.doStep(0.0, 20000.0)
    assert added == one.getReal([VR[o] for o in OUT])


def test_refused_step_says_how_far_its_end_lies_from_the_grid(make_slave):
    """A step of 1.0000004e-3 s from 0.5 s (not a whole multiple, end 4e-10 s off the grid
    beyond rounding): the message gives the ratio, the offset and the nearest grid point, and
    no longer the self-contradicting 'ratio 100'."""
    slave, log = _start(make_slave)
    slave.doStep(0.0, 0.5)
    with pytest.raises(FMICallException):
        slave.doStep(0.5, 1.0000004e-3)
    text = log.text()
    assert "communication step size 0.0010000004 s (100.00004 rk4_step)" in text, text
    assert "off by 4e-10 s" in text and "nearest point t = 0.501 s" in text, text
    assert "(ratio 100)" not in text


def _drive_constant(slave, n, u, clock):
    vin = (ctypes.c_uint * 2)(VR["tau_m[1]"], VR["tau_m[2]"])
    slave.fmi2SetReal(slave.component, vin, 2, (ctypes.c_double * 2)(*u))
    c, do_step = slave.component, slave.fmi2DoStep
    t = 0.0
    for k in range(n):
        status = do_step(c, t if clock == "add" else k * H, H, 1)
        if status != 0:
            raise AssertionError(f"fmi2DoStep({t!r}, {H}) returned {status} at step {k}")
        t += H
    return slave.getReal([VR[o] for o in OUT])


def test_accumulating_clock_over_1000_s_equals_one_long_step(make_slave):
    """t += h over 1000 s (refused at t = 715 s before): 1e6 doSteps under a constant torque
    end in the same state as one doStep of 1000 s (the same 1e8 RK4 steps, bit for bit)."""
    u = (0.3, -0.2)
    slave, _ = _start(make_slave)
    added = _drive_constant(slave, 1_000_000, u, "add")
    assert slave.getRealStatus(2) == pytest.approx(1000.0, abs=1e-9)
    one, _ = _start(make_slave)
    one.setReal([VR["tau_m[1]"], VR["tau_m[2]"]], list(u))
    one.doStep(0.0, 1000.0)
    assert added == one.getReal([VR[o] for o in OUT])


@pytest.mark.parametrize("start", [8192.0, 1e6])
def test_large_start_time_with_fmpy_gives_the_time_shifted_trajectory(fmu_path, start):
    """fmpy's exact clock was refused from t = 8192 s (its step next - t carries the rounding
    of t). The plant is time-invariant: the run equals the one started at 0. (At 1e6 s fmpy
    itself ends one point early: its isclose() takes 1e6 + 0.999 for the stop time.)"""
    kw = dict(output_interval=1e-3, start_values={"tau_m[1]": 0.5, "tau_m[2]": -0.3},
              output=list(OUT))
    late = simulate_fmu(str(fmu_path), start_time=start, stop_time=start + 1.0, **kw)
    early = simulate_fmu(str(fmu_path), start_time=0.0, stop_time=1.0, **kw)
    assert len(early) == 1001 and len(late) >= 1000
    for name in OUT:
        np.testing.assert_array_equal(late[name], early[name][:len(late)], err_msg=name)


def test_residual_step_of_1e_13_is_a_no_op(make_slave):
    """OMSimulator ends with a step of ~1e-13 s: accepted, changes nothing; the importer's
    clock then continues from the point it reached."""
    slave, _ = _start(make_slave)
    slave.setReal([VR["tau_m[1]"]], [0.5])
    t = 0.0
    for _ in range(1000):
        slave.doStep(t, H)
        t += H
    before = slave.getReal([VR[o] for o in OUT])
    slave.doStep(t, 1e-13)
    assert slave.getReal([VR[o] for o in OUT]) == before
    slave.doStep(t + 1e-13, H)  # the next point is the importer's, 1e-13 s off the grid
    assert slave.getRealStatus(2) == pytest.approx(1.001, abs=1e-15)


@pytest.mark.parametrize("point, step, fragment", [
    (0.0, 1.5e-5, "communication step size 1.5e-05 s (1.5 rk4_step) is not a whole multiple of "
                  "rk4_step = 1e-05 s (off by -5e-06 s), and the step would end at t = 1.5e-05 s, "
                  "-5e-06 s from the nearest point t = 2e-05 s of the FMU's time grid"),
    (0.0, 0.4e-5, "not a whole multiple"),                 # rounds to zero steps, but is no residual
    (1e-3 + 2e-5, 1e-3, "expected communication point 0.001 but got 0.00102"),  # a lost RK4 step
    (1e-3 - 1e-9, 1e-3, "expected communication point 0.001"),  # beyond what rounding explains
])
def test_off_grid_points_and_steps_are_still_refused(make_slave, point, step, fragment):
    slave, log = _start(make_slave)
    if point > 0:
        slave.doStep(0.0, 1e-3)
    with pytest.raises(FMICallException):
        slave.doStep(point, step)
    assert fragment in log.text(), log.text()


_GUID_SCRIPT = textwrap.dedent("""
    import sys
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    path = sys.argv[1]
    md = read_model_description(path)
    slave = FMU2Slave(guid="{%s%n%s%n}", unzipDirectory=extract(path),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="x%n%s")
    try:
        slave.instantiate(loggingOn=True)
    except Exception as exc:
        print("refused:", exc)
""")


def test_guid_with_percent_signs_is_logged_as_text(fmu_path):
    """fmpy's logger formats the message with printf: a GUID "%s%n" in it crashed fmpy.
    Run in a subprocess so that a crash fails this test instead of the test run."""
    proc = subprocess.run([sys.executable, "-c", _GUID_SCRIPT, str(fmu_path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "wrong GUID {%s%n%s%n}, expected {" in proc.stdout, proc.stdout
    assert "refused:" in proc.stdout


def test_percent_signs_reach_a_plain_logger_escaped(unzipdir):
    """A logger that does not format receives '%%' for each '%' (the FMI 2.0 message is a
    printf format), and nothing else changes."""
    from fmpy import calloc, free
    from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                           fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

    from .conftest import LogCapture

    log = LogCapture()
    slave = FMU2Slave(guid="{100%s-%n}", unzipDirectory=unzipdir, modelIdentifier="ArmExoPlant",
                      instanceName="plant")
    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(log)
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    with pytest.raises(Exception):
        slave.instantiate(loggingOn=False, callbacks=cb)
    assert len(log.messages()) == 1
    assert log.messages()[0].startswith("fmi2Instantiate: wrong GUID {100%%s-%%n}, expected {")
