"""Stage 3, estimate the limb: the experiment's estimate from the measured trials (with
the sampling and leakage handling the trials declare), and the torque sign the
estimate reveals (a passive limb's stiffness is positive: conventions.check_torque_sign)."""

from __future__ import annotations

from ..conventions import check_torque_sign


def run(r) -> None:
    """Fill ``r.model``; a reversed torque sign is corrected and added to the findings."""
    model = r.experiment.estimate(r.trials)
    k_scale = r.units["tau_h"] / r.units["theta"] if r.units else 1.0  # the file's units
    trials, model, found = check_torque_sign(r.trials, model, r.experiment.estimate,
                                             k_scale)
    r.trials, r.model = trials, model
    r.findings += found
