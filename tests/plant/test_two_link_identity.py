"""The two-link plant stays bit-identical to its trajectories before the n-link plant.

The SHA-256 of every output of four experiments (2 s, 1 ms steps, a fixed multisine) was
recorded with the FMU built from the sources before the n-link generalisation (commit
86e66b8); the current sources must give the same bytes. A change of the last bit of any
output at any step changes the hash.
"""
from __future__ import annotations

import hashlib

import numpy as np
import pytest

from fmus.variables import OUTPUTS, friction_parameters

from .helpers import run_plain

EFFECTS = {"actuator_lag.time_constant_s": 0.003,
           "transmission_compliance.k_t[1]": 300.0, "transmission_compliance.k_t[2]": 300.0,
           "transmission_compliance.c_t[1]": 0.5, "transmission_compliance.c_t[2]": 0.5,
           "interface_compliance.k_s[1]": 400.0, "interface_compliance.k_s[2]": 400.0,
           "interface_compliance.c_s[1]": 2.0, "interface_compliance.c_s[2]": 2.0,
           "gravity.tilt_deg": 10.0, "inertia_mismatch.scale": 0.8,
           "torque_sensor_lag.time_constant_s": 0.002}
CASES = {
    "nominal": {},
    "friction3": friction_parameters(3),
    "gravity_friction1": {"gravity.tilt_deg": 15.0, **friction_parameters(1)},
    "effects_friction2": {**EFFECTS, **friction_parameters(2)},
}
HASHES = {
    "nominal": "4cb708b46898aa69559c5201ab6fe542486add3bc48a05820410e125bc727745",
    "friction3": "baef72734b03c2c0218f742cd934cce5adfeef0f9a65c621b19b33e49ca8815a",
    "gravity_friction1": "b033bef5fa74ba34fbfaf37d6b6042e3d25b483c7fcd8acd1b5c8cbff2d1152e",
    "effects_friction2": "6a963bd4657777348670fcbcc7198aad3f798b953fa2f9cbf714391191bbbdc4",
}


def experiment_input(n=2000):
    t = np.arange(n) * 1e-3
    return np.column_stack([1.5 * np.sin(2 * np.pi * 1.3 * t) + 0.4 * np.sin(2 * np.pi * 9.0 * t),
                            0.8 * np.sin(2 * np.pi * 2.1 * t) + 0.3 * np.sin(2 * np.pi * 13.0 * t)])


def trajectory_hash(slave, params) -> str:
    run = run_plain(slave, params, experiment_input(), outputs=OUTPUTS)
    data = np.column_stack([run.y[o] for o in OUTPUTS]).astype("<f8")
    return hashlib.sha256(data.tobytes()).hexdigest()


@pytest.mark.parametrize("case", list(CASES))
def test_two_link_trajectories_are_bit_identical(slave, case):
    assert trajectory_hash(slave, CASES[case]) == HASHES[case]
