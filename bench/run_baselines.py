"""All-joints-perturbed trials for the MIMO baselines, one per paper-grid condition.

The orchestrator's grid holds only decomposition trials (one joint perturbed per trial);
the closed-loop and direct MIMO estimators need every joint perturbed at once. This script
(outside the estimation package, which must not import the orchestrator) simulates them
with ``orchestrator.simulate_trial(..., perturbed_dof=None)``, named
``fric{F}_res{R}_pert{P}_dofall``. Re-running skips trials already written.

    python bench/run_baselines.py runs/grid_alljoints [--tuning robust] [--duration 50]
"""

import argparse
from pathlib import Path

from tqdm import tqdm

import trialformat as tf
from orchestrator import Setup, simulate_trial


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--tuning", choices=("reference", "robust"), default="reference")
    parser.add_argument("--duration", type=float, default=50.0)
    parser.add_argument("--friction", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--resolution", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--perturbation", type=int, nargs="+", default=[1, 2, 3])
    args = parser.parse_args(argv)
    tasks = [(f, r, p) for f in args.friction for r in args.resolution for p in args.perturbation]
    for f, r, p in tqdm(tasks, desc="all-joints trials"):
        stem = args.out / f"fric{f}_res{r}_pert{p}_dofall"
        if tf.trial_exists(stem):
            continue
        setup = Setup.reference(friction_level=f, resolution_level=r, tuning=args.tuning)
        trial = simulate_trial(setup, perturbed_dof=None, level=p, seed=1000 + 10 * p,
                               duration_s=args.duration)
        tf.write_trial(stem, trial)


if __name__ == "__main__":
    main()
