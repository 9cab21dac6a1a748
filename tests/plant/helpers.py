"""Helpers of the plant tests: the plain stepping loop."""
from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np

from fmus.variables import VR


@dataclass
class Run:
    t: np.ndarray          # [s] sample times 0, Ts, ..., N Ts
    y: dict                # output name -> ndarray, sampled at t (end of each interval)


def run_plain(slave, params: dict, u: np.ndarray, Ts: float = 1e-3,
              outputs=("theta[1]", "theta[2]", "tau_h[1]", "tau_h[2]", "omega[1]", "omega[2]")) -> Run:
    """Plain stepping loop: u[n] (shape (N, 2), [N m]) held from n Ts to (n+1) Ts.

    Outputs are sampled at t = n Ts from the state reached at the end of the previous
    interval, before the next input is set (sample 0: the initial state with u[0]).
    Uses preallocated ctypes arrays and the raw fmi2 functions for speed.
    """
    slave.reset()
    slave.setupExperiment(startTime=0.0)
    if params:
        slave.setReal([VR[k] for k in params], [float(v) for v in params.values()])
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    n = len(u)
    vin = (ctypes.c_uint * 2)(VR["tau_m[1]"], VR["tau_m[2]"])
    uin = (ctypes.c_double * 2)()
    vout = (ctypes.c_uint * len(outputs))(*[VR[o] for o in outputs])
    yout = (ctypes.c_double * len(outputs))()
    Y = np.empty((n + 1, len(outputs)))
    c = slave.component
    set_real, get_real, do_step = slave.fmi2SetReal, slave.fmi2GetReal, slave.fmi2DoStep
    uu = np.asarray(u, dtype=float)
    for k in range(n):
        uin[0], uin[1] = uu[k, 0], uu[k, 1]
        set_real(c, vin, 2, uin)
        if k == 0:
            get_real(c, vout, len(outputs), yout)
            Y[0] = yout
        do_step(c, k * Ts, Ts, 1)
        get_real(c, vout, len(outputs), yout)
        Y[k + 1] = yout
    t = np.arange(n + 1) * Ts
    return Run(t=t, y={o: Y[:, i] for i, o in enumerate(outputs)})
