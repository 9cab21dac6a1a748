"""Intervals that include the form (issue 21, item 2; docs/diagnosis.md, "Intervals that
include the form"): blind labsim sets whose forms differ from the fit's tied choices.

labsim (the independent simulator) makes one-joint position-servo recordings of 30 s at
1 kHz (band-limited noise perturbation, no recorded reference, torque sign +1) with

- a stretch reflex (second-order activation of damping 0.6, 0.8 or 1.0 against the fit's
  tied 0.7; labsim's own threshold, rectifier and delay draw), or
- a wobbling mass of damping 0.15 or 0.5 (against the tied 0.3), at 6-10 Hz, inertia at
  least 0.004 kg m^2 (the catalogue's realistic range),

each written in a lab representation, read back blind by trialformat and diagnosed by
diagnosis.limbfit.diagnose_position (effects tried: stretch_reflex, wobbling_mass,
channel_delay, torque_sensor_lag; no pairs: the truth is one effect). For the named
effect, the truth's delay / activation frequency / gain (reflex) or mass / frequency
(wobbling) is scored against (a) the fit's own jackknife interval at the tied choice (the
intervals before) and (b) the form-profiled envelope (diagnosis.formprofile). Coverage
with Wilson 95 % intervals; width relative to the point estimate (target: truth inside
in >= 80 %, width under a third of the value).

    nice -n 10 python3 bench/bench_form_intervals.py [--seeds 3] [--duration 30]

Writes bench/results/form_intervals.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import labsim  # noqa: E402
import trialformat as tf  # noqa: E402
from diagnosis import limbfit as lf  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchio import wilson, write_blind, write_results  # noqa: E402

EFFECTS = ("stretch_reflex", "wobbling_mass", "channel_delay", "torque_sensor_lag")
CONDITIONS = [("stretch_reflex", 0.6), ("stretch_reflex", 0.8), ("stretch_reflex", 1.0),
              ("wobbling_mass", 0.15), ("wobbling_mass", 0.5)]
#: scored parameters: catalogue name -> labsim truth key
SCORED = {"stretch_reflex": {"delay_s": "delay_s", "frequency_hz": "f_hz", "gain": "gain"},
          "wobbling_mass": {"mass": "inertia", "frequency_hz": "f_hz"}}
REPRESENTATIONS = ("csv17", "mat5", "float32", "sig6", "pandas")


def make_spec(effect, damping, seed, duration):
    rng = np.random.default_rng(1000 + seed)
    kind = "nominal+reflex" if effect == "stretch_reflex" else "wobbling_other_damping"
    spec = labsim.draw(kind, rng, duration_s=duration)
    spec = dataclasses.replace(spec, record_reference=False, perturbation=dataclasses.replace(
        spec.perturbation, kind="noise"))
    spec.sensors.torque_sign = 1
    if effect == "stretch_reflex":
        spec.reflex.form = "second_order"
        spec.reflex.damping = float(damping)
    else:
        spec.wobbling.damping = float(damping)
        spec.wobbling.f_hz = float(rng.uniform(6.0, 10.0))
        spec.wobbling.inertia = float(max(spec.wobbling.inertia, 0.004))
    return spec


def truth_of(rec, effect):
    name = "reflex" if effect == "stretch_reflex" else "wobbling_mass"
    spec = rec.truth["spec"]
    src = spec["reflex"] if effect == "stretch_reflex" else spec["wobbling"]
    for e in rec.truth["effects"]:  # the resolved reflex gain
        if e["name"] == name:
            src = {**src, **e["params"]}
    return {k: float(np.atleast_1d(src[v])[0]) for k, v in SCORED[effect].items()}


def one(effect, damping, seed, folder, representation, duration):
    spec = make_spec(effect, damping, seed, duration)
    rec = labsim.simulate(spec)
    truth = truth_of(rec, effect)
    sub = write_blind(rec, folder, f"{effect}_{damping:g}_{seed}", representation)
    t0 = time.perf_counter()
    trials = tf.read_trials(sub)
    d = lf.diagnose_position(trials, lf.FitConfig(effects=EFFECTS, pairs=False))
    dt = time.perf_counter() - t0
    row = {"effect": effect, "damping": damping, "seed": seed,
           "representation": representation, "verdict": d.verdict, "named": d.named,
           "truth": truth, "elapsed_s": dt, "scores": {}}
    top = d.ranking[0] if d.ranking else None
    if not d.named or d.named[0] != effect or top is None or top["effect"] != effect:
        row["correct"] = False
        return row
    row["correct"] = True
    fp = top.get("form_profile") or {}
    own = (fp.get("alternatives") or [{}])[0]
    row["profile"] = {k: fp.get(k) for k in ("best_fitting", "point_estimate_changed",
                                            "n_evaluations")}
    row["alternatives"] = [{k: a.get(k) for k in ("choice", "kept", "calibration_excess",
                                                  "params")}
                           for a in fp.get("alternatives") or []]
    for k, tv in truth.items():
        before = (fp.get("jackknife_intervals") or top["intervals"])[k]
        v_before = (own.get("params") or top["params"])[k]
        after = top["intervals"][k]
        v_after = top["params"][k]
        row["scores"][k] = {
            "truth": tv, "before": {"value": v_before, "interval": before,
                                    "inside": bool(before[0] <= tv <= before[1]),
                                    "width_rel": (before[1] - before[0]) / abs(v_before)},
            "after": {"value": v_after, "interval": after,
                      "inside": bool(after[0] <= tv <= after[1]),
                      "width_rel": (after[1] - after[0]) / abs(v_after)}}
    return row


def summary(rows):
    table = []
    for effect, params in SCORED.items():
        for k in params:
            rs = [r for r in rows if r["effect"] == effect and r.get("correct")]
            for when in ("before", "after"):
                inside = sum(r["scores"][k][when]["inside"] for r in rs)
                widths = [r["scores"][k][when]["width_rel"] for r in rs]
                narrow = sum(w < 1.0 / 3.0 for w in widths)
                table.append({"effect": effect, "param": k, "intervals": when, "n": len(rs),
                              "inside": inside, "inside_wilson95": wilson(inside, len(rs)),
                              "width_under_third": narrow,
                              "width_rel_median": float(np.median(widths)) if widths else None,
                              "width_rel_max": float(np.max(widths)) if widths else None})
    return table


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--name", default="form_intervals")
    a = ap.parse_args(argv)
    rows = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        i = 0
        for effect, damping in CONDITIONS:
            for seed in range(a.seeds):
                r = one(effect, damping, seed, Path(tmp), REPRESENTATIONS[i % 5], a.duration)
                i += 1
                rows.append(r)
                sc = "; ".join(
                    f"{k} {s['truth']:.4g}: before {s['before']['value']:.4g} "
                    f"[{s['before']['interval'][0]:.4g}, {s['before']['interval'][1]:.4g}]"
                    f"{'' if s['before']['inside'] else ' MISS'} after {s['after']['value']:.4g} "
                    f"[{s['after']['interval'][0]:.4g}, {s['after']['interval'][1]:.4g}]"
                    f"{'' if s['after']['inside'] else ' MISS'}"
                    for k, s in r["scores"].items())
                print(f"{effect} damping {damping:g} seed {seed} {r['representation']}: "
                      f"{r['verdict']} {r['named']} ({r['elapsed_s']:.1f} s) "
                      f"{(r.get('profile') or {}).get('best_fitting')} | {sc}", flush=True)
    table = summary(rows)
    n_sets = len(rows)
    named = sum(r["correct"] for r in rows)
    print(f"\n{named}/{n_sets} sets named the truth's effect; coverage of the truth "
          f"(Wilson 95 %) and width relative to the value:")
    print("| effect | parameter | intervals | truth inside (Wilson 95 %) | width < 1/3 | "
          "median width | max width |")
    print("|---|---|---|---|---|---|---|")
    for t in table:
        w = t["inside_wilson95"]
        print(f"| {t['effect']} | {t['param']} | {t['intervals']} | {t['inside']}/{t['n']} "
              f"({100 * w[0]:.0f}-{100 * w[1]:.0f} %) | {t['width_under_third']}/{t['n']} | "
              f"{100 * (t['width_rel_median'] or 0):.1f} % | "
              f"{100 * (t['width_rel_max'] or 0):.1f} % |")
    allk = [(r["scores"][k]["after"]["inside"], r["scores"][k]["before"]["inside"])
            for r in rows if r.get("correct") for k in r["scores"]]
    ka, kb, n = sum(x for x, _ in allk), sum(y for _, y in allk), len(allk)
    print(f"all scored parameters: after {ka}/{n} {wilson(ka, n)}, before {kb}/{n} "
          f"{wilson(kb, n)}; {time.perf_counter() - t0:.0f} s")
    write_results(a.name, {"seeds": a.seeds, "duration_s": a.duration, "effects": EFFECTS,
                           "conditions": CONDITIONS, "rows": rows, "table": table,
                           "named": [named, n_sets],
                           "all_after": [ka, n, wilson(ka, n)],
                           "all_before": [kb, n, wilson(kb, n)],
                           "elapsed_s": time.perf_counter() - t0})
    return 0


if __name__ == "__main__":
    sys.exit(main())
