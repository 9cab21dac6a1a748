"""Time the diagnosis of the measured moving-ankle recording (docs/diagnosis.md, section
"Time- and state-varying effects"; issue 20 target: <= 30 s on the 2-core machine).

    nice -n 10 python3 bench/bench_pilot_diagnose.py [--workers N] [--tag NAME]

Runs ``diagnosis.diagnose`` as ``armimp diagnose FILE --out OUT`` does (default workers:
one per core; ``--workers 1``: this process only) on
../shared/data/reklab-pilot/IEEETBME2022_PilotData_AV_PT1_UT2.mat (GPL data, never
copied: only figures are written). Prints a stage table (wall and CPU seconds of every
pipeline stage, and of every effect fitted in the which stage) and writes
bench/results/time_state_pilot[_TAG].json: wall and CPU time (this process, and the
worker processes it reaped), the load average, the stage table, the verdict, the
state-varying effect's rank, held-out reduction and split, the ranking, and the ties
(``indistinguishable``, every ``alternatives`` row on the named fit's split).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

PILOT = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "reklab-pilot"
         / "IEEETBME2022_PilotData_AV_PT1_UT2.mat")


def _children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _timed(rows: list, label: str, fn):
    """``fn`` wrapped to append {label, wall_s, cpu_s} to ``rows`` at every call."""
    def wrapper(*a, **k):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            return fn(*a, **k)
        finally:
            rows.append({"stage": label(*a, **k) if callable(label) else label,
                         "wall_s": time.perf_counter() - t0,
                         "cpu_s": time.process_time() - c0})
    return wrapper


def instrument(stages: list, fits: list) -> None:
    """Time every pipeline stage, every limbfit effect fit and the alternatives'
    re-scoring (this process)."""
    from diagnosis import limbfit, pipeline
    for st in pipeline.STAGES:
        st.run = _timed(stages, st.__name__.rsplit(".", 1)[-1], st.run)
    limbfit.fit_effect = _timed(fits, lambda preps, name, *a, **k: name, limbfit.fit_effect)
    limbfit.add_intervals = _timed(fits, lambda fit, *a, **k: f"jackknife ({fit.effect})",
                                   limbfit.add_intervals)
    from diagnosis import limbties  # the alternatives judged on the named fit's split
    limbties.alternatives = _timed(fits, "limbties (alternatives)", limbties.alternatives)


def record_single_alternatives(kept: dict) -> None:
    """When a pair is named, also judge the alternatives of its first effect as if it
    were named alone (diagnosis.limbties on the best single's split): the comparison the
    summary made before issue 21 item 3 was mended (runner-ups of other splits)."""
    from diagnosis.pipeline import verdict
    inner = verdict.alternatives_of

    def wrapper(r, chosen):
        own = getattr(r, "alternatives", None)
        best = r.singles[0] if r.singles else None
        if callable(own) and chosen is not None and len(chosen.effects) > 1 \
                and best is not None and best.effects == chosen.effects[:1]:
            res = own(best)
            if res is not None:
                kept["best_single"] = list(best.effects)
                kept["rows"] = res["rows"]
                kept["indistinguishable"] = res["indistinguishable"]
        return inner(r, chosen)
    verdict.alternatives_of = wrapper


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--workers", type=int, default=None,
                    help="local processes (default: one per core, as armimp diagnose)")
    ap.add_argument("--tag", default="", help="suffix of the JSON file name")
    ap.add_argument("--out", default=None,
                    help="keep the report folder here (default: a temporary one)")
    args = ap.parse_args(argv)
    if not PILOT.is_file():
        print(f"no pilot recording at {PILOT.name} (../shared/data/reklab-pilot/): skipped")
        return 0
    load = os.getloadavg()[0]
    t0, c0, k0 = time.perf_counter(), time.process_time(), _children_cpu()
    from diagnosis.core import diagnose
    import_wall, import_cpu = time.perf_counter() - t0, time.process_time() - c0
    stages, fits = [{"stage": "import", "wall_s": import_wall, "cpu_s": import_cpu}], []
    instrument(stages, fits)
    single_alt = {}
    record_single_alternatives(single_alt)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.out) if args.out else Path(tmp) / "out"
        rep = diagnose(str(PILOT), folder, progress=False, workers=args.workers)
        report_json = json.loads((folder / "report.json").read_text())
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    child = _children_cpu() - k0
    rows = rep.ranking
    angle = next(((i + 1, r) for i, r in enumerate(rows) if "stiffness_angle" in r["effects"]),
                 (None, None))
    out = {"wall_s": wall, "cpu_s": cpu, "worker_cpu_s": child,
           "workers": args.workers, "load_1min": load, "load_1min_after": os.getloadavg()[0],
           "target_s": 30.0, "stages": stages, "which_fits": fits,
           "verdict": rep.verdict, "named": rep.named, "summary": rep.summary,
           # ties (issue 21 item 3): the models these trials cannot tell apart, and every
           # alternative judged on the named fit's held-out split (diagnosis.limbties)
           "indistinguishable": report_json.get("indistinguishable"),
           "alternatives": [{k: a.get(k) for k in
                             ("name", "held_out_reduction", "named_held_out_reduction",
                              "split", "own_split", "own_held_out_reduction",
                              "named_on_own_split", "rescored",
                              "nameable", "indistinguishable", "closes_more", "separate")}
                            for a in report_json.get("alternatives", [])],
           # a named pair's first effect judged alone: its alternatives on its split
           "alternatives_to_best_single": None if not single_alt else {
               "named_alone": single_alt["best_single"],
               "indistinguishable": single_alt["indistinguishable"],
               "rows": [{k: a.get(k) for k in
                         ("name", "held_out_reduction", "named_held_out_reduction",
                          "own_split", "own_held_out_reduction", "named_on_own_split",
                          "rescored", "nameable",
                          "indistinguishable")} for a in single_alt["rows"]]},
           "stiffness_angle": None if angle[1] is None else {
               "rank": angle[0], "held_out_reduction": angle[1]["held_out_reduction"],
               "params": angle[1]["params"], "split": angle[1].get("split")},
           "ranking": [{"effects": r["effects"], "held_out_reduction": r["held_out_reduction"]}
                       for r in rows],
           "gap": report_json.get("gap"),
           # pairs on the best single (diagnosis.limbpairs) with the second's held-out test
           "pairs": [{"effects": r["effects"], "held_out_reduction": r["held_out_reduction"],
                      "params": r["params"],
                      "second_effect_test": r.get("second_effect_test")}
                     for r in rep.pairs]}
    res = Path(__file__).parent / "results"
    res.mkdir(exist_ok=True)
    name = "time_state_pilot" + (f"_{args.tag}" if args.tag else "") + ".json"
    (res / name).write_text(json.dumps(out, indent=1, default=float))
    print(f"{'stage':28s} {'wall [s]':>9s} {'CPU [s]':>9s}")
    for row in stages + [{"stage": "  which: " + f["stage"], **{k: f[k] for k in
                                                               ("wall_s", "cpu_s")}}
                         for f in fits]:
        print(f"{row['stage']:28s} {row['wall_s']:9.2f} {row['cpu_s']:9.2f}")
    print(f"{'total (this process)':28s} {wall:9.2f} {cpu:9.2f}")
    print(f"{'worker processes':28s} {'':9s} {child:9.2f}")
    print(f"pilot diagnosed in {wall:.1f} s wall, {cpu:.1f} s CPU + {child:.1f} s in workers "
          f"(workers {args.workers or 'one per core'}, load {load:.1f} -> "
          f"{out['load_1min_after']:.1f}; target 30 s); verdict {rep.verdict}; "
          f"indistinguishable {out['indistinguishable']}; "
          f"stiffness_angle rank {angle[0]}, held-out reduction "
          f"{angle[1] and angle[1]['held_out_reduction']}; results/{name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
