"""Timing of the estimation package: reading a condition, estimating it, fitting it.

One condition = two 50 s decomposition trials. Uses the first condition of a grid folder
when given (``python bench/bench_estimation.py runs/grid``), otherwise two trials of the
package's scipy simulation written to a temporary folder. Prints a table and writes
bench/results/estimation.json.
"""

import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import trialformat as tf
from estimation import (estimate_impedance, fit_impedance, fit_second_order, left_limit_delay,
                        read_trials, write_trial_mat)
from estimation.synthetic import synthetic_condition

from benchio import write_results

REPEATS = 5


def best_of(fn, repeats=REPEATS):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return min(times), float(np.median(times)), result


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    with tempfile.TemporaryDirectory() as tmp:
        if argv:
            folder = Path(argv[0])
            paths = sorted(folder.glob("fric0_res0_pert3_dof[12].csv"))[:2]
            source = f"{folder.name}: {[p.stem for p in paths]}"
        else:
            paths = [tf.write_trial(Path(tmp) / f"syn_dof{t.perturbed_dof}", t)
                     for t in synthetic_condition()]
            source = "estimation.synthetic (two 50 s trials)"
        mats = [write_trial_mat(Path(tmp) / f"m{i}.mat", t)
                for i, t in enumerate(read_trials(paths))]
        rows = {}
        rows["read 2 trials (csv+json)"] = best_of(lambda: read_trials(paths), 3)
        rows["read 2 trials (.mat)"] = best_of(lambda: read_trials(mats), 3)
        trials = rows["read 2 trials (csv+json)"][2]
        rows["estimate decomposition"] = best_of(lambda: estimate_impedance(trials))
        rows["estimate full"] = best_of(lambda: estimate_impedance(trials, method="full"))
        est = rows["estimate full"][2]
        rows["fit plain (per element)"] = best_of(lambda: fit_second_order(est.f, est.Z))
        rows["fit corrected (leakage+sampling)"] = best_of(
            lambda: fit_impedance(est, inertia_delay_s=left_limit_delay(est.fs)))
        rows["estimate full + corrected fit"] = best_of(lambda: fit_impedance(
            estimate_impedance(trials, method="full"), inertia_delay_s=0.0005))
    print(f"source: {source}")
    print(f"{'step':36s} {'best [s]':>10s} {'median [s]':>11s}")
    for name, (best, med, _) in rows.items():
        print(f"{name:36s} {best:10.4f} {med:11.4f}")
    result = {"source": source, "python": platform.python_version(),
              "machine": platform.machine(), "repeats": REPEATS,
              "seconds": {k: {"best": v[0], "median": v[1]} for k, v in rows.items()}}
    write_results("estimation", result)


if __name__ == "__main__":
    main()
