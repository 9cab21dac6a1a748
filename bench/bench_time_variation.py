"""The shared time-variation test (estimation.timevarying) on labsim recordings:
detection rate on the time-varying kinds, false alarms on the stationary ones, shape
labels, Wilson 95 % intervals.

Each recording: ``labsim.draw(kind, default_rng([seed, 20, k]))`` (60 s, 1 kHz, one
joint), the test run on its measured theta and tau_h (the truth is only read to score).
On the stationary kinds the table also gives how many had p below alpha (a change found
before the 10 % reporting threshold) and the track's SD over the test's sigma (K, B, I:
near 1 when the noise model is right). A time-varying recording counts as "a change a lab would act on" when its truth's K
ratio differs from 1 by at least 10 % (the test's reporting threshold, MIN_CHANGE); the
others are counted apart (neither a hit nor a miss).

Run from the repository root: ``nice python3 bench/bench_time_variation.py [--seeds 5]``
(about 1-2 s of CPU per recording). Prints a markdown table and writes
bench/results/time_variation.json.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import binomtest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import labsim  # noqa: E402
from benchio import write_results  # noqa: E402
from estimation.timevarying import ALPHA, MIN_CHANGE, time_variation  # noqa: E402

VARYING = ("linear_drift", "saturating_drift", "switching", "modulated")
STATIONARY = ("nominal", "nominal_coloured_noise", "voluntary", "moving_linear")
SHAPE = {"linear_drift": ("linear drift",), "saturating_drift": ("saturating drift",),
         "switching": ("switching", "step", "steps"), "modulated": ("modulated",)}


def wilson(k, n):
    if n == 0:
        return [None, None]
    ci = binomtest(int(k), int(n)).proportion_ci(confidence_level=0.95, method="wilson")
    return [float(ci.low), float(ci.high)]


def one(kind, k_index, seed):
    spec = labsim.draw(kind, np.random.default_rng([seed, 20, k_index]))
    rec = labsim.simulate(spec)
    t0 = time.process_time()
    r = time_variation(rec.trial.theta[:, 0], rec.trial.tau_h[:, 0], rec.trial.fs)
    var = spec.limb.K_var
    ratio = None if var is None else float(var.ratio)
    return {"kind": kind, "seed": seed, "truth_K_ratio": ratio,
            "time_varying": r.time_varying, "parameter": r.parameter,
            "p_value": r.p_value, "shape": r.shape, "n_blocks": len(r.blocks),
            # the noise model's check: on a stationary recording the track's own SD
            # over sigma is near 1 (far above 1: sigma understated, false alarms)
            "sd_over_sigma": {p: float(np.std(r.track[p]) / r.sigma[p]) for p in "KBI"},
            "cpu_s": time.process_time() - t0}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args(argv)
    rows = []
    for k, kind in enumerate(VARYING + STATIONARY):
        for seed in range(args.seeds):
            rows.append(one(kind, k, seed))
            print(f"{kind} {seed}: {rows[-1]['time_varying']} {rows[-1]['shape']}",
                  file=sys.stderr)
    table, summary = [], {}
    for kind in VARYING + STATIONARY:
        rs = [x for x in rows if x["kind"] == kind]
        if kind in VARYING:
            big = [x for x in rs if abs(x["truth_K_ratio"] - 1) >= MIN_CHANGE]
            hit = sum(x["time_varying"] for x in big)
            shape = sum(x["time_varying"] and x["shape"] in SHAPE[kind] for x in big)
            summary[kind] = {"n": len(big), "detected": hit, "rate": hit / max(len(big), 1),
                             "wilson95": wilson(hit, len(big)), "shape_right": shape,
                             "shape_wilson95": wilson(shape, len(big)),
                             "small_truth_changes": len(rs) - len(big),
                             "small_detected": sum(x["time_varying"] for x in rs
                                                   if x not in big)}
            table.append(f"| {kind} | detection | {hit}/{len(big)} "
                         f"[{summary[kind]['wilson95'][0]:.2f}, "
                         f"{summary[kind]['wilson95'][1]:.2f}] | shape right {shape}/{len(big)} |")
        else:
            fa = sum(x["time_varying"] for x in rs)
            below = sum(x["p_value"] < ALPHA for x in rs)
            ratio = {p: [x["sd_over_sigma"][p] for x in rs] for p in "KBI"}
            summary[kind] = {"n": len(rs), "false_alarms": fa, "rate": fa / len(rs),
                             "wilson95": wilson(fa, len(rs)), "p_below_alpha": below,
                             "sd_over_sigma_median": {p: float(np.median(v))
                                                      for p, v in ratio.items()},
                             "sd_over_sigma_max": {p: float(np.max(v))
                                                   for p, v in ratio.items()}}
            table.append(f"| {kind} | false alarm | {fa}/{len(rs)} "
                         f"[{summary[kind]['wilson95'][0]:.2f}, "
                         f"{summary[kind]['wilson95'][1]:.2f}] | p < alpha {below}/{len(rs)};"
                         f" track SD / sigma K, B, I median "
                         f"{', '.join(f'{np.median(v):.2f}' for v in ratio.values())}, max "
                         f"{', '.join(f'{np.max(v):.2f}' for v in ratio.values())} |")
    det = [summary[k] for k in VARYING]
    fal = [summary[k] for k in STATIONARY]
    pooled = {"detection": [sum(d["detected"] for d in det), sum(d["n"] for d in det)],
              "false_alarm": [sum(f["false_alarms"] for f in fal), sum(f["n"] for f in fal)]}
    pooled["detection_wilson95"] = wilson(*pooled["detection"])
    pooled["false_alarm_wilson95"] = wilson(*pooled["false_alarm"])
    print("| kind | measure | count [Wilson 95 %] | |\n|---|---|---|---|")
    print("\n".join(table))
    print(f"| all varying | detection | {pooled['detection'][0]}/{pooled['detection'][1]} "
          f"{np.round(pooled['detection_wilson95'], 2).tolist()} | |")
    print(f"| all stationary | false alarm | {pooled['false_alarm'][0]}/"
          f"{pooled['false_alarm'][1]} {np.round(pooled['false_alarm_wilson95'], 2).tolist()} | |")
    print(f"CPU per test: median {np.median([x['cpu_s'] for x in rows]):.3f} s")
    write_results("time_variation", {"seeds": args.seeds, "duration_s": 60.0,
                                     "summary": summary, "pooled": pooled, "rows": rows})


if __name__ == "__main__":
    main()
