"""Intervals that include the form, for a named pair (issue 21, item 2): blind labsim
sessions where diagnose names ``stretch_reflex + servo_bandwidth``.

Each session is one drawn ankle (labsim ``nominal+reflex``, as bench/bench_session.py:
labsim's own reflex form, threshold and rectifier, its PD servo with motor inertia and
actuator lag, the theta_ref recorded) recorded ``--trials`` times for 9 s (trial seeds
1000 + i), labelled one condition, and diagnosed by ``armimp diagnose`` (a subprocess of
this checkout). Where the named model is the pair, the truth's K, B, I and the reflex's
gain, delay and activation frequency are scored against (a) the pair's one-step
jackknife at the tied form (the intervals before: ``form_profile.jackknife_intervals``
and ``jackknife_limb_ci``) and (b) the named model's intervals (the envelope over the
members' form alternatives, limbpairs.profile_pair). The servo's bandwidth is shown
beside labsim's PD tuning frequency but not scored: labsim's servo (PD loop with motor
inertia, actuator lag, the limb's load) is not the fit's second-order low-pass, and
its "bandwidth" has no one true value in the fit's form.

    nice -n 10 python3 bench/bench_pair_form_intervals.py [--sessions 5] [--trials 6]

Writes bench/results/pair_form_intervals.json.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
import labsim  # noqa: E402
from benchio import wilson, write_results  # noqa: E402
from bench_session import label_condition  # noqa: E402

PAIR = ("stretch_reflex", "servo_bandwidth")
REFLEX = {"gain": "gain", "delay_s": "delay_s", "frequency_hz": "f_hz"}


def make_session(folder: Path, seed: int, n_trials: int) -> dict:
    """``n_trials`` 9 s trials of one ankle drawn with ``seed``; returns its truth."""
    folder.mkdir(parents=True, exist_ok=True)
    base = labsim.draw("nominal+reflex", np.random.default_rng(seed), duration_s=9.0)
    truth = None
    for i in range(n_trials):
        spec = copy.deepcopy(base)
        spec.seed = 1000 + i
        rec = labsim.simulate(spec)
        labsim.write(rec, folder, f"trial{i:03d}")
        label_condition(folder / f"trial{i:03d}.json", "ankle")
        if truth is None:
            t = rec.truth
            reflex = dict(t["spec"]["reflex"] or {})
            for e in t["effects"]:
                if e["name"] == "reflex":
                    reflex.update(e["params"])
            truth = {"K": t["nominal"]["K"], "B": t["nominal"]["B"], "I": t["nominal"]["I"],
                     **{k: float(np.atleast_1d(reflex[v])[0]) for k, v in REFLEX.items()},
                     "reflex_damping": reflex.get("damping"),
                     "reflex_form": reflex.get("form"),
                     "servo_f_hz": t["spec"]["servo"]["f_hz"],
                     "servo_damping": t["spec"]["servo"]["damping"],
                     "servo_actuator_lag_s": t["spec"]["servo"]["actuator_lag_s"]}
    return truth


def diagnose(folder: Path, out: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    subprocess.run([sys.executable, "-c", "import sys; from orchestrator.cli import main; "
                    "sys.exit(main(sys.argv[1:]))", "diagnose", str(folder),
                    "--out", str(out), "--quiet"], check=True, env=env, cwd=ROOT,
                   stdout=subprocess.DEVNULL)
    return json.loads((out / "report.json").read_text())


def score(nm: dict, truth: dict) -> dict:
    fp = (nm.get("form_profile") or {}).get("stretch_reflex") or {}
    jk, jl = fp.get("jackknife_intervals") or {}, fp.get("jackknife_limb_ci") or {}
    eff = nm["effects"]["stretch_reflex"]
    out = {}
    for k, hk in (("K", "K_h"), ("B", "B_h"), ("I", "M_h")):
        v, lo, hi = nm[k]
        h = np.atleast_2d(jl[hk])[0, 0] if hk in jl else None
        out[k] = (v, None if h is None else [v - h, v + h], [lo, hi])
    for k in REFLEX:
        v, lo, hi = eff[k]
        out[k] = (v, jk.get(k), [lo, hi])
    rows = {}
    for k, (v, before, after) in out.items():
        tv = truth[k]
        rows[k] = {"truth": tv, "value": v}
        for when, ci in (("before", before), ("after", after)):
            rows[k][when] = None if ci is None or ci[0] is None else {
                "interval": ci, "inside": bool(ci[0] <= tv <= ci[1]),
                "width_rel": (ci[1] - ci[0]) / abs(v)}
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sessions", type=int, default=5)
    ap.add_argument("--trials", type=int, default=6)
    ap.add_argument("--first-seed", type=int, default=500)
    ap.add_argument("--name", default="pair_form_intervals")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in range(a.sessions):
            seed = a.first_seed + s
            folder = Path(tmp) / f"s{seed}"
            truth = make_session(folder, seed, a.trials)
            t1 = time.perf_counter()
            rep = diagnose(folder, Path(tmp) / f"out{seed}")
            nm = rep.get("named_model") or {}
            named = tuple(sorted((nm.get("effects") or {}).keys()))
            row = {"seed": seed, "trials": a.trials, "truth": truth, "named": named,
                   "elapsed_s": time.perf_counter() - t1}
            row["pair"] = named == tuple(sorted(PAIR))
            if row["pair"]:
                row["scores"] = score(nm, truth)
                bw = nm["effects"]["servo_bandwidth"]["bandwidth_hz"]
                row["servo_bandwidth_hz"] = bw
                fp = nm.get("form_profile", {}).get("stretch_reflex", {})
                row["alternatives"] = [{k: x.get(k) for k in ("choice", "kept",
                                                              "calibration_excess")}
                                       for x in fp.get("alternatives") or []]
            results.append(row)
            sc = "; ".join(
                f"{k} {r['truth']:.4g}: {r['value']:.4g} before "
                + (f"[{r['before']['interval'][0]:.4g}, {r['before']['interval'][1]:.4g}]"
                   f"{'' if r['before']['inside'] else ' MISS'}" if r["before"] else "-")
                + f" after [{r['after']['interval'][0]:.4g}, {r['after']['interval'][1]:.4g}]"
                  f"{'' if r['after']['inside'] else ' MISS'}"
                for k, r in (row.get("scores") or {}).items())
            extra = (f" | servo {row['servo_bandwidth_hz']} (labsim PD f {truth['servo_f_hz']:.4g}"
                     f" Hz, damping {truth['servo_damping']:.2f}, lag "
                     f"{1e3 * truth['servo_actuator_lag_s']:.2f} ms)") if row["pair"] else ""
            print(f"seed {seed}: named {' + '.join(named) or '-'} "
                  f"({row['elapsed_s']:.0f} s; reflex damping {truth['reflex_damping']}) | "
                  f"{sc}{extra}", flush=True)
    scored = [r for r in results if r["pair"]]
    keys = ["K", "B", "I"] + list(REFLEX)
    table = []
    for k in keys:
        for when in ("before", "after"):
            cs = [r["scores"][k][when] for r in scored if r["scores"][k][when]]
            inside = sum(c["inside"] for c in cs)
            widths = [c["width_rel"] for c in cs]
            table.append({"param": k, "intervals": when, "n": len(cs), "inside": inside,
                          "inside_wilson95": wilson(inside, len(cs)),
                          "width_under_third": sum(w < 1 / 3 for w in widths),
                          "width_rel_median": float(np.median(widths)) if widths else None,
                          "width_rel_max": float(np.max(widths)) if widths else None})
    print(f"\n{len(scored)}/{len(results)} sessions named {' + '.join(PAIR)}; coverage of "
          "the truth (Wilson 95 %) and width relative to the value:")
    print("| parameter | intervals | truth inside (Wilson 95 %) | width < 1/3 | median width "
          "| max width |")
    print("|---|---|---|---|---|---|")
    for t in table:
        w = t["inside_wilson95"]
        print(f"| {t['param']} | {t['intervals']} | {t['inside']}/{t['n']} "
              f"({100 * w[0]:.0f}-{100 * w[1]:.0f} %) | {t['width_under_third']}/{t['n']} | "
              f"{100 * (t['width_rel_median'] or 0):.2f} % | "
              f"{100 * (t['width_rel_max'] or 0):.2f} % |")
    tot = {}
    for when in ("before", "after"):
        k = sum(t["inside"] for t in table if t["intervals"] == when)
        n = sum(t["n"] for t in table if t["intervals"] == when)
        tot[when] = [k, n, wilson(k, n)]
        print(f"all scored parameters, {when}: {k}/{n} ({100 * tot[when][2][0]:.0f}-"
              f"{100 * tot[when][2][1]:.0f} %)")
    print(f"{time.perf_counter() - t0:.0f} s")
    write_results(a.name, {"sessions": a.sessions, "trials": a.trials,
                           "first_seed": a.first_seed, "rows": results, "table": table,
                           "all": tot, "elapsed_s": time.perf_counter() - t0})
    return 0


if __name__ == "__main__":
    sys.exit(main())
