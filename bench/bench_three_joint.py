"""A 50 s three-joint trial against the two-joint trial, measured side by side.

    python bench/bench_three_joint.py [--repeat 5] [--duration 50]

Target (issue 10): a 50 s 3-joint trial within 1.5x the 2-joint trial's time. Each repeat
runs the two-joint and the three-joint trial back to back (alternating which goes first),
so both see the same machine load; the ratio is taken per pair and its median reported,
with wall and process CPU times. Condition: friction 3, resolution 3, perturbation 3, the
reference tuning; joint 1 perturbed (a decomposition trial) and all joints perturbed. Also
the plant alone under each trial's torque history (the C plant's share). Prints a table
and writes bench/results/three_joint.json.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from pathlib import Path

from orchestrator import Setup, simulate_trial
from orchestrator.trial import simulate_plant

from benchio import write_results

RESULTS = Path(__file__).resolve().parent / "results" / "three_joint.json"
TARGET_RATIO = 1.5


def _timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return time.perf_counter() - w, time.process_time() - c, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--duration", type=float, default=50.0)
    args = ap.parse_args(argv)
    setups = {arm: Setup.reference(3, 3, arm=arm) for arm in ("2dof", "3dof")}
    for s in setups.values():  # load and warm the plants
        simulate_trial(s, perturbed_dof=1, level=3, seed=11, duration_s=1.0)
    rows = []
    for dof in (1, None):
        pairs = []
        for rep in range(args.repeat):
            order = ("2dof", "3dof") if rep % 2 == 0 else ("3dof", "2dof")
            res = {}
            for arm in order:
                wall, cpu, trial = _timed(lambda: simulate_trial(
                    setups[arm], perturbed_dof=dof, level=3, seed=11,
                    duration_s=args.duration))
                p_wall, _, _ = _timed(lambda: simulate_plant(setups[arm], trial.tau_m))
                res[arm] = {"wall_s": wall, "cpu_s": cpu, "plant_alone_s": p_wall}
            pairs.append(res)
        med = {arm: {k: statistics.median(p[arm][k] for p in pairs)
                     for k in ("wall_s", "cpu_s", "plant_alone_s")} for arm in setups}
        ratios = [p["3dof"]["wall_s"] / p["2dof"]["wall_s"] for p in pairs]
        cpu_ratios = [p["3dof"]["cpu_s"] / p["2dof"]["cpu_s"] for p in pairs]
        rows.append({"perturbed": "joint 1" if dof else "all joints", "two_joint": med["2dof"],
                     "three_joint": med["3dof"], "ratio_median": statistics.median(ratios),
                     "ratio_cpu_median": statistics.median(cpu_ratios),
                     "ratios": ratios, "meets": statistics.median(ratios) <= TARGET_RATIO})
    print(f"{args.duration:g} s trial, friction 3 / resolution 3 / perturbation 3, "
          f"{args.repeat} paired repeats (medians)")
    print("| perturbed | 2 joints [s] | 3 joints [s] | ratio (wall) | ratio (CPU) | "
          "plant alone 2 / 3 joints [s] | target <= 1.5 |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['perturbed']} | {r['two_joint']['wall_s']:.2f} | "
              f"{r['three_joint']['wall_s']:.2f} | {r['ratio_median']:.2f} | "
              f"{r['ratio_cpu_median']:.2f} | {r['two_joint']['plant_alone_s']:.2f} / "
              f"{r['three_joint']['plant_alone_s']:.2f} | {'met' if r['meets'] else 'missed'} |")
    write_results(RESULTS.stem, {"duration_s": args.duration, "repeat": args.repeat,
                                   "machine": platform.processor() or platform.machine(),
                                   "target_ratio": TARGET_RATIO, "rows": rows}, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
