"""labsim's speed: one 60 s recording at 1 kHz per kind (one joint unless said), and the
accuracy of its linear core measured on the same machine.

For each case: the CPU time (process_time, less sensitive to the shared machine's load
than the wall time, also printed), the servo loop's iterations, and the fine grid's
size. Then the known-answer FRF error of a linear limb on the PD servo (periodic
multisine, 0.5-40 Hz: max |H/Z - 1| over the lines) with and without the actuator lag,
and at oversample 10 and 20. Prints a markdown table and writes bench/results/labsim.json.

Run from the repository root: ``nice python3 bench/bench_labsim.py`` (about 1 min of CPU).
"""

import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

import labsim  # noqa: E402
from benchio import write_results  # noqa: E402

CASES = [("nominal", 1), ("nominal+reflex", 1), ("voluntary", 1),
         ("footplate_friction", 1), ("wobbling_other_damping+reflex", 1),
         ("saturating_drift", 1), ("switching+reflex", 1),
         ("moving_angle_dependent+reflex", 1), ("moving_pilot", 1),
         ("short_range_stiffness", 1), ("backlash", 1), ("nominal", 2),
         ("footplate_friction+reflex", 2)]


def timing():
    rows = []
    labsim.simulate(labsim.draw("nominal", np.random.default_rng(0), duration_s=2.0))  # warm
    for kind, n in CASES:
        spec = labsim.draw(kind, np.random.default_rng(7), n_dof=n, duration_s=60.0)
        w0, c0 = time.perf_counter(), time.process_time()
        rec = labsim.simulate(spec)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        rows.append({"kind": kind, "n_dof": n, "cpu_s": cpu, "wall_s": wall,
                     "iterations": rec.truth["solver"]["iterations"],
                     "fine_points": int(round((60 + spec.preroll_s) * spec.fs
                                              * spec.oversample))})
        print(f"| {kind} | {n} | {cpu:.2f} | {wall:.2f} | "
              f"{rec.truth['solver']['iterations']} |", flush=True)
    return rows


def frf_error(lag, oversample):
    K, B, I = 80.0, 1.2, 0.015
    pert = labsim.Perturbation(kind="multisine", band_hz=[0.5, 40.0], period_s=10.0)
    spec = labsim.RecordingSpec(duration_s=40.0, preroll_s=5.0, perturbation=pert,
                                oversample=oversample, limb=labsim.Limb(K=K, B=B, I=I),
                                servo=labsim.Servo(kind="pd", actuator_lag_s=lag))
    rec = labsim.simulate(spec)
    x = rec.trial.theta[:, 0].reshape(4, -1)
    y = rec.trial.tau_h[:, 0].reshape(4, -1)
    X, Y = np.fft.rfft(x, axis=1).mean(0), np.fft.rfft(y, axis=1).mean(0)
    f = np.fft.rfftfreq(x.shape[1], 1e-3)
    sel = (f >= 0.5) & (f <= 40)
    w = 2 * np.pi * f[sel]
    return float(np.max(np.abs(Y[sel] / X[sel] / (K + 1j * w * B - w * w * I) - 1)))


def main():
    load = os.getloadavg()
    print(f"load average {load[0]:.1f} (2 cores)\n")
    print("| kind | joints | CPU [s] | wall [s] | loop iterations |\n|---|---|---|---|---|")
    rows = timing()
    acc = []
    print("\n| actuator lag [ms] | oversample | max FRF error 0.5-40 Hz |\n|---|---|---|")
    for lag, m in ((0.5e-3, 10), (0.0, 10), (0.0, 20)):
        e = frf_error(lag, m)
        acc.append({"actuator_lag_s": lag, "oversample": m, "max_rel_frf_error": e})
        print(f"| {1e3 * lag:g} | {m} | {e:.2e} |")
    write_results("labsim", {"load_average_start": load[0],
                             "load_average_end": os.getloadavg()[0],
                             "recordings_60s_1kHz": rows, "frf_accuracy": acc})


if __name__ == "__main__":
    main()
