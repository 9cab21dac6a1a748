"""Write ``fmus/ArmExoPlant/reference_result.csv``: the default experiment of the FMU.

0 to 2 s, communication step 1 ms, default parameters (friction level 0, effects off),
tau_m = [0.5 sin(2 pi 1.5 t), 0.3 sin(2 pi 2.5 t)] N m held over each step (sampled at
the start of the step).  Usage: ``python -m fmus.reference_result``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

OUTPUTS = ("theta[1]", "theta[2]", "tau_h[1]", "tau_h[2]", "omega[1]", "omega[2]")
STOP_TIME = 2.0
STEP = 1e-3


def reference_input(t: np.ndarray) -> np.ndarray:
    """tau_m [N m], shape (len(t), 2)."""
    return np.column_stack([0.5 * np.sin(2 * np.pi * 1.5 * t), 0.3 * np.sin(2 * np.pi * 2.5 * t)])


def simulate(fmu_path) -> np.ndarray:
    """Columns: time, tau_m[1], tau_m[2], then OUTPUTS."""
    from fmpy import simulate_fmu

    n = int(round(STOP_TIME / STEP))
    tk = np.arange(n + 1) * STEP
    u = reference_input(tk)
    # piecewise-constant input: duplicate time points make fmpy hold u[k] on [t_k, t_k+1)
    t_sig = np.repeat(tk, 2)[1:-1]
    u_sig = np.repeat(u[:-1], 2, axis=0)
    sig = np.zeros(len(t_sig), dtype=[("time", float), ("tau_m[1]", float), ("tau_m[2]", float)])
    sig["time"], sig["tau_m[1]"], sig["tau_m[2]"] = t_sig, u_sig[:, 0], u_sig[:, 1]
    res = simulate_fmu(str(fmu_path), stop_time=STOP_TIME, output_interval=STEP, input=sig, output=list(OUTPUTS))
    return np.column_stack([res["time"], u[:, 0], u[:, 1]] + [res[o] for o in OUTPUTS])


def main() -> None:
    from . import default_fmu_path

    data = simulate(default_fmu_path())
    out = Path(__file__).resolve().parent / "ArmExoPlant" / "reference_result.csv"
    header = ",".join(["time", "tau_m[1]", "tau_m[2]", *OUTPUTS])
    np.savetxt(out, data, delimiter=",", header=header, comments="", fmt="%.12g")
    print(out)


if __name__ == "__main__":
    main()
