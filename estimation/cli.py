"""Command-line subcommands of the estimation package: ``estimate`` and ``figures``.

``register(subparsers)`` adds them to the project's CLI (orchestrator/cli.py);
``python -m estimation`` runs them on their own.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from trialformat import reference as ref

from .conditions import PAPER, RECOMMENDED, evaluate, group_conditions
from .estimator import METHODS
from .io import read_trials
from .report import make_report


def register(subparsers) -> None:
    """Add ``estimate`` and ``figures`` to an argparse subparsers object."""
    p = subparsers.add_parser("estimate", help="estimate the arm impedance from trials",
                              description="Estimate Z per condition from a folder or files "
                                          "(.csv+.json or .mat) and print the fit.")
    p.add_argument("source", nargs="+", help="folder of trials, or trial files")
    p.add_argument("--method", choices=METHODS, default="decomposition")
    p.add_argument("--raw", action="store_true",
                   help="plain fit: no compensation of the left-limit sampling of tau_h and "
                        "no removal of the Welch window leakage (both on by default; the "
                        "leakage removal needs a perturbation-based method)")
    p.add_argument("--truth", choices=("none", "table1"), default="none",
                   help="compare with Table I (simulated trials); 'none' for lab data: VAF "
                        "against the fitted second-order model")
    p.add_argument("--json", type=Path, help="write the results to this JSON file")
    p.set_defaults(func=run_estimate)

    p = subparsers.add_parser("figures", help="paper figures and tables from a grid run",
                              description="Figs. 2-4 and tables of every condition of a "
                                          "folder of trials.")
    p.add_argument("folders", type=Path, nargs="+",
                   help="folders of trials (e.g. a grid run and its all-joints trials)")
    p.add_argument("--out", type=Path, required=True, help="report folder")
    p.add_argument("--truth", choices=("none", "table1"), default="table1")
    p.add_argument("--fig-variant", default=RECOMMENDED,
                   help="main variant of Figs. 2-4 (estimation.conditions.VARIANTS names; "
                        f"default {RECOMMENDED}, the recommended bias-removing estimator)")
    p.add_argument("--compare", default=PAPER,
                   help=f"variant drawn beside it in Fig. 2, with its own Figs. 3-4 "
                        f"(default {PAPER}, the paper's T/R; 'none' to omit)")
    p.set_defaults(func=run_figures)


def run_estimate(args) -> int:
    source = args.source[0] if len(args.source) == 1 else args.source
    trials = read_trials(source)
    arm = ref.arm_matrices() if args.truth == "table1" else None
    results = []
    for cond, group in group_conditions(trials).items():
        corrected = not args.raw
        rows = evaluate(group, truth=arm, variants=[(
            args.method, args.method, corrected, corrected and args.method != "direct")])
        if not rows:
            print(f"{cond.label} ({cond.tuning}): no trials suited to method "
                  f"{args.method!r}", file=sys.stderr)
            continue
        row = rows[0]
        results.append({"condition": cond.__dict__, **row})
        print(_describe(cond, row, arm is not None))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=1))
    return 0 if results else 1


def _describe(cond, row, has_truth) -> str:
    lines = [f"{cond.label} tuning={cond.tuning} method={row['variant']} "
             f"sampling_compensated={row['compensated']} leakage_removed={row['leakage_removed']}"]
    for e in ("11", "12", "21", "22"):
        text = (f"  Z{e}: M={row[f'M_{e}']:.4f}±{row[f'M_ci_{e}']:.4f} "
                f"B={row[f'B_{e}']:.4f}±{row[f'B_ci_{e}']:.4f} "
                f"K={row[f'K_{e}']:.4f}±{row[f'K_ci_{e}']:.4f}  VAF={row[f'vaf_{e}']:.3f}% "
                f"R2={row[f'r2_{e}']:.5f} coh={row[f'coh_{e}']:.4f}")
        if has_truth:
            text += (f"  err M/B/K={row[f'err_M_{e}']:+.2f}/{row[f'err_B_{e}']:+.2f}/"
                     f"{row[f'err_K_{e}']:+.2f}%")
        lines.append(text)
    return "\n".join(lines)


def run_figures(args) -> int:
    compare = None if args.compare.lower() == "none" else args.compare
    result = make_report(args.folders, args.out, truth=args.truth, variant=args.fig_variant,
                         compare=compare)
    for f in result["files"]:
        print(f)
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m estimation")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, OSError) as exc:
        print(f"python -m estimation {args.command}: error: {exc}", file=sys.stderr)
        return 1
