"""Coverage of a named pair's 95 % intervals (issue 21, items 2 and 6): blind labsim
recordings of a stretch reflex behind a 10 ms torque-channel delay (labsim's own reflex
form: activation damping, threshold and delay drawn; the fit ties damping 0.7 and
threshold 0), diagnosed by diagnosis.limbfit.diagnose_position with the effects
stretch_reflex, channel_delay and wobbling_mass. For each draw whose named pair is
stretch_reflex + channel_delay, the truth's reflex delay and activation frequency, the
channel delay and the limb's K, B, I are scored against the pair's intervals

- ``jackknife``: the one-step delete-one-block jackknife at the tied form
  (FitConfig.form_profile off), and
- ``form``: the envelope over the profiled form choices the data do not reject, plus
  the pipeline's derivative allowance on K, B, I (limbpairs.profile_pair, the default).

Coverage with Wilson 95 % intervals and the median width relative to the value
(target of issue 21: truth inside in >= 80 %, width under a third of the value).

    nice -n 10 python3 bench/bench_pair_intervals.py [--seeds 6] [--duration 15]

Writes bench/results/pair_intervals.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import labsim  # noqa: E402
from benchio import wilson, write_results  # noqa: E402
from diagnosis import limbfit as lf  # noqa: E402

EFFECTS = ("stretch_reflex", "channel_delay", "wobbling_mass")
DELAY_S = 0.010
PARAMS = ("reflex delay", "reflex frequency", "channel delay", "K", "B", "I")


def draw(seed: int, duration_s: float):
    spec = labsim.draw("channel_delay+reflex", np.random.default_rng(seed),
                       duration_s=duration_s)
    spec = dataclasses.replace(spec, record_reference=False, perturbation=dataclasses.replace(
        spec.perturbation, kind="noise"))
    spec.sensors.tau.delay_s = DELAY_S
    return labsim.simulate(spec).trial, spec


def score(pair: dict, spec) -> dict:
    """{param: (truth, low, high, value)} of one named pair."""
    iv, ci = pair["intervals"], pair["limb_ci"]
    r = pair["params"]["stretch_reflex"]
    out = {"reflex delay": (spec.reflex.delay_s, *iv["stretch_reflex"]["delay_s"], r["delay_s"]),
           "reflex frequency": (spec.reflex.f_hz, *iv["stretch_reflex"]["frequency_hz"],
                                r["frequency_hz"]),
           "channel delay": (DELAY_S, *iv["channel_delay"]["delay_s"],
                             pair["params"]["channel_delay"]["delay_s"])}
    for k, key in (("K", "K_h"), ("B", "B_h"), ("I", "M_h")):
        v, h = pair[k][0][0], ci[key][0][0]
        out[k] = (getattr(spec.limb, k), v - h, v + h, v)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--duration", type=float, default=15.0, help="seconds per recording")
    args = ap.parse_args(argv)
    rows, t0 = [], time.perf_counter()
    for seed in range(1, args.seeds + 1):
        trial, spec = draw(seed, args.duration)
        row = {"seed": seed, "damping": spec.reflex.damping,
               "threshold_rad_s": spec.reflex.threshold_rad_s}
        for mode, on in (("jackknife", False), ("form", True)):
            d = lf.diagnose_position([trial], lf.FitConfig(effects=EFFECTS, form_profile=on))
            row[f"named_{mode}"] = d.named
            if d.named == ["stretch_reflex", "channel_delay"]:
                row[mode] = score(d.pairs[0], spec)
        rows.append(row)
        print(f"seed {seed}: named {row['named_form']} ({time.perf_counter() - t0:.0f} s)",
              flush=True)
    summary = {}
    print(f"\n{'parameter':<18} {'mode':<10} {'covered':>8} {'Wilson 95 %':>14} "
          f"{'median width / value':>21}")
    for p in PARAMS:
        for mode in ("jackknife", "form"):
            sc = [r[mode][p] for r in rows if mode in r]
            k = sum(lo <= t <= hi for t, lo, hi, _ in sc)
            w = float(np.median([(hi - lo) / abs(v) for _, lo, hi, v in sc])) if sc else None
            summary[f"{p}|{mode}"] = {"covered": k, "n": len(sc), "wilson": wilson(k, len(sc)),
                                      "median_relative_width": w}
            lo_w, hi_w = wilson(k, len(sc))
            print(f"{p:<18} {mode:<10} {k:>3}/{len(sc):<4} {100 * lo_w:5.0f}-{100 * hi_w:3.0f} % "
                  f"{'' if w is None else f'{w:21.3f}'}")
    for mode in ("jackknife", "form"):
        sc = [r[mode][p] for r in rows if mode in r for p in PARAMS]
        k = sum(lo <= t <= hi for t, lo, hi, _ in sc)
        lo_w, hi_w = wilson(k, len(sc))
        summary[f"all|{mode}"] = {"covered": k, "n": len(sc), "wilson": [lo_w, hi_w]}
        print(f"{'all':<18} {mode:<10} {k:>3}/{len(sc):<4} {100 * lo_w:5.0f}-{100 * hi_w:3.0f} %")
    write_results("pair_intervals", {"seeds": args.seeds, "duration_s": args.duration,
                                     "rows": rows, "summary": summary,
                                     "elapsed_s": time.perf_counter() - t0})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
