"""All-joints-perturbed trials for the MIMO baselines: a thin call of the orchestrator grid.

Equivalent to ``armimp grid OUT --dofs all``: one trial per condition with every joint
perturbed at once by independent perturbations, named ``fric{F}_res{R}_pert{P}_dofall``,
seed ``base + 10 P`` (orchestrator.grid.SEED_RULE, k = 0). Re-running skips trials
already written. ``armimp paper`` runs these together with the decomposition grid.

    python bench/run_baselines.py runs/grid_alljoints [--tuning robust] [--duration 50]
"""

import argparse
from pathlib import Path

from orchestrator import run_grid


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--tuning", choices=("reference", "robust"), default="reference")
    parser.add_argument("--duration", type=float, default=50.0)
    parser.add_argument("--friction", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--resolution", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--perturbation", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    manifest = run_grid(args.out, workers=args.workers, dofs=["all"],
                        friction_levels=args.friction, resolution_levels=args.resolution,
                        perturbation_levels=args.perturbation, duration_s=args.duration,
                        tuning=args.tuning)
    print(f"all-joints trials: {manifest['n_done']} done, {manifest['n_skipped']} skipped, "
          f"{manifest['n_failed']} failed -> {args.out}")
    return 1 if manifest["n_failed"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
