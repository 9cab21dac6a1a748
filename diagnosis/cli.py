"""``diagnose`` and ``validate-diagnosis`` subcommands of ``python -m orchestrator``.

Only argument parsing lives here; the work is done by :func:`diagnosis.diagnose` and
:func:`diagnosis.validation.run_validation`.
"""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path

from trialformat.cliargs import MAX_SAMPLES, number


def register(subparsers) -> None:
    """Add this package's subcommands to the orchestrator's argparse subparsers."""
    p = subparsers.add_parser("diagnose", help="diagnose the sim-to-real gap of a folder "
                              "of measured trials (report folder: Markdown, JSON, PNG)")
    p.add_argument("folder", help="folder of trials (NAME.csv + NAME.json, NAME.mat, or a "
                   ".mat of NLID nldat objects), or one such file")
    p.add_argument("--out", required=True, help="report folder")
    p.add_argument("--effects", default=None,
                   help="comma-separated effects to try (default: every catalogue effect "
                        "that applies to the trials' experiment, exoskeleton or position: "
                        "docs/diagnosis.md)")
    p.add_argument("--fmu", default=None, help="plant FMU (default: the reference plant)")
    p.add_argument("--workers", type=int, default=None,
                   help="local processes for the simulations (default: one per core)")
    p.add_argument("--scheduler", default=None,
                   help="Dask distributed scheduler address (e.g. tcp://127.0.0.1:8786)")
    p.add_argument("--rk4-step", type=number("--rk4-step", 0, 0.01, 1e-5, unit="s"),
                   default=None,
                   help="the plant's internal RK4 step [s]; must divide the sample period "
                        "(default: the plant's, or the nearest step that divides it)")
    p.add_argument("--scheduling", metavar="NAME", default=None,
                   help="the scheduling variable the limb changes with: an extra column or "
                        "nldat variable (sv), time, angle or angle[j]; as metadata "
                        "'scheduling', which it overrides (trialformat.scheduling)")
    p.add_argument("--plant-parameter", action="append", default=None, metavar="NAME=VALUE",
                   type=_name_value,
                   help="set a plant parameter, or an input outside the contract (listed by "
                        "'armimp info', e.g. motor_enable=1), in every simulation; "
                        "repeatable")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bars (the one line per stage stays)")
    p.set_defaults(func=_diagnose)

    v = subparsers.add_parser("validate-diagnosis", help="make validation sets with withheld "
                              "effects, diagnose them blind and score the diagnosis")
    v.add_argument("--out", required=True, help="folder for the sets, reports and score table")
    v.add_argument("--per-effect", type=int, default=2, help="sets per catalogue effect")
    v.add_argument("--nominal", type=int, default=4, help="sets with nothing withheld")
    v.add_argument("--pairs", type=int, default=2, help="sets with two effects")
    v.add_argument("--outside", type=int, default=1,
                   help="sets with an effect outside the catalogue")
    v.add_argument("--duration", type=number("--duration", 0, MAX_SAMPLES / 1000, 12,
                                             unit="s"), default=12.0, help="trial length [s]")
    v.add_argument("--seed", type=int, default=2024, help="seed of the draws")
    v.add_argument("--workers", type=int, default=None,
                   help="local processes per diagnosis (default: one per core)")
    v.add_argument("--scheduler", default=None, help="Dask distributed scheduler address")
    v.add_argument("--quiet", action="store_true", help="no progress bars")
    v.set_defaults(func=_validate)


def _effects(text):
    from . import catalogue as cat  # numpy: loaded by the handler, not by --help
    if not text:
        return tuple(cat.CATALOGUE)  # the experiment keeps those that apply to it
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise ValueError(f"--effects {text!r}: names no effect; give catalogue names "
                         f"separated by commas (e.g. stretch_reflex,channel_delay) or leave "
                         f"it out for all")
    for n in names:
        cat.get_effect(n)
    return names


def _name_value(text):
    from orchestrator.cli import _name_value as parse
    return parse(text)


