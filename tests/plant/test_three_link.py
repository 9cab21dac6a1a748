"""The three-link plant (ArmExoPlant3.fmu): an independent model, the FRF of its analytic
linearisation, energy, and refused parameters (docs/spec/reference-3dof.md)."""
from __future__ import annotations

import ctypes

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

import fmus
from fmus.variables import friction_parameters, table

from .conftest import LogCapture
from .pymodel3 import Plant3
from .test_physics import FRF_FREQS, TS, multisine, phasor, zoh

T3 = table(3)
OUT = ("theta[1]", "theta[2]", "theta[3]", "tau_h[1]", "tau_h[2]", "tau_h[3]",
       "omega[1]", "omega[2]", "omega[3]")


@pytest.fixture(scope="module")
def slave3(tmp_path_factory):
    from fmpy import calloc, free
    from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                           fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

    path = fmus.build_fmu(tmp_path_factory.mktemp("fmu_n3"), n=3)
    md = read_model_description(path)
    log = LogCapture()
    s = FMU2Slave(guid=md.guid, unzipDirectory=extract(path, unzipdir=tmp_path_factory.mktemp("u3")),
                  modelIdentifier=T3.model_name, instanceName="three")
    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(log)
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    s._keep_callbacks = cb
    s.instantiate(loggingOn=False, callbacks=cb)
    s.log = log
    yield s
    s.freeInstance()


def run3(slave, params, u, outputs=OUT):
    """u[n] (N, 3) held over [n Ts, (n+1) Ts); outputs at n Ts (N + 1 rows)."""
    slave.reset()
    slave.setupExperiment(startTime=0.0)
    if params:
        slave.setReal([T3.vr[k] for k in params], [float(v) for v in params.values()])
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    c = slave.component
    vin = (ctypes.c_uint * 3)(*[T3.vr[f"tau_m[{j}]"] for j in (1, 2, 3)])
    uin = (ctypes.c_double * 3)()
    vout = (ctypes.c_uint * len(outputs))(*[T3.vr[o] for o in outputs])
    yout = (ctypes.c_double * len(outputs))()
    Y = np.empty((len(u) + 1, len(outputs)))
    for k in range(len(u)):
        uin[:] = [float(v) for v in u[k]]
        slave.fmi2SetReal(c, vin, 3, uin)
        if k == 0:
            slave.fmi2GetReal(c, vout, len(outputs), yout)
            Y[0] = yout
        slave.fmi2DoStep(c, k * TS, TS, 1)
        slave.fmi2GetReal(c, vout, len(outputs), yout)
        Y[k + 1] = yout
    return Y


def test_table_defaults_are_reference_3dof():
    """The defaults of the three-link table are reference-3dof.md's numbers."""
    p = {v.name: v.start for v in T3.variables if v.causality == "parameter"}
    assert [p[f"posture_deg[{j}]"] for j in (1, 2, 3)] == [62.708, 77.260, 10.0]
    assert p["arm.M_h[3,3]"] == 0.006 and p["arm.K_h[2,3]"] == 0.6 and p["arm.B_h[3,1]"] == 0.020
    assert (p["robot.m3"], p["robot.L3"], p["robot.lc3"], p["robot.I3"]) == (0.6, 0.12, 0.06, 0.0008)
    assert p["robot.Jm[3]"] == 0.004
    assert friction_parameters(3, 3)["friction.Fc[3]"] == pytest.approx(0.25 * 0.40)


def test_mass_matrix_eigenvalues_as_specified():
    """reference-3dof.md: M_r has eigenvalues 0.0053, 0.066, 0.48 at the posture, and the
    smallest over all q2, q3 is 0.0052 (checks the independent model against the spec)."""
    plant = Plant3()
    ev = np.linalg.eigvalsh(plant.M_r(plant.q0))
    assert ev == pytest.approx([0.0053, 0.066, 0.48], rel=0.06)
    grid = np.linspace(0, 2 * np.pi, 73)
    low = min(np.linalg.eigvalsh(plant.M_r(np.array([0.0, a, b])))[0] for a in grid for b in grid)
    assert low == pytest.approx(0.0052, rel=0.05)


CASES = {
    "nominal": {},
    "gravity_inertia_friction": {"gravity.tilt_deg": 25.0, "inertia_mismatch.scale": 1.3,
                                 **friction_parameters(3, 3)},
    "effects_per_joint": {"actuator_lag.time_constant_s": 0.004,
                          "transmission_compliance.k_t[3]": 80.0,
                          "transmission_compliance.c_t[3]": 0.1,
                          **{f"interface_compliance.k_s[{j}]": k for j, k in ((1, 400.0), (2, 300.0), (3, 60.0))},
                          **{f"interface_compliance.c_s[{j}]": c for j, c in ((1, 2.0), (2, 1.0), (3, 0.2))},
                          "torque_sensor_lag.time_constant_s": 0.002,
                          **friction_parameters(1, 3)},
}


