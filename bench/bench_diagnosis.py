"""Full validation of the sim-to-real gap diagnosis on sets whose effect is withheld.

Makes validation sets with the project's simulator (each catalogue effect at realistic
magnitudes, sets with nothing withheld at every declared resolution level and tuning,
pairs, effects outside the catalogue), each stored in a representation drawn at random
(this project's CSV, 6/7/8/10 significant digits, fixed decimals, float32 CSV or .mat),
diagnoses each blind, scores the verdicts against the truth files (every rate with its
Wilson 95 % interval), and writes ``bench/results/diagnosis.json`` and
``bench/results/diagnosis_score.md``. Resumable: sets already scored under ``--work``
are not run again (run it under nohup; progress on stderr). ``--timing`` times the
diagnosis of an 8-trial set (2 joints x 4 seeds, 50 s trials, all ten effects) with the
default workers and with one process, side by side, and prints the speed-up.

    python bench/bench_diagnosis.py                          # ~70 sets, about an hour on 2 cores
    python bench/bench_diagnosis.py --timing-only --repeat 3 # 8-trial timing, 2 workers vs 1
    python bench/bench_diagnosis.py --position               # position-servo sets (1 and 2
                                                             # joints, limb/apparatus effects)

``--position`` validates the position-servo experiments (diagnosis.position_validation:
every limb/apparatus effect of the catalogue ``--per-effect`` times over its realistic
range, one and two joints in turn, nominal and outside-catalogue sets, random storage
representations), two sets at a time, and writes ``bench/results/diagnosis_position.json``
and ``bench/results/diagnosis_position_score.md``; it also times the diagnosis of one
60 s one-joint recording (a stretch reflex withheld).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's packages
import numpy as np  # noqa: E402

from diagnosis.report import _clean  # noqa: E402
from diagnosis import catalogue as cat  # noqa: E402
from diagnosis.validation import SetSpec, draw_specs, make_set, nominal_gap, run_validation

RESULTS = Path(__file__).resolve().parent / "results"


def timing_run(work: Path, repeat: int = 1, workers: int | None = None) -> dict:
    """Diagnose an 8-trial set (2 joints x 4 seeds x 50 s, gravity withheld, all ten
    effects tried) with ``workers`` processes (default: one per core) and with one,
    alternating, ``repeat`` times each; medians and the paired speed-up."""
    from diagnosis import diagnose
    from diagnosis.parallel import default_workers
    workers = workers or default_workers()
    spec = SetSpec("timing-8trials", (("gravity", {"tilt_deg": 5.0}),),
                   seeds=(101, 102, 103, 104), duration_s=50.0)
    folder = make_set(spec, work / "sets")
    runs = {workers: [], 1: []}
    report = None
    for i in range(repeat):
        for w in (workers, 1):
            t0 = time.perf_counter()
            report = diagnose(folder, work / "reports" / f"{spec.name}-w{w}", progress=False,
                              workers=w)
            runs[w].append(time.perf_counter() - t0)
            print(f"8-trial diagnosis, {w} process(es): {runs[w][-1]:.1f} s "
                  f"(load {os.getloadavg()[0]:.2f})", flush=True)
    ratios = [a / b for a, b in zip(runs[1], runs[workers])]
    return {"n_trials": len(report.trials), "workers": workers,
            "elapsed_s": float(np.median(runs[workers])), "elapsed_s_runs": runs[workers],
            "one_process_s": float(np.median(runs[1])), "one_process_s_runs": runs[1],
            "speed_up_median": float(np.median(ratios)), "speed_up_runs": ratios,
            "verdict": report.verdict, "named": report.named, "fitted": report.fitted,
            "n_simulations": report.n_simulations,
            "load_average_1min_at_end": os.getloadavg()[0]}


INVARIANCE_CASES = (
    ("quantization", (("quantization", {"encoder_resolution_deg": 0.0031,
                                        "torque_resolution_nm": 0.0123}),), 0),
    ("nominal-r2", (), 2), ("nominal-r0", (), 0),
    ("gravity", (("gravity", {"tilt_deg": 4.0}),), 1))


def invariance_run(work: Path) -> dict:
    """The nominal gap of one 2 x 12 s set per case written in every representation
    (representation.REPRESENTATIONS), with its part per feature kind."""
    from diagnosis.representation import REPRESENTATIONS
    out = {}
    for name, effects, resolution in INVARIANCE_CASES:
        rows = {}
        for rep in REPRESENTATIONS:
            spec = SetSpec(f"inv-{name}-{rep}", effects, seeds=(77,), duration_s=12.0,
                           resolution_level=resolution, representation=rep)
            g = nominal_gap(make_set(spec, work / "sets"))
            kinds = {k[0]: v for k, v in g.breakdown("kind").items()}
            rows[rep] = {"gap": g.value, "excess": g.excess, "by_kind": kinds}
            print(f"{name:>14} {rep:>12}: gap {g.value:9.3f}  " + "  ".join(
                f"{k} {v:8.2f}" for k, v in kinds.items()), flush=True)
        out[name] = rows
    return out


#: effects not detected at the low end of their realistic range: also tried stronger
#: (multiples of the low end) to locate their floor
STRONGER_FLOOR_POINTS = {"torque_sensor_lag": (2.0, 3.0, 4.0, 6.0)}

#: parameters whose effect vanishes as they grow (compliances)
STIFFNESSES = ("k_t", "k_s")


def _cached_gap(spec: SetSpec, work: Path) -> dict:
    """Nominal gap (clipped ``nominal_gap`` and unclipped ``excess``) of a set, made if
    needed; cached in work/gaps/NAME.json (resumable). A truth model whose closed loop
    leaves the torque limits gives ``{"error": ...}`` (obviously detectable)."""
    path = work / "gaps" / f"{spec.name}.json"
    if path.is_file():
        return json.loads(path.read_text())
    try:
        result = nominal_gap(make_set(spec, work / "sets"))
        value = ({"error": "nominal model diverges"} if result is None else
                 {"nominal_gap": result.value, "excess": result.excess})
    except Exception as exc:  # noqa: BLE001 - a diverging truth model is a result here
        value = {"error": f"{type(exc).__name__}: {str(exc)[:200]}"}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(value))
    return value


def calibration_run(work: Path, duration_s: float, n_seeds: int,
                    floors_wanted: bool = True) -> dict:
    """Nominal-vs-nominal gaps (the significance threshold) and detectability floors.

    Nominal sets: every declared friction level 0-2 x resolution level 0-2 x tuning
    (reference, robust), ``n_seeds`` perturbation/noise seeds each; nothing withheld.
    Floors: each effect withheld at f = 1, 1/2, 1/4 of the way from "off" to the low end
    of its realistic range (delay: 1 sample only), declared levels 0, reference tuning
    (robust where the effect needs it).
    """
    from tqdm.auto import tqdm
    specs = [SetSpec(f"cal-f{f}-r{r}-{tuning}-{i}", (), seeds=(500 + 37 * i + 7 * f + 3 * r,),
                     duration_s=duration_s, friction_level=f, resolution_level=r,
                     tuning_override=tuning)
             for f in range(3) for r in range(3) for tuning in ("reference", "robust")
             for i in range(n_seeds)]
    nominal = [{"set": s.name, "friction_level": s.friction_level,
                "resolution_level": s.resolution_level, "tuning": s.tuning(),
                **_cached_gap(s, work)}
               for s in tqdm(specs, desc="nominal-vs-nominal", unit="set")]
    floors = []
    todo = []
    for name, effect in (cat.CATALOGUE.items() if floors_wanted else ()):
        fractions = (1.0,) if effect.fit == "integer" else (1.0, 0.5, 0.25)
        if name in STRONGER_FLOOR_POINTS:
            fractions += STRONGER_FLOOR_POINTS[name]
        low_end = {p.name: p.realistic[1] if p.name in STIFFNESSES else p.realistic[0]
                   for p in effect.parameters}
        tuning = "robust" if effect.needs_robust_tuning(low_end) else "reference"
        for frac in fractions:
            # a stiffness is weakest at the top of its range: weaker means stiffer
            params = {p.name: (p.realistic[1] / frac if p.name in STIFFNESSES else
                               p.off + frac * (p.realistic[0] - p.off))
                      for p in effect.parameters}
            if effect.fit == "integer":
                params = {k: int(v) for k, v in params.items()}
            todo.append((name, frac, SetSpec(f"floor-{name}-{round(100 * frac)}pct", ((name, params),),
                                             seeds=(900,), duration_s=duration_s,
                                             tuning_override=tuning)))
    for name, frac, spec in tqdm(todo, desc="detectability", unit="set"):
        floors.append({"effect": name, "fraction_of_low_end": frac,
                       "params": dict(spec.effects[0][1]), "tuning": spec.tuning(),
                       **_cached_gap(spec, work)})
    gaps = np.array([r.get("excess", np.inf) for r in nominal])
    return {"duration_s": duration_s, "nominal": nominal, "floors": floors,
            "nominal_max": float(gaps.max()), "nominal_p95": float(np.quantile(gaps, 0.95)),
            "nominal_median": float(np.median(gaps)), "n_nominal": int(gaps.size)}


def position_run(args) -> int:
    """The position-servo validation and the 60 s one-joint timing (module docstring)."""
    from diagnosis import position_validation as pv
    from diagnosis.validation import rate_text
    work = Path(args.work + "_position" + ("" if args.via == "limbfit" else "_pipeline"))
    specs = pv.draw_position_specs(np.random.default_rng(args.seed),
                                   n_per_effect=args.per_effect, n_nominal=args.nominal,
                                   n_outside=max(args.outside, 4),
                                   duration_s=args.position_duration)
    specs = sorted(specs, key=lambda s: int(s.name.rsplit("-", 1)[1]))  # round robin
    if args.long_delays:
        work = Path(args.work + "_position_long_delays")
        specs = pv.long_delay_specs(args.position_duration)
    t0 = time.perf_counter()
    result = pv.run_position_validation(specs, work, workers=args.position_workers,
                                        via=args.via, score_only=args.score_only)
    if args.long_delays:
        out = {"summary": result["summary"], "rows": result["rows"],
               "settings": dict(vars(args), work=work.name)}
        (RESULTS / "diagnosis_position_long_delays.json").write_text(
            json.dumps(_clean(out), indent=2))
        print(result["table_markdown"])
        return 0
    timing = position_timing(work)
    s = result["summary"]
    table = result["table_markdown"] + (
        f"\nreflex rectified or not, chosen right: {rate_text(s['rectified_correct'])}\n"
        f"truth inside the 95 % jackknife interval (every parameter of the named effect): "
        f"{rate_text(s['truth_in_95pct_interval'])}\n"
        f"60 s one-joint recording diagnosed in {timing['elapsed_s']:.1f} s (one process, "
        f"load {timing['load_average_1min']:.1f}); verdict {timing['verdict']} "
        f"{timing['named']}\n")
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = {"summary": s, "rows": result["rows"], "timing_60s_one_joint": timing,
           "n_sets_drawn": len(specs), "n_sets_done": len(result["rows"]),
           "settings": dict(vars(args), work=work.name), "elapsed_s": time.perf_counter() - t0}
    tag = "" if args.via == "limbfit" else "_pipeline"
    (RESULTS / f"diagnosis_position{tag}.json").write_text(json.dumps(_clean(out), indent=2))
    (RESULTS / f"diagnosis_position{tag}_score.md").write_text(table)
    print(table)
    return 0


def position_timing(work: Path) -> dict:
    """Diagnose one 60 s, 1 kHz one-joint position recording (reflex withheld), timed."""
    from diagnosis import position_validation as pv
    spec = pv.PositionSetSpec("timing-60s", (("stretch_reflex", {
        "gain": 2.5, "delay_s": 0.045, "frequency_hz": 4.0, "rectified": False}),),
        n_dof=1, seed=60, duration_s=60.0)
    folder = pv.make_position_set(spec, work / "sets")
    t0 = time.perf_counter()
    d = pv.diagnose_folder(folder)
    return {"elapsed_s": time.perf_counter() - t0, "verdict": d.verdict, "named": d.named,
            "fitted": d.fitted, "intervals": d.intervals,
            "load_average_1min": os.getloadavg()[0]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--work", default="runs/diagnosis_validation",
                   help="folder for the sets and reports (resumable)")
    p.add_argument("--per-effect", type=int, default=5)
    p.add_argument("--nominal", type=int, default=8,
                   help="nothing-withheld sets (resolution levels 0-3 x both tunings)")
    p.add_argument("--pairs", type=int, default=4)
    p.add_argument("--outside", type=int, default=5, help="outside-catalogue sets")
    p.add_argument("--workers", type=int, default=None,
                   help="local processes per diagnosis (default: one per core)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address")
    p.add_argument("--timing-only", action="store_true",
                   help="only the 8-trial timing (writes bench/results/diagnosis_timing.json)")
    p.add_argument("--repeat", type=int, default=1, help="timing repetitions")
    p.add_argument("--score-only", action="store_true",
                   help="score the sets already diagnosed under --work (a run in progress "
                        "or stopped), without running new ones")
    p.add_argument("--invariance", action="store_true",
                   help="only the nominal gap of 4 sets in every representation "
                        "(writes bench/results/diagnosis_invariance.json)")
    p.add_argument("--duration", type=float, default=12.0, help="trial length [s]")
    p.add_argument("--seed", type=int, default=2024)
    p.add_argument("--timing", action="store_true", help="also time an 8-trial diagnosis")
    p.add_argument("--calibrate", action="store_true",
                   help="only measure nominal-vs-nominal gaps and detectability floors "
                        "(writes bench/results/diagnosis_calibration.json)")
    p.add_argument("--calibration-seeds", type=int, default=2)
    p.add_argument("--no-floors", action="store_true",
                   help="with --calibrate: nominal-vs-nominal gaps only")
    p.add_argument("--position", action="store_true",
                   help="the position-servo validation (writes "
                        "bench/results/diagnosis_position*.json/md)")
    p.add_argument("--long-delays", action="store_true",
                   help="with --position: only the 8 sets of 30-40 ms channel delays "
                        "(writes bench/results/diagnosis_position_long_delays.json)")
    p.add_argument("--position-duration", type=float, default=30.0,
                   help="position trial length [s]")
    p.add_argument("--position-workers", type=int, default=2,
                   help="position sets diagnosed side by side")
    p.add_argument("--via", choices=("limbfit", "pipeline"), default="limbfit",
                   help="position sets diagnosed by limbfit's which/how-far/verdict alone, "
                        "or by the whole diagnosis pipeline (diagnosis.diagnose, with "
                        "reports; slower); results *_position_pipeline.*")
    args = p.parse_args(argv)
    work = Path(args.work)
    if args.position:
        return position_run(args)
    if args.invariance:
        RESULTS.mkdir(parents=True, exist_ok=True)
        inv = invariance_run(work)
        (RESULTS / "diagnosis_invariance.json").write_text(json.dumps(_clean(inv), indent=2))
        return 0
    if args.timing_only:
        tm = timing_run(work, args.repeat, args.workers)
        RESULTS.mkdir(parents=True, exist_ok=True)
        (RESULTS / "diagnosis_timing.json").write_text(json.dumps(_clean(tm), indent=2))
        print(f"| 8-trial set (8 x 50 s, all ten effects) | {tm['workers']} processes | 1 process "
              f"| speed-up |\n|---|---|---|---|\n| median of {args.repeat} | "
              f"{tm['elapsed_s']:.1f} s | {tm['one_process_s']:.1f} s | "
              f"{tm['speed_up_median']:.2f} |")
        return 0
    if args.calibrate:
        cal = calibration_run(work, args.duration, args.calibration_seeds,
                              floors_wanted=not args.no_floors)
        RESULTS.mkdir(parents=True, exist_ok=True)
        (RESULTS / f"diagnosis_calibration_{args.duration:g}s.json").write_text(json.dumps(_clean(cal), indent=2))
        print(json.dumps({k: v for k, v in cal.items() if k not in ("nominal", "floors")}))
        for r in cal["floors"]:
            print(f"{r['effect']:>24} x{r['fraction_of_low_end']:<5g} "
                  f"{r.get('nominal_gap', r.get('error'))}")
        return 0
    specs = draw_specs(np.random.default_rng(args.seed), n_per_effect=args.per_effect,
                       n_nominal=args.nominal, n_pairs=args.pairs, n_outside=args.outside,
                       pairs=(("gravity", "sensor_noise"), ("friction", "torque_sensor_lag"),
                              ("actuator_lag", "gravity"), ("delay", "inertia_mismatch")),
                       duration_s=args.duration)
    # round robin (the i-th set of every group, then the next): a run stopped early still
    # covers every effect, the nominal sets, the outside effects and the pairs
    specs = sorted(specs, key=lambda s: int(s.name.rsplit("-", 1)[1]))
    t0 = time.perf_counter()
    if args.score_only:
        from diagnosis.validation import score_markdown, summarise
        rows = [json.loads(p.read_text()) for s in specs
                for p in [work / "reports" / s.name / "score_row.json"] if p.is_file()]
        summary = summarise(rows)
        result = {"summary": summary, "rows": rows,
                  "table_markdown": score_markdown(summary, rows)}
        print(f"{len(rows)} of {len(specs)} sets diagnosed so far")
    else:
        result = run_validation(specs, work, progress=True, workers=args.workers,
                                scheduler=args.scheduler)
    out = {"summary": result["summary"], "rows": result["rows"],
           "settings": dict(vars(args), work=Path(args.work).name),  # no machine path
           "n_sets_drawn": len(specs),
           "n_sets_done": len(result["rows"]), "elapsed_s": time.perf_counter() - t0}
    if args.timing:
        out["timing_8_trials"] = timing_run(work, args.repeat, args.workers)
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "diagnosis.json").write_text(json.dumps(_clean(out), indent=2))
    table = result["table_markdown"]
    if args.timing:
        tm = out["timing_8_trials"]
        table += (f"\n8-trial set (50 s trials): {tm['elapsed_s']:.0f} s with {tm['workers']} "
                  f"processes, {tm['one_process_s']:.0f} s with one (speed-up "
                  f"{tm['speed_up_median']:.2f}); verdict {tm['verdict']} {tm['named']}\n")
    (RESULTS / "diagnosis_score.md").write_text(table)
    print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