@contextlib.contextmanager
def _plant_parameters(pairs):
    """``--plant-parameter`` for the run: in the environment every simulation reads (the
    workers inherit it), restored afterwards."""
    import json
    import os

    from orchestrator.trial import PLANT_PARAMETERS_ENV
    if not pairs:
        yield
        return
    before = os.environ.get(PLANT_PARAMETERS_ENV)
    os.environ[PLANT_PARAMETERS_ENV] = json.dumps(dict(pairs))
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(PLANT_PARAMETERS_ENV, None)
        else:
            os.environ[PLANT_PARAMETERS_ENV] = before


def _diagnose(args) -> int:
    from .core import DiagnosisConfig, diagnose
    config = DiagnosisConfig(effects=_effects(args.effects))
    with _plant_parameters(args.plant_parameter):
        report = diagnose(args.folder, args.out, config=config, plant=args.fmu,
                          progress=not args.quiet, workers=args.workers,
                          scheduler=args.scheduler, rk4_step=args.rk4_step,
                          scheduling=args.scheduling, stage_lines=True)
    if getattr(report, "grouping", None):
        print(report.grouping)
    reports = getattr(report, "reports", None) or {None: report}
    for condition, one in reports.items():
        named = " + ".join(one.named)
        head = "" if condition is None else f"[{condition}] "
        print(f"{head}verdict: {one.verdict}{': ' + named if named else ''}")
        print(one.summary)
        from .report import scheduling_line
        for u in getattr(one, "scheduling", None) or []:
            print(f"{head}{scheduling_line(u)}")
        feat = one.gap.get("features")
        if feat:  # an experiment with its own fit measure (position servo: limbfit)
            print(f"{head}nominal gap {one.gap['nominal_all']:.3g} (threshold "
                  f"{one.gap['significance_threshold']:.3g}, "
                  f"{one.gap['measure'].split(':')[0]}); feature gap "
                  f"{feat['nominal_all']:.3g} (threshold {feat['significance_threshold']:.3g})")
        else:
            print(f"{head}nominal gap {one.gap['nominal_all']:.3g} (threshold "
                  f"{one.gap['significance_threshold']:.3g})")
    print(f"report: {Path(args.out) / 'report.md'}")
    return 0


def _validate(args) -> int:
    import numpy as np

    from .validation import draw_specs, run_validation
    specs = draw_specs(np.random.default_rng(args.seed), n_per_effect=args.per_effect,
                       n_nominal=args.nominal, n_pairs=args.pairs, n_outside=args.outside,
                       duration_s=args.duration)
    _check_options(Path(args.out), {"--per-effect": args.per_effect, "--nominal": args.nominal,
                                     "--pairs": args.pairs, "--outside": args.outside,
                                     "--duration": args.duration, "--seed": args.seed})
    result = run_validation(specs, args.out, progress=not args.quiet,
                            workers=args.workers, scheduler=args.scheduler)
    print(result["table_markdown"])
    print(f"score table: {Path(args.out) / 'score.md'}")
    failed = result["summary"]["failed_sets"]
    if failed:
        print(f"validate-diagnosis: {len(failed)} of {len(specs)} sets failed: "
              f"{', '.join(f['set'] for f in failed)}")
    return 1 if failed else 0


OPTIONS_FILE = "validation.json"


def _check_options(out: Path, options: dict) -> None:
    """Refuse a resumed ``validate-diagnosis`` with other options, naming each option;
    record the options of a new run (``OUT/validation.json``)."""
    import json

    from .validation import _atomic_json
    path = out / OPTIONS_FILE
    if path.is_file():
        previous = json.loads(path.read_text(encoding="utf-8")).get("options", {})
        diff = [f"{k} {previous.get(k)!r} there, {v!r} now" for k, v in options.items()
                if previous.get(k) != v]
        if diff:
            raise ValueError(f"{out} holds a validation run made with other options "
                             f"({'; '.join(diff)}); use another --out, or the options of "
                             f"that run")
        return
    out.mkdir(parents=True, exist_ok=True)
    _atomic_json(path, {"format": "arm-impedance-validation/1", "options": options})