@pytest.mark.parametrize("case", list(CASES))
def test_matches_independent_model(slave3, case):
    """Large motion (Coriolis and configuration-dependent inertia matter): the FMU and the
    spec-written model (Radau, rtol 1e-10) agree to 1e-6 of each signal's peak-to-peak.
    A wrong sign or factor in any coupling term shows at 1e-3 or more."""
    n = 250
    t = np.arange(n) * TS
    u = np.column_stack([2.0 * np.sin(2 * np.pi * 3 * t), -1.5 * np.sin(2 * np.pi * 5 * t),
                         0.3 * np.sin(2 * np.pi * 7 * t)])
    params = CASES[case]
    ref = Plant3(params)
    if params.get("gravity.tilt_deg"):
        u = u + ref.gravity(ref.q0)
    y = run3(slave3, params, u, OUT[:6])
    y_ref = ref.simulate(u)
    assert np.ptp(y[:, 2]) > 0.05  # the wrist moves by a large angle
    for i, name in enumerate(OUT[:6]):
        err = np.max(np.abs(y[:, i] - y_ref[:, i])) / np.ptp(y_ref[:, i])
        assert err < 1e-6, (name, err)


def test_frf_matches_linearised_transfer_function(slave3):
    """tau_m -> theta, friction off, small motion: ((M_r(q0) + M_h) s^2 + B_h s + K_h)^-1
    (reference-3dof.md matrices), one joint at a time; 1e-3 of the largest |G_ik| (as the
    two-link test: nonlinearity ~1e-4, ZOH aliases ~1e-6)."""
    plant = Plant3()
    M = plant.M_r(plant.q0) + plant.Mh
    G = np.array([np.linalg.inv(M * (2j * np.pi * f) ** 2 + plant.Bh * 2j * np.pi * f + plant.Kh)
                  for f in FRF_FREQS])
    n_settle, n_per = 16000, 2000
    n = n_settle + n_per
    for k in range(3):
        u = np.zeros((n, 3))
        u[:, k] = multisine(n, FRF_FREQS, 0.02 if k < 2 else 0.004, seed=k)
        y = run3(slave3, {}, u, OUT[:3])
        for i in range(3):
            yy, uu = y[n_settle + 1:, i], u[n_settle:, k]
            for j, f in enumerate(FRF_FREQS):
                w = 2 * np.pi * f
                est = phasor(yy, f) / (phasor(uu, f) * zoh(w)) * np.exp(-1j * w * TS)
                assert abs(est - G[j, i, k]) / np.max(np.abs(G[j])) < 1e-3, (f, i, k)


def test_energy_is_conserved_without_damping(slave3):
    """Symmetric arm, B_h = 0, friction off: after a torque pulse the kinetic energy
    (1/2 w^T (M_r(q) + M_h) w) plus 1/2 theta^T K_h theta stays constant to 1e-9."""
    sym = {}
    plant0 = Plant3()
    for name, mat in (("M_h", plant0.Mh), ("K_h", plant0.Kh)):
        s = 0.5 * (mat + mat.T)
        sym.update({f"arm.{name}[{i + 1},{j + 1}]": s[i, j] for i in range(3) for j in range(3)})
    params = {**sym, **{f"arm.B_h[{i},{j}]": 0.0 for i in (1, 2, 3) for j in (1, 2, 3)}}
    n = 4200
    u = np.zeros((n, 3))
    u[:200] = [3.0, -2.0, 0.4]
    y = run3(slave3, params, u)
    plant = Plant3(params)
    th, w = y[:, :3], y[:, 6:9]
    E = np.array([0.5 * w[k] @ (plant.M_r(plant.q0 + th[k]) + plant.Mh) @ w[k]
                  + 0.5 * th[k] @ plant.Kh @ th[k] for k in range(len(th))])[201:]
    assert np.ptp(th[:, 2]) > 0.3
    assert np.ptp(E) / E.mean() < 1e-9


@pytest.mark.parametrize("name,value,expected", [
    ("robot.m3", 0.0, "robot.m3"),
    ("robot.Jm[3]", -1.0, "robot.Jm[3]"),
    ("friction.Fs[3]", 0.01, "friction.Fs[3]"),           # Fs < Fc of level 3
    ("interface_compliance.k_s[3]", 100.0, "interface_compliance.k_s[3]"),  # not on every joint
    ("arm.M_h[3,3]", -5.0, "mass matrix"),
])
def test_bad_parameters_are_refused_by_name(slave3, name, value, expected):
    params = {**friction_parameters(3, 3), name: value} if name.startswith("friction") else {name: value}
    slave3.reset()
    slave3.setupExperiment(startTime=0.0)
    slave3.setReal([T3.vr[k] for k in params], list(params.values()))
    slave3.log.records.clear()
    slave3.enterInitializationMode()
    with pytest.raises(Exception):
        slave3.exitInitializationMode()
    assert expected in slave3.log.text()
