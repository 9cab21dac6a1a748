"""Example lab data with known answers, for the worked example of docs/estimation.md.

``python -m estimation.examples ankle OUT`` writes a 1-DOF ankle position-perturbation
experiment (60 s at 1 kHz, angle, torque and the servo's reference, like a human-joint lab
archive): two conditions, ``relaxed`` (K 80 N m/rad, B 1.2 N m s/rad, I 0.012 kg m^2) and
``co-contracted`` (K 250, B 2.5, I 0.018), two recordings each labelled with its condition,
plus one unlabelled recording without the reference (``relaxed_noref``). The torque is
stored with the lab's opposite sign (``sensors.torque_sign = -1``) and ``t`` with 6
decimals, as lab files often are.
``python -m estimation.examples arm3 OUT`` writes the 3-joint torque-perturbation trials
(one per joint, reference-3dof.md arm and controller, 50 s).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

import trialformat as tf

from .synthetic import ARM_3DOF, CONTROLLER_3DOF, PEAK_3DOF, position_trial, synthetic_trial

ANKLE_CONDITIONS = {"relaxed": {"K": 80.0, "B": 1.2, "I": 0.012},
                    "co-contracted": {"K": 250.0, "B": 2.5, "I": 0.018}}


def write_ankle(out) -> list[Path]:
    """The ankle experiment (module docstring); returns the CSV paths."""
    out = Path(out)
    paths = []
    seed = 100
    for cond, limb in ANKLE_CONDITIONS.items():
        for rep in (1, 2):
            seed += 1
            trial = position_trial(**limb, duration_s=60.0, seed=seed, torque_sign=-1,
                                   condition=cond, name=f"{cond}_{rep}")
            paths.append(_write_lab_csv(out / f"{cond}_{rep}", trial))
    trial = position_trial(**ANKLE_CONDITIONS["relaxed"], duration_s=60.0, seed=seed + 1,
                           record_reference=False, torque_sign=-1)
    paths.append(_write_lab_csv(out / "relaxed_noref", trial))
    return paths


def _write_lab_csv(stem: Path, trial) -> Path:
    """As a lab's export: pandas, ``t`` with 6 decimals, 7 significant digits."""
    tf.write_trial(stem, trial)  # JSON and the stored sign convention
    frame = pd.read_csv(stem.with_suffix(".csv"))
    frame["t"] = frame["t"].map(lambda v: f"{v:.6f}")
    frame.to_csv(stem.with_suffix(".csv"), index=False, float_format="%.7g")
    return stem.with_suffix(".csv")


def write_arm3(out) -> list[Path]:
    """Three torque-perturbation trials of the 3-joint arm (reference-3dof.md)."""
    out = Path(out)
    return [tf.write_trial(out / f"arm3_dof{k}", synthetic_trial(
        perturbed_dof=k, arm=ARM_3DOF, controller=CONTROLLER_3DOF, peak=PEAK_3DOF,
        seed=10 + k, theta_noise_std_rad=1e-5, tau_noise_std_nm=0.02)) for k in (1, 2, 3)]


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2 or argv[0] not in ("ankle", "arm3"):
        print("usage: python -m estimation.examples {ankle|arm3} OUT", file=sys.stderr)
        return 2
    for p in (write_ankle if argv[0] == "ankle" else write_arm3)(argv[1]):
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())
