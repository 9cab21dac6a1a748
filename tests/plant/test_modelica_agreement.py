"""The Modelica model of record (modelica/ArmExo) and the C FMU agree.

rumoca 0.10.2 compiles the package from source (packages with ``within``, partial models
and ``extends``, parameter arrays and matrices, for-loops, structural if-equations,
modifiers, array comprehensions) and simulates the examples.  It takes no time-varying
input from Python, so the input is defined inside each example (a sum of sines of time).

The FMU is driven with the same sines, held over communication steps of H = 0.1 ms at
their mid-step value (error ~ (w H)^2 / 24 < 3e-6 of the input at 11 Hz), and its outputs
are read at t_k after setting the exact input u(t_k), because tau_h depends directly on the
input.  Tolerance: 2e-5 of each signal's peak.  Measured: 1e-7 to 4e-6 (the friction
example is the largest, from the stiff bristle dynamics and rumoca's tolerances rtol 1e-8,
atol 1e-10); an error in any term of the equations shows as 1e-3 or more.
"""
from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest

from fmus import variables as V
from fmus.variables import VR, friction_parameters

rm = pytest.importorskip("rumoca")

MODELICA = Path(__file__).resolve().parents[2] / "modelica"
OUTPUTS = ("theta[1]", "theta[2]", "tau_h[1]", "tau_h[2]", "omega[1]", "omega[2]")

EFFECTS = {"actuator_lag.time_constant_s": 0.003,
           "transmission_compliance.k_t[1]": 300.0, "transmission_compliance.k_t[2]": 300.0,
           "transmission_compliance.c_t[1]": 0.5, "transmission_compliance.c_t[2]": 0.5,
           "interface_compliance.k_s[1]": 400.0, "interface_compliance.k_s[2]": 400.0,
           "interface_compliance.c_s[1]": 2.0, "interface_compliance.c_s[2]": 2.0,
           "gravity.tilt_deg": 10.0, "inertia_mismatch.scale": 0.8,
           "torque_sensor_lag.time_constant_s": 0.002}
EXAMPLES = {  # example model -> FMU parameters of the same experiment
    "SumOfSines": {},
    "SumOfSinesFriction": friction_parameters(3),
    "SumOfSinesEffects": {**EFFECTS, **friction_parameters(2)},  # friction on the motor side
}


def sines(t):
    """The input of ArmExo.Examples.SumOfSines [N m], shape (len(t), 2)."""
    return np.column_stack([0.5 * np.sin(2 * np.pi * 1.5 * t) + 0.2 * np.sin(2 * np.pi * 7.0 * t),
                            0.3 * np.sin(2 * np.pi * 2.5 * t) + 0.15 * np.sin(2 * np.pi * 11.0 * t)])


@pytest.fixture(scope="module")
def session():
    return rm.Session(roots=[str(MODELICA)])


def simulate_fmu(slave, params, t_end=2.0, H=1e-4, every=10):
    """Outputs at multiples of every * H, read with the exact input u(t) set."""
    slave.reset()
    slave.setupExperiment(startTime=0.0)
    if params:
        slave.setReal([VR[k] for k in params], list(params.values()))
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    n = int(round(t_end / H))
    u_mid = sines((np.arange(n) + 0.5) * H)
    u_at = sines(np.arange(n + 1) * H)
    c = slave.component
    vin = (ctypes.c_uint * 2)(VR["tau_m[1]"], VR["tau_m[2]"])
    vout = (ctypes.c_uint * len(OUTPUTS))(*[VR[o] for o in OUTPUTS])
    uin, yout = (ctypes.c_double * 2)(), (ctypes.c_double * len(OUTPUTS))()
    Y = []
    for k in range(n + 1):
        if k % every == 0:
            uin[0], uin[1] = u_at[k]
            slave.fmi2SetReal(c, vin, 2, uin)
            slave.fmi2GetReal(c, vout, len(OUTPUTS), yout)
            Y.append(list(yout))
        if k == n:
            break
        uin[0], uin[1] = u_mid[k]
        slave.fmi2SetReal(c, vin, 2, uin)
        slave.fmi2DoStep(c, k * H, H, 1)
    return np.array(Y)


@pytest.mark.parametrize("example", list(EXAMPLES))
def test_modelica_example_matches_c_fmu(session, slave, example):
    model = session.load(str(MODELICA / "ArmExo" / "Examples" / f"{example}.mo"), model=f"ArmExo.Examples.{example}")
    res = model.simulate(t=(0.0, 2.0), dt=1e-3, config=rm.SimConfig(rtol=1e-8, atol=1e-10))
    t = np.asarray(res.time)
    assert len(t) == 2001 and abs(t[-1] - 2.0) < 1e-12
    Y = simulate_fmu(slave, EXAMPLES[example])
    for i, name in enumerate(OUTPUTS):
        ym = np.asarray(res[f"plant.{name}"])
        peak = np.max(np.abs(Y[:, i]))
        assert peak > 1e-3
        err = np.max(np.abs(ym - Y[:, i])) / peak
        assert err < 2e-5, (name, err)


def test_modelica_parameters_have_the_fmu_names_and_units(session):
    """Every FMU parameter (but the C solver's rk4_step) exists in ArmExo.ArmExoPlant, same unit."""
    model = session.load(str(MODELICA / "ArmExo" / "ArmExoPlant.mo"), model="ArmExo.ArmExoPlant")
    params = {p.name: p for p in model.parameters}
    for name in V.PARAMETERS:
        if name == "rk4_step":
            continue
        base = name.split("[")[0]
        assert base in params, name
        assert (params[base].unit or "") in (V.BY_NAME[name].unit, "1" if V.BY_NAME[name].unit == "" else None), name
        if "[" not in name and params[base].value is not None:
            assert params[base].value == pytest.approx(V.BY_NAME[name].start), name
    assert set(model.outputs.names) >= {"theta", "tau_h", "omega"}
    assert model.inputs.names == ["tau_m"]


