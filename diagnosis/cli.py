"""``diagnose`` and ``validate-diagnosis`` subcommands of ``python -m orchestrator``.

Only argument parsing lives here; the work is done by :func:`diagnosis.diagnose` and
:func:`diagnosis.validation.run_validation`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from . import catalogue as cat


def register(subparsers) -> None:
    """Add this package's subcommands to the orchestrator's argparse subparsers."""
    p = subparsers.add_parser("diagnose", help="diagnose the sim-to-real gap of a folder "
                              "of measured trials (report folder: Markdown, JSON, PNG)")
    p.add_argument("folder", help="folder of trials (NAME.csv + NAME.json, NAME.mat, or a "
                   ".mat of NLID nldat objects), or one such file")
    p.add_argument("--out", required=True, help="report folder")
    p.add_argument("--effects", default=None,
                   help="comma-separated effects to try (default: every catalogue effect "
                        "that applies to the trials' experiment: "
                        f"exoskeleton {','.join(cat.effects_for('exoskeleton'))}; "
                        f"position {','.join(cat.effects_for('position'))})")
    p.add_argument("--fmu", default=None, help="plant FMU (default: the reference plant)")
    p.add_argument("--workers", type=int, default=None,
                   help="local processes for the simulations (default: one per core)")
    p.add_argument("--scheduler", default=None,
                   help="Dask distributed scheduler address (e.g. tcp://127.0.0.1:8786)")
    p.add_argument("--rk4-step", type=float, default=None,
                   help="the plant's internal RK4 step [s]; must divide the sample period "
                        "(default: the plant's, or the nearest step that divides it)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=_diagnose)

    v = subparsers.add_parser("validate-diagnosis", help="make validation sets with withheld "
                              "effects, diagnose them blind and score the diagnosis")
    v.add_argument("--out", required=True, help="folder for the sets, reports and score table")
    v.add_argument("--per-effect", type=int, default=2, help="sets per catalogue effect")
    v.add_argument("--nominal", type=int, default=4, help="sets with nothing withheld")
    v.add_argument("--pairs", type=int, default=2, help="sets with two effects")
    v.add_argument("--outside", type=int, default=1,
                   help="sets with an effect outside the catalogue")
    v.add_argument("--duration", type=float, default=12.0, help="trial length [s]")
    v.add_argument("--seed", type=int, default=2024, help="seed of the draws")
    v.add_argument("--workers", type=int, default=None,
                   help="local processes per diagnosis (default: one per core)")
    v.add_argument("--scheduler", default=None, help="Dask distributed scheduler address")
    v.add_argument("--quiet", action="store_true", help="no progress bars")
    v.set_defaults(func=_validate)


def _effects(text):
    if not text:
        return tuple(cat.CATALOGUE)  # the experiment keeps those that apply to it
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    for n in names:
        cat.get_effect(n)
    return names


def _diagnose(args) -> int:
    from .core import DiagnosisConfig, diagnose
    config = DiagnosisConfig(effects=_effects(args.effects))
    report = diagnose(args.folder, args.out, config=config, plant=args.fmu,
                      progress=not args.quiet, workers=args.workers,
                      scheduler=args.scheduler, rk4_step=args.rk4_step)
    reports = getattr(report, "reports", None) or {None: report}
    for condition, one in reports.items():
        named = " + ".join(one.named)
        head = "" if condition is None else f"[{condition}] "
        print(f"{head}verdict: {one.verdict}{': ' + named if named else ''}")
        print(one.summary)
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
    result = run_validation(specs, args.out, progress=not args.quiet,
                            workers=args.workers, scheduler=args.scheduler)
    print(result["table_markdown"])
    print(f"score table: {Path(args.out) / 'score.md'}")
    return 0
