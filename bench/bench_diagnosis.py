"""Full validation of the sim-to-real gap diagnosis on sets whose effect is withheld.

Makes validation sets with the project's simulator (each catalogue effect at realistic
magnitudes, sets with nothing withheld, pairs, an effect outside the catalogue), diagnoses
each blind, scores the verdicts against the truth files, and writes
``bench/results/diagnosis.json`` and ``bench/results/diagnosis_score.md``. Resumable:
sets already scored under ``--work`` are not run again. ``--timing`` also times the
diagnosis of an 8-trial set (2 joints x 4 seeds, 50 s trials).

    python bench/bench_diagnosis.py                 # ~15-30 min on 2 cores
    python bench/bench_diagnosis.py --per-effect 2 --nominal 6 --timing
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from diagnosis.report import _clean
from diagnosis.validation import SetSpec, draw_specs, make_set, run_validation

RESULTS = Path(__file__).resolve().parent / "results"


def timing_run(work: Path) -> dict:
    """Diagnose an 8-trial set (2 joints x 4 seeds x 50 s, gravity withheld)."""
    from diagnosis import diagnose
    spec = SetSpec("timing-8trials", (("gravity", {"tilt_deg": 5.0}),),
                   seeds=(101, 102, 103, 104), duration_s=50.0)
    folder = make_set(spec, work / "sets")
    t0 = time.perf_counter()
    report = diagnose(folder, work / "reports" / spec.name, progress=True)
    return {"n_trials": len(report.trials), "elapsed_s": time.perf_counter() - t0,
            "verdict": report.verdict, "named": report.named, "fitted": report.fitted,
            "n_simulations": report.n_simulations}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--work", default="runs/diagnosis_validation",
                   help="folder for the sets and reports (resumable)")
    p.add_argument("--per-effect", type=int, default=1)
    p.add_argument("--nominal", type=int, default=3)
    p.add_argument("--pairs", type=int, default=2)
    p.add_argument("--outside", type=int, default=1)
    p.add_argument("--duration", type=float, default=12.0, help="trial length [s]")
    p.add_argument("--seed", type=int, default=2024)
    p.add_argument("--timing", action="store_true", help="also time an 8-trial diagnosis")
    args = p.parse_args(argv)
    work = Path(args.work)
    specs = draw_specs(np.random.default_rng(args.seed), n_per_effect=args.per_effect,
                       n_nominal=args.nominal, n_pairs=args.pairs, n_outside=args.outside,
                       pairs=(("gravity", "sensor_noise"), ("friction", "torque_sensor_lag")),
                       duration_s=args.duration)
    t0 = time.perf_counter()
    result = run_validation(specs, work, progress=True)
    out = {"summary": result["summary"], "rows": result["rows"],
           "settings": vars(args), "elapsed_s": time.perf_counter() - t0}
    if args.timing:
        out["timing_8_trials"] = timing_run(work)
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "diagnosis.json").write_text(json.dumps(_clean(out), indent=2))
    table = result["table_markdown"]
    if args.timing:
        tm = out["timing_8_trials"]
        table += (f"\n8-trial set (50 s trials): {tm['elapsed_s']:.0f} s, verdict "
                  f"{tm['verdict']} {tm['named']}\n")
    (RESULTS / "diagnosis_score.md").write_text(table)
    print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