def test_gravity_hold_example_keeps_the_posture(session):
    model = session.load(str(MODELICA / "ArmExo" / "Examples" / "GravityHold.mo"), model="ArmExo.Examples.GravityHold")
    res = model.simulate(t=(0.0, 1.0), dt=1e-2)
    assert np.max(np.abs(np.asarray(res["plant.theta[1]"]))) < 1e-9
    assert abs(np.asarray(res["plant.robot.G[1]"])[-1]) > 0.1


# ---------------------------------------------------------------------------------------------
# three links: ArmExo.ArmExoPlant3 against the C FMU ArmExoPlant3 (same method, same tolerance)

T3 = V.table(3)
OUTPUTS3 = ("theta[1]", "theta[2]", "theta[3]", "tau_h[1]", "tau_h[2]", "tau_h[3]")
EXAMPLES3 = {
    "SumOfSines3": {},
    "SumOfSines3Effects": {
        "actuator_lag.time_constant_s": 0.003,
        **{f"transmission_compliance.k_t[{j}]": k for j, k in ((1, 300.0), (2, 300.0), (3, 100.0))},
        **{f"transmission_compliance.c_t[{j}]": c for j, c in ((1, 0.5), (2, 0.5), (3, 0.1))},
        **{f"interface_compliance.k_s[{j}]": k for j, k in ((1, 400.0), (2, 400.0), (3, 100.0))},
        **{f"interface_compliance.c_s[{j}]": c for j, c in ((1, 2.0), (2, 2.0), (3, 0.3))},
        "gravity.tilt_deg": 10.0, "inertia_mismatch.scale": 0.8,
        "torque_sensor_lag.time_constant_s": 0.002, **friction_parameters(2, 3)},
}


def sines3(t):
    """The input of ArmExo.Examples.SumOfSines3 [N m], shape (len(t), 3)."""
    A, f, A2, f2 = (0.5, 0.3, 0.06), (1.5, 2.5, 3.5), (0.2, 0.15, 0.03), (7.0, 11.0, 5.0)
    return np.column_stack([A[j] * np.sin(2 * np.pi * f[j] * t) + A2[j] * np.sin(2 * np.pi * f2[j] * t)
                            for j in range(3)])


@pytest.fixture(scope="module")
def slave3(tmp_path_factory):
    import fmus
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    path = fmus.build_fmu(tmp_path_factory.mktemp("fmu_n3"), n=3)
    s = FMU2Slave(guid=read_model_description(path).guid, modelIdentifier=T3.model_name,
                  unzipDirectory=extract(path, unzipdir=tmp_path_factory.mktemp("u3")),
                  instanceName="three")
    s.instantiate()
    yield s
    s.freeInstance()


def simulate_fmu3(slave, params, t_end=2.0, H=1e-4, every=10):
    slave.reset()
    slave.setupExperiment(startTime=0.0)
    if params:
        slave.setReal([T3.vr[k] for k in params], list(params.values()))
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    n = int(round(t_end / H))
    u_mid, u_at = sines3((np.arange(n) + 0.5) * H), sines3(np.arange(n + 1) * H)
    c = slave.component
    vin = (ctypes.c_uint * 3)(*[T3.vr[f"tau_m[{j}]"] for j in (1, 2, 3)])
    vout = (ctypes.c_uint * len(OUTPUTS3))(*[T3.vr[o] for o in OUTPUTS3])
    uin, yout = (ctypes.c_double * 3)(), (ctypes.c_double * len(OUTPUTS3))()
    Y = []
    for k in range(n + 1):
        if k % every == 0:
            uin[:] = list(u_at[k])
            slave.fmi2SetReal(c, vin, 3, uin)
            slave.fmi2GetReal(c, vout, len(OUTPUTS3), yout)
            Y.append(list(yout))
        if k == n:
            break
        uin[:] = list(u_mid[k])
        slave.fmi2SetReal(c, vin, 3, uin)
        slave.fmi2DoStep(c, k * H, H, 1)
    return np.array(Y)


@pytest.mark.parametrize("example", list(EXAMPLES3))
def test_modelica_three_link_example_matches_c_fmu(session, slave3, example):
    model = session.load(str(MODELICA / "ArmExo" / "Examples" / f"{example}.mo"), model=f"ArmExo.Examples.{example}")
    res = model.simulate(t=(0.0, 2.0), dt=1e-3, config=rm.SimConfig(rtol=1e-8, atol=1e-10))
    Y = simulate_fmu3(slave3, EXAMPLES3[example])
    for i, name in enumerate(OUTPUTS3):
        ym = np.asarray(res[f"plant.{name}"])
        peak = np.max(np.abs(Y[:, i]))
        assert peak > 1e-4
        err = np.max(np.abs(ym - Y[:, i])) / peak
        assert err < 2e-5, (name, err)


def test_modelica_three_link_parameters_have_the_fmu_names(session):
    """Every parameter of the C FMU ArmExoPlant3 (but rk4_step) exists in ArmExo.ArmExoPlant3."""
    model = session.load(str(MODELICA / "ArmExo" / "ArmExoPlant3.mo"), model="ArmExo.ArmExoPlant3")
    params = {p.name: p for p in model.parameters}
    for name in T3.parameters:
        if name != "rk4_step":
            assert name.split("[")[0] in params, name
            if "[" not in name and params[name].value is not None:
                assert params[name].value == pytest.approx(T3.by_name[name].start), name
