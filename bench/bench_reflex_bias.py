"""Bias of the reflex-aware estimate (estimation.reflex) with a perturbation filling 0-40 Hz.

Known-answer recordings (estimation.synthetic_reflex: analytic derivatives, the reflex
input rectified from the exact velocity, activation simulated in continuous time; truth K
80 N m/rad, B 1 N m s/rad, I 0.015 kg m^2, G 4 N m s/rad, delay 45 ms) with a flat
multisine angle spectrum to 40 Hz, torque noise 5 % of the torque's std, 40 s, at 500 Hz,
1 kHz and 2 kHz. For each rate: the share of recordings whose 95 % interval holds the
truth, per parameter and for K, B, I jointly, with Wilson 95 % intervals, and the mean
relative error. Issue target: K, B, I inside their intervals in >= 90 %.

Prints a markdown table and writes bench/results/reflex_bias.json. Run from the repository
root: ``python3 bench/bench_reflex_bias.py [--seeds N]`` (default 10 per rate; about
1 min of CPU).
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.stats import binomtest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from estimation.reflex import fit_reflex  # noqa: E402
from estimation.synthetic_reflex import parallel_cascade  # noqa: E402

TRUTH = {"K": 80.0, "B": 1.0, "I": 0.015, "G": 4.0}


def wilson(k, n):
    ci = binomtest(int(k), int(n)).proportion_ci(confidence_level=0.95, method="wilson")
    return [k / n, float(ci.low), float(ci.high)]


def run_rate(fs, seeds):
    inside = {p: 0 for p in (*TRUTH, "KBI")}
    err = {p: [] for p in TRUTH}
    for seed in range(seeds):
        d = parallel_cascade(fs=fs, f_max_hz=40.0, corner_hz=None, noise=0.05,
                             seed=1000 + seed, duration_s=40.0, **TRUTH)
        r = fit_reflex(d["theta"], d["tau"], fs)
        ok = {p: abs(r.values[p] - TRUTH[p]) <= r.ci[p] for p in TRUTH}
        for p in TRUTH:
            inside[p] += ok[p]
            err[p].append((r.values[p] - TRUTH[p]) / TRUTH[p])
        inside["KBI"] += ok["K"] and ok["B"] and ok["I"]
    return {"fs_hz": fs, "n": seeds,
            "inside": {p: wilson(k, seeds) for p, k in inside.items()},
            "mean_rel_error": {p: float(np.mean(v)) for p, v in err.items()}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    args = ap.parse_args(argv)
    rows = [run_rate(fs, args.seeds) for fs in (500.0, 1000.0, 2000.0)]
    print("| fs [Hz] | n | K, B, I all inside | K inside | B inside | I inside | G inside "
          "| mean error K / B / I / G |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        cell = {p: "{:.0%} ({:.0%}-{:.0%})".format(*r["inside"][p]) for p in r["inside"]}
        e = r["mean_rel_error"]
        print(f"| {r['fs_hz']:g} | {r['n']} | {cell['KBI']} | {cell['K']} | {cell['B']} | "
              f"{cell['I']} | {cell['G']} | {e['K']:+.2%} / {e['B']:+.2%} / {e['I']:+.2%} "
              f"/ {e['G']:+.2%} |")
    out = ROOT / "bench" / "results" / "reflex_bias.json"
    out.write_text(json.dumps({"truth": TRUTH, "rates": rows}, indent=1) + "\n")
    print(f"wrote {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
