"""Stage 2, conventions and storage: declared conventions, absolute angles, degrees, a
rounded ``t`` (diagnosis.conventions), how the numbers were stored (storage.py, read
once per trial), and the experiment that made the trials (diagnosis.experiments)."""

from __future__ import annotations

from ..conventions import apply_declared, check_angles, check_time
from ..evaluation import storage_context
from ..experiments import experiment_for


def run(r) -> None:
    """Correct ``r.trials``, fill ``r.findings``, ``r.experiment``, ``r.effects``."""
    trials, findings = apply_declared(r.trials)
    trials, found = check_angles(trials)
    findings += found + check_time(trials)
    for t in trials:
        storage_context(t)
    r.trials, r.findings = trials, findings
    r.experiment = experiment_for(trials)
    r.effects = r.experiment.applicable_effects(r.config.effects)
    r.skipped_effects = tuple(e for e in r.config.effects if e not in r.effects)
