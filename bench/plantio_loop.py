"""The master's per-sample access loop on a plant, shared by the plant benches.

``bench/bench_plant.py`` (the C FMU, FMI 2.0 against 3.0) and
``bench/bench_modelica_export.py`` (the exported FMU against the C FMU) time the same loop:
``orchestrator.plant.PlantIO``'s pre-bound ``write`` (tau_m), ``step`` (one communication
step of ``ts`` s) and ``read`` (theta, tau_h) per sample, as the master makes them.
"""
from __future__ import annotations

import time

import numpy as np


def plantio_loop(plant, params: dict, u: np.ndarray, ts: float) -> tuple[float, float, np.ndarray]:
    """Start ``plant`` (an ``orchestrator.plant.Plant``) with ``params`` and drive it with the
    torque ``u`` over ``len(u)`` communication steps of ``ts`` s.

    Parameters
    ----------
    plant : orchestrator.plant.Plant
    params : dict
        FMU parameter name -> value, set before initialisation.
    u : ndarray, shape (n_steps, n_joints)
        Motor torque [N m] of each step (one column per input of the plant).
    ts : float
        Communication step [s].

    Returns
    -------
    (wall time [s], CPU time of the process [s], the last outputs read: theta then tau_h)

    Raises
    ------
    ValueError
        ``u`` has not one column per input of the plant.
    RuntimeError
        An FMI call returned a status other than OK (the FMU's file named).
    """
    plant.start(params)
    io = plant.io
    read, write, step, val_in, val_out = io.read, io.write, io.step, io.val_in, io.val_out
    if u.ndim != 2 or u.shape[1] != len(val_in):
        raise ValueError(f"the torque has shape {u.shape}, expected (n_steps, {len(val_in)}) "
                         f"for {plant.path.name}")
    ul = u.tolist()
    status = 0
    c0, t0 = time.process_time(), time.perf_counter()
    for k in range(len(ul)):
        val_in[:] = ul[k]
        status |= write()
        status |= step(k * ts, ts, 1)
        status |= read()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if status:
        raise RuntimeError(f"an FMI call failed in the PlantIO loop of {plant.path.name}")
    return wall, cpu, np.array(val_out[:])
