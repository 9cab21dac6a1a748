"""Validation of the diagnosis on data whose effect is withheld (docs/diagnosis.md).

:func:`make_validation_sets` writes sets of trials made by "truth" models (nominal model
plus withheld effects drawn from the catalogue's realistic ranges) with ``NAME.truth.json``
beside each trial; :func:`run_validation` diagnoses every set blind (the diagnosis reads
only ``NAME.csv``/``NAME.json``) and :func:`score` compares the verdicts with the truth.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import asdict, dataclass, field
from itertools import product
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm


from . import catalogue as cat
from .errors import DiagnosisInputError
from .core import VERDICT_EFFECT, VERDICT_NONE, DiagnosisConfig, diagnose
from .outside import make_model
from .representation import REPRESENTATIONS, trial_written, write_represented

TRUTH_SUFFIX = ".truth.json"


@dataclass(frozen=True)
class SetSpec:
    """One validation set.

    Attributes
    ----------
    name : str
    effects : tuple of (name, primary params)
        Withheld effects (empty: nothing withheld).
    seeds : tuple of int
        One trial per joint per seed.
    level : int
        Perturbation level.
    duration_s : float
    friction_level, resolution_level : int
        Declared (nominal) friction and sensor levels (reference.md).
    extra : dict
        Out-of-catalogue truth (plant parameters, e.g. an arm that differs), recorded in
        the truth file; empty for catalogue sets.
    tuning_override : str
        Declared tuning when not the one the effects need.
    representation : str
        How the trials are stored (representation.REPRESENTATIONS): the project's
        bit-exact CSV, significant digits, fixed decimals or float32.
    levels : tuple of int
        Perturbation levels, one trial per joint, seed and level (default: ``level``).
    """

    name: str
    effects: tuple = ()
    seeds: tuple = (1,)
    level: int = 3
    duration_s: float = 12.0
    friction_level: int = 0
    resolution_level: int = 0
    extra: dict = field(default_factory=dict)
    tuning_override: str = ""
    representation: str = "float64"
    levels: tuple = ()

    def tuning(self) -> str:
        """The declared tuning: ``tuning_override`` if set, else robust when an effect
        needs it (effects.md)."""
        if self.tuning_override:
            return self.tuning_override
        robust = any(cat.get_effect(n).needs_robust_tuning(p) for n, p in self.effects)
        return "robust" if robust else "reference"

    def truth(self) -> dict:
        return {"effects": [{"name": n, "params": p} for n, p in self.effects],
                "representation": self.representation,
                **({"outside_catalogue": self.extra} if self.extra else {})}


#: effects outside the catalogue. Physically different from every catalogue effect: two
#: nonlinearities of the limb (stiffness growing with stretch; viscosity growing with
#: speed), an active torque the perturbation does not cause (physiological tremor) --
#: torques of the limb (outside.py), each at two perturbation levels so that an amplitude
#: dependence can show -- and plant parameters the catalogue does not touch: a heavier
#: motor/transmission inertia Jm (inertia_mismatch scales a1..a3, not Jm) and a heavier
#: second link (changes a2, a3 but not a1 alike). ``draw`` gives the magnitudes. (The
#: stretch reflex and the wobbling mass of the earlier list joined the catalogue, for
#: position experiments: diagnosis.limb, diagnosis.position_validation.)
OUTSIDE = (
    {"name": "cubic_stiffness", "levels": (1, 3),
     "draw": lambda rng: {"human": {"model": "cubic_stiffness",
                                    "params": {"k3": _log_uniform(rng, 1500.0, 4000.0)}}}},
    {"name": "quadratic_damping", "levels": (1, 3),
     "draw": lambda rng: {"human": {"model": "quadratic_damping",
                                    "params": {"b2": _log_uniform(rng, 0.5, 2.0)}}}},
    {"name": "tremor", "levels": (1, 3),
     "draw": lambda rng: {"human": {"model": "tremor",
                                    "params": {"rms_nm": _log_uniform(rng, 0.05, 0.15),
                                               "frequency_hz": float(rng.uniform(8.0, 12.0)),
                                               "seed": int(rng.integers(1, 10_000))}}}},
    {"name": "motor_inertia", "levels": (),
     "draw": lambda rng: {"parameters": {"robot.Jm[1]": 0.016, "robot.Jm[2]": 0.016}}},
    {"name": "link2_mass", "levels": (),
     "draw": lambda rng: {"parameters": {"robot.m2": 1.5}}},
)


def _log_uniform(rng, lo, hi) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_specs(rng: np.random.Generator, *, n_per_effect: int = 1, n_nominal: int = 2,
               n_pairs: int = 2, n_outside: int = 0, pairs: tuple = (),
               representations: tuple | None = None, **common) -> list[SetSpec]:
    """Validation specs: each effect ``n_per_effect`` times at realistic magnitudes,
    ``n_nominal`` sets with nothing withheld (declared resolution levels 0-3 in turn, the
    reference then the robust tuning, friction levels 0-2), ``n_pairs`` sets of two
    effects, ``n_outside`` sets with an effect outside the catalogue (OUTSIDE in turn).
    Every set is stored in a representation drawn from ``representations`` (default:
    all of representation.REPRESENTATIONS)."""
    reps = tuple(representations or REPRESENTATIONS)

    def rep():
        return str(reps[int(rng.integers(len(reps)))])

    specs = []
    for name in cat.effects_for("exoskeleton"):
        effect = cat.get_effect(name)
        for i in range(n_per_effect):
            specs.append(SetSpec(f"{name}-{i}", ((name, effect.draw(rng)),),
                                 seeds=(int(rng.integers(1, 10_000)),),
                                 representation=rep(), **common))
    for i in range(n_nominal):
        levels = {"friction_level": int(i % 3), "resolution_level": int(i % 4),
                  "tuning_override": "reference" if (i // 4) % 2 == 0 else "robust"}
        specs.append(SetSpec(f"nominal-{i}", (), seeds=(int(rng.integers(1, 10_000)),),
                             representation=rep(), **{**levels, **common}))
    for i in range(n_outside):
        out = OUTSIDE[i % len(OUTSIDE)]
        specs.append(SetSpec(f"outside-{out['name']}-{i}", (),
                             seeds=(int(rng.integers(1, 10_000)),),
                             extra={"name": out["name"], **out["draw"](rng)},
                             levels=out["levels"], representation=rep(), **common))
    names = list(cat.effects_for("exoskeleton"))
    for i in range(n_pairs):
        a, b = pairs[i % len(pairs)] if pairs else rng.choice(names, 2, replace=False)
        specs.append(SetSpec(f"pair-{a}+{b}-{i}", ((a, cat.get_effect(a).draw(rng)),
                                                  (b, cat.get_effect(b).draw(rng))),
                             seeds=(int(rng.integers(1, 10_000)),),
                             representation=rep(), **common))
    return specs


def make_set(spec: SetSpec, folder, *, plant=None) -> Path:
    """Simulate the set's trials with its truth model and write them with truth files.

    Skips trials already written (resumable); returns the set's folder.
    """
    from orchestrator import Setup, simulate_trial

    folder = Path(folder) / spec.name
    check_spec(folder / SET_FILE, spec)
    folder.mkdir(parents=True, exist_ok=True)
    if not (folder / SET_FILE).is_file():
        _atomic_json(folder / SET_FILE, spec_record(spec))
    setup = Setup.reference(friction_level=spec.friction_level,
                            resolution_level=spec.resolution_level, tuning=spec.tuning())
    n = setup.n_dof
    effects = {name: cat.expand_effect(name, params, n) for name, params in spec.effects}
    human = spec.extra.get("human")
    levels = spec.levels or (spec.level,)
    for level, seed, k in product(levels, spec.seeds, range(1, n + 1)):
        tag = f"_l{level}" if len(levels) > 1 else ""
        stem = folder / f"{spec.name}{tag}_s{seed}_j{k}"
        if trial_written(stem) and Path(str(stem) + TRUTH_SUFFIX).is_file():
            continue
        model = None if not human else make_model(human["model"], human["params"], n,
                                                  setup.fs)
        trial = simulate_trial(setup, perturbed_dof=k, level=level, seed=seed,
                               duration_s=spec.duration_s, effects=effects or None,
                               parameters=spec.extra.get("parameters") or None,
                               plant=plant, name=stem.name, human=model)
        trial.meta["source"] = "diagnosis validation set (truth withheld)"
        _atomic_json(Path(str(stem) + TRUTH_SUFFIX), spec.truth())
        write_represented(stem, trial, spec.representation)
    return folder


#: A set folder's record of the spec it was made with (checked on resuming).
SET_FILE = "set.json"


def spec_record(spec: SetSpec) -> dict:
    """The spec as JSON-comparable data (every field: effects, seeds, duration, levels,
    representation, extra truth)."""
    return json.loads(json.dumps(asdict(spec), sort_keys=True, default=repr))


def check_spec(path: Path, spec: SetSpec, recorded=None) -> None:
    """Refuse to resume a set made from another spec (another --seed or --duration draws
    other sets under the same names), naming the fields that differ.

    ``recorded``: the spec stored in a score row (else read from ``path`` if present).

    Raises
    ------
    DiagnosisInputError
    """
    if recorded is None:
        if not Path(path).is_file():
            return
        recorded = json.loads(Path(path).read_text(encoding="utf-8"))
    now = spec_record(spec)
    diff = [f"{k}: {recorded.get(k)!r} there, {now.get(k)!r} now" for k in now
            if json.dumps(recorded.get(k), sort_keys=True) != json.dumps(now.get(k),
                                                                         sort_keys=True)]
    if diff:
        raise DiagnosisInputError(
            f"{path}: set {spec.name!r} was made with other options ({'; '.join(diff)}); "
            f"its trials and score would be reused: use another --out, or the options of "
            f"that run")


def _atomic_json(path: Path, obj) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        json.dump(obj, fh, indent=2)
    os.replace(tmp, path)


def nominal_gap(folder, *, config: DiagnosisConfig = DiagnosisConfig(), plant=None):
    """The gap of the nominal model over all trials of ``folder`` (what the verdict
    compares with the significance threshold), without any effect fit.

    Returns
    -------
    GapResult or None
        ``value`` is the (clipped) gap, ``excess`` the unclipped mean(z^2) - expected;
        None when the nominal model diverges.
    """
    from .evaluation import Evaluator, Unit
    from .experiments import experiment_for
    from .inputs import load_trials
    trials = load_trials(folder)
    experiment = experiment_for(trials)
    simulate = experiment.simulator(experiment.estimate(trials), plant=plant)
    units = [Unit(t, 0, t.n_samples, "all") for t in trials]
    return Evaluator(experiment, simulate, units, config).gap({})


def read_truth(folder) -> dict:
    """The truth of a set (for scoring only; the diagnosis never calls this)."""
    files = sorted(Path(folder).glob("*" + TRUTH_SUFFIX))
    return json.loads(files[0].read_text()) if files else {"effects": []}


def score_one(report, truth: dict) -> dict:
    """Compare one diagnosis with its truth."""
    true_names = sorted(e["name"] for e in truth["effects"])
    named = sorted(report.named)
    row = {"truth": true_names, "verdict": report.verdict, "named": named,
           "representation": truth.get("representation", "float64"),
           "amplitude_dependent": bool(report.amplitude.get("amplitude_dependent")),
           "conventions": [c["name"] for c in report.conventions],
           "outside_catalogue": bool(truth.get("outside_catalogue")),
           "nominal_gap": report.gap["nominal_all"],
           "held_out_reduction": report.gap["named_held_out_reduction"],
           "elapsed_s": report.elapsed_s, "n_simulations": report.n_simulations}
    if not true_names:
        # outside the catalogue: anything but a confident catalogue name is honest
        row["correct"] = report.verdict == VERDICT_NONE if not row["outside_catalogue"] \
            else report.verdict != VERDICT_EFFECT
        row["false_alarm"] = report.verdict != VERDICT_NONE
        row["confident_wrong_name"] = report.verdict == VERDICT_EFFECT
        return row
    row["top1"] = bool(report.ranking) and report.verdict == VERDICT_EFFECT and \
        report.named[0] in true_names if len(true_names) == 1 else None
    row["correct"] = named == true_names
    errors = {}
    for e in truth["effects"]:
        if e["name"] in report.fitted:
            errors[e["name"]] = cat.relative_parameter_error(e["name"], report.fitted[e["name"]],
                                                             e["params"])
    row["parameter_error"] = errors
    scored = [cat.relative_parameter_error(e["name"], report.fitted[e["name"]], e["params"],
                                           scored_only=True)
              for e in truth["effects"] if e["name"] in report.fitted]
    row["max_scored_parameter_error"] = max((v for d in scored for v in d.values()),
                                            default=None)
    # held-out reduction of the *true* effect's fit, whatever was named
    for r in report.ranking:
        if r["effects"] == true_names:
            row["true_effect_held_out_reduction"] = r["held_out_reduction"]
            row["true_effect_rank"] = report.ranking.index(r) + 1
            row["true_effect_fit"] = r["params"]
    return row


def run_validation(specs, out_dir, *, config: DiagnosisConfig = DiagnosisConfig(),
                   plant=None, progress: bool = True, workers: int | None = None,
                   scheduler=None) -> dict:
    """Make every set, diagnose it blind, score it; write ``score.json`` and ``score.md``.

    Resumable: a set whose ``reports/NAME/score_row.json`` exists (written atomically
    once the set is scored) is not run again. ``workers``/``scheduler``: as
    :func:`diagnose`.
    """
    out = Path(out_dir)
    for spec in specs:  # all refused up front, before any set is reused or remade
        row_path = out / "reports" / spec.name / "score_row.json"
        if row_path.is_file():
            recorded = json.loads(row_path.read_text()).get("spec")
            if recorded is None:
                raise DiagnosisInputError(f"{row_path}: a score row that records no spec "
                                          f"(an older run); remove it to score the set again")
            check_spec(row_path, spec, recorded)
        check_spec(out / "sets" / spec.name / SET_FILE, spec)
    rows = []
    bar = tqdm(specs, desc="validation sets", disable=None if progress else True, unit="set")
    for spec in bar:
        bar.set_postfix_str(spec.name)
        row_path = out / "reports" / spec.name / "score_row.json"
        if row_path.is_file():
            rows.append(json.loads(row_path.read_text()))
            continue
        try:
            folder = make_set(spec, out / "sets", plant=plant)
            report = diagnose(folder, out / "reports" / spec.name, config=config,
                              plant=plant, progress=False, workers=workers,
                              scheduler=scheduler)
        except Exception as exc:  # a set that cannot be made or diagnosed is reported
            rows.append({"set": spec.name, "error": f"{type(exc).__name__}: {exc}",
                         "truth": sorted(n for n, _ in spec.effects)})
            continue
        row = {"set": spec.name, **score_one(report, read_truth(folder)),
               "truth_params": {n: p for n, p in spec.effects}, "spec": spec_record(spec)}
        _atomic_json(row_path, _jsonable(row))
        rows.append(row)
    summary = summarise(rows)
    result = {"summary": summary, "rows": rows, "table_markdown": score_markdown(summary, rows)}
    _atomic_json(out / "score.json", _jsonable({k: v for k, v in result.items()
                                                if k != "table_markdown"}))
    (out / "score.md").write_text(result["table_markdown"], encoding="utf-8")
    return result


def _jsonable(obj):
    from .report import _clean
    return _clean(obj)


def _mean(values):
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else None


def summarise(rows) -> dict:
    """Headline figures over scored rows (targets of docs/diagnosis.md)."""
    failed = [r for r in rows if "error" in r]
    rows = [r for r in rows if "error" not in r]
    for r in rows:
        r["below_detectability"] = len(r["truth"]) == 1 and cat.below_detectability(
            r["truth"][0], (r.get("truth_params") or {}).get(r["truth"][0], {}))
    below = [r for r in rows if r["below_detectability"]]
    single = [r for r in rows if len(r["truth"]) == 1 and not r["below_detectability"]]
    nominal = [r for r in rows if not r["truth"] and not r.get("outside_catalogue")]
    pairs = [r for r in rows if len(r["truth"]) == 2]
    outside = [r for r in rows if r.get("outside_catalogue")]
    named_ok = [r for r in single if r.get("top1")]
    param_err = [r["max_scored_parameter_error"] for r in named_ok
                 if r.get("max_scored_parameter_error") is not None]
    reductions = [r["held_out_reduction"] for r in named_ok
                  if r.get("held_out_reduction") is not None]
    outside_rows = [r for r in rows if r.get("outside_catalogue")]
    rates = {
        "top1": rate(sum(bool(r.get("top1")) for r in single), len(single)),
        "parameter_within_20pct": rate(sum(e <= 0.2 for e in param_err), len(param_err)),
        "held_out_reduction_at_least_70pct": rate(sum(v >= 0.7 for v in reductions),
                                                  len(reductions)),
        "false_alarm": rate(sum(bool(r["false_alarm"]) for r in nominal), len(nominal)),
        "outside_confident_wrong_name": rate(
            sum(r["verdict"] == VERDICT_EFFECT for r in outside_rows), len(outside_rows)),
        "pair_both_named": rate(sum(bool(r["correct"]) for r in pairs), len(pairs)),
        "spurious_second_name": rate(sum(bool(r.get("top1")) and len(r["named"]) > 1
                                         for r in single), len(single)),
    }
    return {
        "n_sets": len(rows),
        "rates": rates,
        "top1_accuracy": _mean([1.0 if r.get("top1") else 0.0 for r in single]),
        "n_single": len(single),
        "single_with_extra_effect": [r["set"] for r in single
                                     if r.get("top1") and len(r["named"]) > 1],
        "below_detectability": [{"set": r["set"], "params": r.get("truth_params"),
                                 "verdict": r["verdict"], "named": r["named"]} for r in below],
        "parameter_within_20pct": _mean([1.0 if e <= 0.2 else 0.0 for e in param_err]),
        "median_parameter_error": float(np.median(param_err)) if param_err else None,
        "mean_held_out_reduction_named": _mean(reductions),
        "min_held_out_reduction_named": min(reductions) if reductions else None,
        "false_alarm_rate": _mean([1.0 if r["false_alarm"] else 0.0 for r in nominal]),
        "n_nominal": len(nominal),
        "pair_both_named": _mean([1.0 if r["correct"] else 0.0 for r in pairs]),
        "pair_one_named": _mean([1.0 if set(r["named"]) & set(r["truth"]) else 0.0
                                 for r in pairs]),
        "n_pairs": len(pairs),
        "outside_verdicts": [{"set": r["set"], "verdict": r["verdict"], "named": r["named"]}
                             for r in outside],
        "per_effect": _per_effect(single),
        "mean_elapsed_s": _mean([r["elapsed_s"] for r in rows]),
        "failed_sets": [{"set": r["set"], "error": r["error"]} for r in failed],
    }


def rate(k: int, n: int) -> dict:
    """k successes out of n with the Wilson 95 % interval (scipy.stats.binomtest)."""
    if n == 0:
        return {"k": 0, "n": 0, "rate": None, "ci95": [None, None]}
    from scipy.stats import binomtest
    ci = binomtest(int(k), int(n)).proportion_ci(confidence_level=0.95, method="wilson")
    return {"k": int(k), "n": int(n), "rate": k / n, "ci95": [float(ci.low), float(ci.high)]}


def rate_text(r: dict) -> str:
    """``"100 % (20/20; 95 % CI 84-100 %)"``."""
    if not r["n"]:
        return "- (0 sets)"
    lo, hi = r["ci95"]
    return (f"{100 * r['rate']:.0f} % ({r['k']}/{r['n']}; 95 % CI "
            f"{100 * lo:.0f}-{100 * hi:.0f} %)")


def _per_effect(single) -> dict:
    """Top-1, worst scored parameter error and worst held-out reduction per true effect."""
    out = {}
    for r in single:
        e = out.setdefault(r["truth"][0], {"n": 0, "top1": 0, "max_parameter_error": None,
                                           "min_held_out_reduction": None})
        e["n"] += 1
        if not r.get("top1"):
            continue
        e["top1"] += 1
        for key, value, pick in (("max_parameter_error", r.get("max_scored_parameter_error"), max),
                                 ("min_held_out_reduction", r.get("held_out_reduction"), min)):
            if value is not None:
                e[key] = value if e[key] is None else pick(e[key], value)
    return out


def _pct(v):
    return "-" if v is None else f"{100 * v:.0f} %"


def score_markdown(summary: dict, rows) -> str:
    """The score table (Markdown) for the README."""
    s = summary
    med = s["median_parameter_error"]
    med_text = "-" if med is None else f"{100 * med:.1f} %"
    r = s["rates"]
    lines = ["| measure | target | measured (Wilson 95 % interval) |", "|---|---|---|",
             f"| top-1 accuracy, single catalogue effects | >= 95 % | {rate_text(r['top1'])} |",
             f"| fitted parameter within 20 % (correctly named) | all | "
             f"{rate_text(r['parameter_within_20pct'])} |",
             f"| held-out gap reduction >= 70 % (correctly named) | all | "
             f"{rate_text(r['held_out_reduction_at_least_70pct'])} |",
             f"| false alarms, nothing withheld | 0 | {rate_text(r['false_alarm'])} |",
             f"| confident wrong name outside the catalogue | 0 | "
             f"{rate_text(r['outside_confident_wrong_name'])} |",
             f"| pairs: both named | - | {rate_text(r['pair_both_named'])} |",
             f"| single effects named with a spurious second | 0 | "
             f"{rate_text(r['spurious_second_name'])} |",
             "", "| measure | target | measured |", "|---|---|---|",
             f"| top-1 accuracy, single effects ({s['n_single']} sets) | >= 95 % | "
             f"{_pct(s['top1_accuracy'])} |",
             f"| fitted parameter within 20 % (correctly named) | all | "
             f"{_pct(s['parameter_within_20pct'])} (median error "
             f"{med_text}) |",
             f"| held-out gap reduction (correctly named; mean / min) | >= 70 % | "
             f"{_pct(s['mean_held_out_reduction_named'])} / "
             f"{_pct(s['min_held_out_reduction_named'])} |",
             f"| single effects named together with a spurious second | 0 | "
             f"{len(s['single_with_extra_effect'])} sets |",
             f"| single effects below the detectability floor (not counted above) | - | "
             f"{len(s['below_detectability'])} sets |",
             f"| false alarms, nothing withheld ({s['n_nominal']} sets) | 0 % | "
             f"{_pct(s['false_alarm_rate'])} |",
             f"| pairs: both named / at least one ({s['n_pairs']} sets) | - | "
             f"{_pct(s['pair_both_named'])} / {_pct(s['pair_one_named'])} |",
             f"| mean diagnosis time per set | - | {s['mean_elapsed_s']:.0f} s |" if
             s["mean_elapsed_s"] is not None else "| mean diagnosis time | - | - |",
             "", "| effect | sets | top-1 | worst scored parameter error | worst held-out "
             "reduction |", "|---|---|---|---|---|"]
    for name, e in s["per_effect"].items():
        lines.append(f"| {name} | {e['n']} | {e['top1']}/{e['n']} | "
                     f"{_pct(e['max_parameter_error'])} | {_pct(e['min_held_out_reduction'])} |")
    lines += ["", "| set | storage | truth | verdict | named | fitted vs truth (error) | "
              "held-out reduction |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['set']} | - | {' + '.join(r['truth'])} | failed: {r['error']} "
                         f"| - | - | - |")
            continue
        err = r.get("parameter_error") or {}
        errs = "; ".join(f"{k}: " + ", ".join(f"{p} {100 * v:.0f} %" for p, v in d.items())
                         for k, d in err.items()) or "-"
        red = r.get("held_out_reduction")
        below = " (below floor)" if r.get("below_detectability") else ""
        amp = " (amplitude-dependent)" if r.get("amplitude_dependent") else ""
        lines.append(f"| {r['set']}{below} | {r.get('representation', 'float64')} | "
                     f"{' + '.join(r['truth']) or ('outside' if r.get('outside_catalogue') else 'none')}{amp} | "
                     f"{r['verdict']} | {' + '.join(r['named']) or '-'} | {errs} | "
                     f"{'-' if red is None else f'{100 * red:.0f} %'} |")
    return "\n".join(lines) + "\n"
