"""The FMI 2.0 Co-Simulation state machine is enforced: wrong-state calls return fmi2Error."""
from __future__ import annotations

import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2Error

from fmus.variables import VR


def _instantiated(slave):
    pass


def _init_mode(slave):
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()


def _step_mode(slave):
    _init_mode(slave)
    slave.exitInitializationMode()


def _terminated(slave):
    _step_mode(slave)
    slave.terminate()


# (name, setup reaching the state, the forbidden call, expected message fragment)
WRONG = [
    ("doStep before initialisation", _instantiated, lambda s: s.doStep(0.0, 1e-3), "fmi2DoStep must not be called in state Instantiated"),
    ("doStep in initialisation mode", _init_mode, lambda s: s.doStep(0.0, 1e-3), "fmi2DoStep must not be called in state InitializationMode"),
    ("doStep after terminate", _terminated, lambda s: s.doStep(0.0, 1e-3), "fmi2DoStep must not be called in state Terminated"),
    ("getReal before enterInitializationMode", _instantiated, lambda s: s.getReal([VR["theta[1]"]]), "fmi2GetReal must not be called in state Instantiated"),
    ("set fixed parameter after initialisation", _step_mode, lambda s: s.setReal([VR["robot.m1"]], [2.0]), "robot.m1 is a fixed parameter"),
    ("setReal after terminate", _terminated, lambda s: s.setReal([VR["tau_m[1]"]], [1.0]), "fmi2SetReal must not be called in state Terminated"),
    ("exitInitializationMode twice", _step_mode, lambda s: s.exitInitializationMode(), "fmi2ExitInitializationMode must not be called in state StepComplete"),
    ("enterInitializationMode twice", _init_mode, lambda s: s.enterInitializationMode(), "fmi2EnterInitializationMode must not be called in state InitializationMode"),
    ("setupExperiment in step mode", _step_mode, lambda s: s.setupExperiment(startTime=0.0), "fmi2SetupExperiment must not be called in state StepComplete"),
    ("terminate before initialisation", _instantiated, lambda s: s.terminate(), "fmi2Terminate must not be called in state Instantiated"),
    ("set an output", _step_mode, lambda s: s.setReal([VR["theta[1]"]], [1.0]), "theta[1] is an output"),
    ("unknown value reference", _step_mode, lambda s: s.getReal([9999]), "unknown value reference 9999"),
]


@pytest.mark.parametrize("case", WRONG, ids=[w[0] for w in WRONG])
def test_wrong_state_call_returns_error(make_slave, case):
    _, setup, call, fragment = case
    slave, log = make_slave()
    setup(slave)
    with pytest.raises(FMICallException) as exc:
        call(slave)
    assert exc.value.status == fmi2Error
    assert fragment in log.text()


def test_refused_call_leaves_instance_usable(make_slave):
    """A call refused by the state machine does not change the state."""
    slave, _ = make_slave()
    with pytest.raises(FMICallException):
        slave.doStep(0.0, 1e-3)
    _step_mode(slave)
    slave.doStep(0.0, 1e-3)


def test_reset_restores_defaults_and_allows_reuse(make_slave):
    slave, _ = make_slave()
    slave.setupExperiment(startTime=0.0)
    slave.setReal([VR["robot.m1"], VR["tau_m[1]"]], [2.0, 1.0])
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    slave.doStep(0.0, 1e-2)
    first = slave.getReal([VR["theta[1]"]])[0]
    assert first != 0.0
    slave.reset()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    assert slave.getReal([VR["robot.m1"], VR["tau_m[1]"], VR["theta[1]"]]) == [1.5, 0.0, 0.0]
    slave.setReal([VR["robot.m1"], VR["tau_m[1]"]], [2.0, 1.0])
    slave.exitInitializationMode()
    slave.doStep(0.0, 1e-2)
    assert slave.getReal([VR["theta[1]"]])[0] == first  # identical trial after reset


def test_fmu_state_get_set_roundtrip(make_slave):
    slave, _ = make_slave()
    _step_mode(slave)
    slave.setReal([VR["tau_m[1]"]], [1.0])
    slave.doStep(0.0, 1e-2)
    state = slave.getFMUstate()
    slave.doStep(1e-2, 1e-2)
    a = slave.getReal([VR["theta[1]"], VR["tau_h[2]"]])
    slave.setFMUstate(state)
    slave.doStep(1e-2, 1e-2)
    assert slave.getReal([VR["theta[1]"], VR["tau_h[2]"]]) == a
    slave.freeFMUstate(state)


def test_error_state_allows_only_get_reset_free(make_slave):
    slave, log = make_slave()
    _step_mode(slave)
    slave.setReal([VR["tau_m[1]"]], [1e300])
    with pytest.raises(FMICallException):
        slave.doStep(0.0, 1e-3)
    with pytest.raises(FMICallException):
        slave.doStep(1e-3, 1e-3)
    assert "fmi2DoStep must not be called in state Error" in log.text()
    slave.getReal([VR["theta[1]"]])
    slave.reset()
    _step_mode(slave)
    slave.doStep(0.0, 1e-3)
