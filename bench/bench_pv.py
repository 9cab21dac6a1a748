"""The parameter-varying estimate (estimation.varying): speed on the measured moving-ankle
recording, accuracy of K(rho) against labsim's truth.

1. Speed: ``fit_varying`` on ../shared/data/reklab-pilot (106 s at 1 kHz, scheduled on
   ``sv``), intrinsic only and with the reflex pathway (wall and CPU seconds), and the
   whole ``estimate --reflex`` command (the time-invariant estimate, the parallel-cascade
   fit and the parameter-varying one) as a user runs it. Target: <= 10 s.
2. Accuracy: labsim ``moving_angle_dependent`` and ``moving_pilot`` recordings (K
   exponential or U-shaped in the angle; 60 s), ``--count`` of each (default 3): the
   fraction of the 15 reported points whose 95 % interval holds the true K(rho)
   (labsim's ``K_of_rho``, a function of the joint's actual slow angle, interpolated),
   scheduled on ``sv`` (the commanded slow angle, which the loaded servo's joint follows
   only to about 0.01-0.02 rad) and, on the kind that keeps the movement, on ``angle``
   (the slow part of the measured angle); the largest and the RMS error relative to the
   true K's mean, and the held-out VAF of the varying and the time-invariant models.

Run from the repository root: ``nice python3 bench/bench_pv.py [--count N]``; writes
bench/results/pv.json and prints a table.
"""

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import numpy as np  # noqa: E402

import labsim  # noqa: E402
from benchio import write_results  # noqa: E402
from estimation.reflex import ReflexOptions  # noqa: E402
from estimation.varying import fit_varying  # noqa: E402
from trialformat.scheduling import slow_part  # noqa: E402

PILOT = ROOT.parent / "shared" / "data" / "reklab-pilot" / \
    "IEEETBME2022_PilotData_AV_PT1_UT2.mat"


def speed():
    if not PILOT.is_file():
        return {"skipped": f"{PILOT.name} not found next to the repository (../shared)"}
    import warnings
    import trialformat as tf
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t = tf.read_trials(PILOT, min_samples=2)[0]
    out = {"recording_s": t.n_samples / t.fs, "fs_hz": t.fs}
    # the file's torque is reversed (estimate's finding): torque_sign -1
    for label, rf in (("intrinsic", None), ("intrinsic+reflex", ReflexOptions())):
        w0, c0 = time.perf_counter(), time.process_time()
        fit = fit_varying(t.theta[:, 0], -t.tau_h[:, 0], t.extra["sv"], t.fs, name="sv",
                          units="rad", reflex=rf)
        out[label] = {"wall_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0,
                      "order": fit.order, "heldout_vaf_pct": fit.heldout_vaf_pct,
                      "K_range": [float(fit.values["K"].min()), float(fit.values["K"].max())]}
    w0 = time.perf_counter()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    subprocess.run([sys.executable, "-m", "estimation", "estimate", str(PILOT),
                    "--torque-sign", "-1", "--reflex"], check=True, env=env,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    out["estimate_reflex_command_wall_s"] = time.perf_counter() - w0
    out["target_s"] = 10.0
    return out


def accuracy(count):
    rows = []
    for kind in ("moving_angle_dependent", "moving_pilot"):
        for i in range(count):
            spec = labsim.draw(kind, np.random.default_rng([11, i]), duration_s=60.0)
            rec = labsim.simulate(spec)
            t = rec.trial
            scheds = {"sv": t.extra["sv"]}
            if kind != "moving_pilot":  # the pilot form has the movement removed
                scheds["angle"] = slow_part(t.theta[:, 0], t.fs)
            for name, rho in scheds.items():
                rows.append(_row(kind, i, name, rho, t, rec))
    return rows


def _row(kind, i, name, rho, t, rec):
    fit = fit_varying(t.theta[:, 0], t.tau_h[:, 0], rho, t.fs, name=name,
                      units="rad")
    kr = rec.truth["K_of_rho"]
    truth = np.interp(fit.rho, kr["rho"], kr["K"])
    err = (fit.values["K"] - truth) / np.mean(truth)
    return {"kind": kind, "draw": i, "scheduling": name, "order": fit.order,
            "coverage": float(np.mean((fit.lo["K"] <= truth) &
                                      (truth <= fit.hi["K"]))),
            "max_err_pct": float(100 * np.max(np.abs(err))),
            "rms_err_pct": float(100 * np.sqrt(np.mean(err ** 2))),
            "K_truth_range": [float(truth.min()), float(truth.max())],
            "heldout_vaf_pct": fit.heldout_vaf_pct,
            "fit_wall_s": fit.elapsed_s}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=3, help="recordings of each kind")
    args = ap.parse_args(argv)
    doc = {"speed": speed(), "accuracy": accuracy(args.count)}
    s = doc["speed"]
    if "skipped" not in s:
        print(f"pilot 106 s: PV intrinsic {s['intrinsic']['wall_s']:.2f} s wall, +reflex "
              f"{s['intrinsic+reflex']['wall_s']:.2f} s; whole `estimate --reflex` "
              f"{s['estimate_reflex_command_wall_s']:.2f} s (target 10 s)")
    print("| kind | draw | scheduling | order | coverage | max err % | rms err % | K truth | "
          "held-out VAF PV / TI % |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in doc["accuracy"]:
        h = r["heldout_vaf_pct"]
        print(f"| {r['kind']} | {r['draw']} | {r['scheduling']} | {r['order']} | "
              f"{r['coverage']:.2f} | "
              f"{r['max_err_pct']:.2f} | {r['rms_err_pct']:.2f} | "
              f"{r['K_truth_range'][0]:.1f}-{r['K_truth_range'][1]:.1f} | "
              f"{h['varying']:.2f} / {h['invariant']:.2f} |")
    acc = doc["accuracy"]
    doc["summary"] = {}
    for name in ("sv", "angle"):
        a = [r for r in acc if r["scheduling"] == name]
        doc["summary"][name] = {"coverage_mean": float(np.mean([r["coverage"] for r in a])),
                                "max_err_pct_worst": float(max(r["max_err_pct"] for r in a)),
                                "rms_err_pct_mean": float(np.mean([r["rms_err_pct"]
                                                                   for r in a]))}
    print(doc["summary"])
    print(write_results("pv", doc))


if __name__ == "__main__":
    main()
