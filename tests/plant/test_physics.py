"""Physics of the plant: FRF against the analytic linearisation, energy, and each effect."""
from __future__ import annotations

import numpy as np
import pytest

from fmus.variables import friction_parameters

from .helpers import run_plain
from .pymodel import Plant

TS = 1e-3


def multisine(n, freqs_hz, amp, seed, Ts=TS):
    """Sum of sines sampled at the start of each interval [N m]."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * Ts
    ph = rng.uniform(0, 2 * np.pi, len(freqs_hz))
    return amp * sum(np.sin(2 * np.pi * f * t + p) for f, p in zip(freqs_hz, ph)) / len(freqs_hz)


def phasor(y, f_hz, Ts=TS):
    """Complex amplitude of y at f over an integer number of periods (y sampled at k Ts)."""
    k = np.arange(len(y))
    return 2.0 / len(y) * np.sum(y * np.exp(-2j * np.pi * f_hz * k * Ts))


def zoh(w, Ts=TS):
    """Fundamental of a zero-order-held sinusoid relative to its samples."""
    return np.exp(-0.5j * w * Ts) * np.sinc(w * Ts / (2 * np.pi))


# ---------------------------------------------------------------------------------------------
# (1) FRF tau_m -> theta, friction off, small motion: ((M_r(q0) + M_h) s^2 + B_h s + K_h)^-1

FRF_FREQS = np.array([0.5, 1.0, 2.0, 3.5, 5.0, 8.0, 12.0, 20.0])


def analytic_frf(plant: Plant, f_hz):
    M = plant.M_r(plant.q0[1]) + plant.Mh
    out = []
    for f in f_hz:
        s = 2j * np.pi * f
        out.append(np.linalg.inv(M * s**2 + plant.Bh * s + plant.Kh))
    return np.array(out)


@pytest.mark.parametrize("params", [{}, {"inertia_mismatch.scale": 1.5}], ids=["nominal", "inertia_mismatch_1.5"])
def test_frf_matches_linearised_transfer_function(slave, params):
    """Multisine on one joint at a time (period 2 s), the last 2 s after 16 s of settling.

    Tolerance: 1e-3 of the largest |G_ik| at each frequency (complex error).  The remaining
    error is the nonlinearity at |theta| ~ 1e-3 rad (~1e-4) and the aliases of the 1 kHz
    zero-order hold (~1e-6 below 20 Hz, corrected to first order by zoh()); the RK4 error
    at h = 1e-5 s is ~1e-12.
    """
    plant = Plant(params)
    G = analytic_frf(plant, FRF_FREQS)
    n_settle, n_per = 16000, 2000
    n = n_settle + n_per
    for k in (0, 1):
        u = np.zeros((n, 2))
        u[:, k] = multisine(n, FRF_FREQS, 0.02, seed=k)
        run = run_plain(slave, params, u)
        for i in (0, 1):
            y = run.y[f"theta[{i + 1}]"][n_settle + 1:]       # theta at (n+1) Ts ...
            uu = u[n_settle:, k]                              # ... after u[n] held over [n Ts, (n+1) Ts)
            for j, f in enumerate(FRF_FREQS):
                w = 2 * np.pi * f
                est = phasor(y, f) / (phasor(uu, f) * zoh(w)) * np.exp(-1j * w * TS)
                scale = np.max(np.abs(G[j]))  # relative to the largest element at f
                assert abs(est - G[j, i, k]) / scale < 1e-3, (f, i, k, est, G[j, i, k])


# ---------------------------------------------------------------------------------------------
# (2) energy conservation without damping or friction

def test_energy_is_conserved_without_damping(slave):
    """Symmetric arm, B_h = 0, friction off: after a torque pulse, kinetic + potential energy
    stays constant to RK4 accuracy (relative 1e-9) while Coriolis terms are large."""
    sym = {"arm.M_h[1,2]": 0.08, "arm.M_h[2,1]": 0.08, "arm.K_h[1,2]": 2.0, "arm.K_h[2,1]": 2.0}
    params = {**sym, **{f"arm.B_h[{i},{j}]": 0.0 for i in (1, 2) for j in (1, 2)}}
    n = 5200
    u = np.zeros((n, 2))
    u[:200] = [3.0, -2.0]
    run = run_plain(slave, params, u)
    plant = Plant(params)
    th = np.column_stack([run.y["theta[1]"], run.y["theta[2]"]])
    w = np.column_stack([run.y["omega[1]"], run.y["omega[2]"]])
    E = np.array([0.5 * w[k] @ (plant.M_r(plant.q0[1] + th[k, 1]) + plant.Mh) @ w[k] + 0.5 * th[k] @ plant.Kh @ th[k]
                  for k in range(len(th))])
    E = E[201:]  # free motion from t = 0.2 s on
    assert np.ptp(th[:, 1]) > 0.3  # large motion: configuration-dependent inertia matters
    assert np.ptp(E) / E.mean() < 1e-9


# ---------------------------------------------------------------------------------------------
# (3) each effect: the FMU equals the exact sampled response of an independent linearisation

EFFECTS = {
    "nominal": {},
    "actuator_lag": {"actuator_lag.time_constant_s": 0.005},
    "transmission_compliance": {"transmission_compliance.k_t[1]": 200.0, "transmission_compliance.k_t[2]": 150.0,
                                "transmission_compliance.c_t[1]": 0.3, "transmission_compliance.c_t[2]": 0.2},
    "interface_compliance": {"interface_compliance.k_s[1]": 300.0, "interface_compliance.k_s[2]": 200.0,
                             "interface_compliance.c_s[1]": 1.0, "interface_compliance.c_s[2]": 0.5},
    "gravity": {"gravity.tilt_deg": 30.0},
    "inertia_mismatch": {"inertia_mismatch.scale": 1.4},
    "torque_sensor_lag": {"torque_sensor_lag.time_constant_s": 0.004},
    # gravity with an actuator lag or a compliant transmission starts far from equilibrium
    # (tau_act = 0, motor aligned): large motion, so it is tested with the other effects
    "gravity_interface_sensor_lag": {"gravity.tilt_deg": -20.0, "interface_compliance.k_s[1]": 400.0,
                                     "interface_compliance.k_s[2]": 400.0, "interface_compliance.c_s[1]": 2.0,
                                     "interface_compliance.c_s[2]": 2.0, "torque_sensor_lag.time_constant_s": 0.002},
    "all_at_once": {"actuator_lag.time_constant_s": 0.003, "transmission_compliance.k_t[1]": 300.0,
                    "transmission_compliance.k_t[2]": 300.0, "transmission_compliance.c_t[1]": 0.5,
                    "transmission_compliance.c_t[2]": 0.5, "interface_compliance.k_s[1]": 400.0,
                    "interface_compliance.k_s[2]": 400.0, "interface_compliance.c_s[1]": 2.0,
                    "interface_compliance.c_s[2]": 2.0, "inertia_mismatch.scale": 0.8, "torque_sensor_lag.time_constant_s": 0.002},
}


@pytest.mark.parametrize("name", list(EFFECTS))
def test_effect_matches_independent_linearisation(slave, name):
    """Small multisine about x = 0 (with gravity: on top of tau_m = G(q0)).

    The reference is the exact ZOH discretisation of the affine linearisation of the
    independent model tests/plant/pymodel.py about x = 0, so transients, the hold, every
    extra state and (with gravity and a compliant transmission) the settling of the
    motor from its aligned start are included.  Tolerance 2e-3 of the peak-to-peak of
    each signal: the nonlinearity at |theta| ~ 1e-4 rad; RK4 contributes ~1e-12.
    """
    params = EFFECTS[name]
    plant = Plant(params)
    u0 = plant.gravity(plant.q0) if params.get("gravity.tilt_deg") else np.zeros(2)
    n = 1500
    du = np.column_stack([multisine(n, [1.0, 4.0, 11.0, 27.0], 0.04, 1), multisine(n, [1.5, 6.0, 17.0, 40.0], 0.025, 2)])
    run = run_plain(slave, params, u0 + du, outputs=("theta[1]", "theta[2]", "tau_h[1]", "tau_h[2]"))
    y_lin = plant.simulate_linear_zoh(u0, du, TS)
    for i, key in enumerate(("theta[1]", "theta[2]", "tau_h[1]", "tau_h[2]")):
        ref = y_lin[:, i]
        err = np.max(np.abs(run.y[key] - ref)) / np.max(np.abs(ref - ref[0]))
        assert err < 2e-3, (key, err)


def test_effects_change_the_response():
    """Sanity of the parametrisation above: each effect alone changes the linear response."""
    n = 300
    du = np.column_stack([multisine(n, [4.0, 27.0], 0.08, 1), multisine(n, [6.0, 40.0], 0.05, 2)])
    base = Plant({}).simulate_linear_zoh(np.zeros(2), du, TS)
    for name, params in EFFECTS.items():
        if name in ("nominal", "gravity"):
            continue
        y = Plant(params).simulate_linear_zoh(np.zeros(2), du, TS)
        assert np.max(np.abs(y - base)) > 1e-3 * np.max(np.abs(base)), name
