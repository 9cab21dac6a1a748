"""Monte Carlo coverage of the confidence intervals of M, B, K (docs/estimation.md).

For each case, SEEDS independent 50 s trials with a known answer are estimated and fitted
as ``armimp estimate`` does (estimation.lab.analyse, default options); the table gives the
fraction of seeds whose 95 % interval contains the truth (target 90-98 %), the mean
relative error (bias) and the ratio of the mean half-width/1.96 to the spread of the
estimates (1 = intervals as wide as the scatter says). Cases:

- ``position_ref``: 1-DOF ankle-like limb (K 150 N m/rad, B 1.5 N m s/rad, I 0.015 kg m^2)
  on a position servo, reference recorded (estimation.synthetic.position_trial);
- ``position_direct``: the same without the reference (direct angle -> torque);
- ``torque_exact``: the same limb under a torque perturbation (3 N m rms to 15 Hz, the
  subject's own torque 0.5 N m rms), generated exactly in the frequency domain
  (estimation.synthetic.torque_trial);
- ``torque``: the same limb under a torque perturbation (scipy.signal.lsim closed loop,
  encoder noise 2e-5 rad, torque noise 0.1 N m, no own torque).

Usage: ``python bench/bench_coverage.py [SEEDS]`` (default 200; ~3 min on 2 cores).
Prints a table and writes bench/results/coverage.json.
"""

import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from benchio import write_results

ANKLE = {"K": 150.0, "B": 1.5, "I": 0.015}
ANKLE_CTRL = {"M_rd": [0.005], "B_rd": [0.5], "K_rd": [10.0], "theta_rd_deg": [0.0],
              "Mbar": [0.005], "wn": [150.0], "tuning": "ankle"}
CASES = ("position_ref", "position_direct", "torque_exact", "torque")


def one(args):
    case, seed = args
    from estimation.lab import Unit, analyse
    from estimation.synthetic import position_trial, synthetic_trial, torque_trial
    if case == "torque_exact":
        trial = torque_trial(**ANKLE, seed=seed)
    elif case == "torque":
        arm = (np.array([[ANKLE["I"]]]), np.array([[ANKLE["B"]]]), np.array([[ANKLE["K"]]]))
        trial = synthetic_trial(perturbed_dof=1, arm=arm, controller=ANKLE_CTRL, peak=[10.0],
                                seed=seed, theta_noise_std_rad=2e-5, tau_noise_std_nm=0.1)
    else:
        trial = position_trial(**ANKLE, seed=seed, record_reference=case == "position_ref")
    r = analyse(Unit(case, [trial], ""))
    return [(float(getattr(r.fit, p)[0, 0]), float(getattr(r.fit, f"{p}_ci")[0, 0]))
            for p in "MBK"]


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    seeds = int(argv[0]) if argv else 200
    truth = {"M": ANKLE["I"], "B": ANKLE["B"], "K": ANKLE["K"]}
    table = {}
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=2) as ex:
        for case in CASES:
            res = np.array(list(ex.map(one, [(case, s) for s in range(seeds)], chunksize=8)))
            row = {}
            for j, p in enumerate("MBK"):
                est, half = res[:, j, 0], res[:, j, 1]
                row[p] = {"coverage": float(np.mean(np.abs(est - truth[p]) <= half)),
                          "bias_pct": float(100 * (est.mean() / truth[p] - 1)),
                          "sd_pct": float(100 * est.std() / truth[p]),
                          "width_over_scatter": float(half.mean() / 1.96 / est.std())}
            table[case] = row
    wall = time.perf_counter() - start
    print(f"coverage of 95 % intervals over {seeds} seeds (target 90-98 %), {wall:.0f} s")
    print(f"{'case':16s} {'param':5s} {'coverage':>9s} {'bias %':>8s} {'sd %':>7s} "
          f"{'width/scatter':>14s}")
    for case, row in table.items():
        for p, v in row.items():
            print(f"{case:16s} {p:5s} {100 * v['coverage']:8.1f}% {v['bias_pct']:+8.3f} "
                  f"{v['sd_pct']:7.3f} {v['width_over_scatter']:14.2f}")
    write_results("coverage", {"seeds": seeds, "truth": truth, "wall_s": wall,
                               "cases": table})
    return 0


if __name__ == "__main__":
    sys.exit(main())
