"""Stage 1, read: the measured trials, blind to any truth (diagnosis.inputs), and the
options checked against them."""

from __future__ import annotations

from .. import catalogue as cat
from ..errors import DiagnosisInputError
from ..inputs import load_trials


def run(r) -> None:
    """Fill ``r.trials``; refuse trials too short, unknown effects. (An RK4 step is
    checked once the experiment is known, pipeline.conventions.check_plant_options: an
    experiment that simulates no plant refuses any step, before its divisibility.)"""
    cfg = r.config
    trials = r.trials or load_trials(r.source)
    for t in trials:
        if t.n_samples < 4 * cfg.features.nperseg:
            raise DiagnosisInputError(f"trial {t.name!r}: {t.n_samples} samples, fewer than "
                                      f"4 spectral segments of {cfg.features.nperseg}")
    unknown = [e for e in cfg.effects if e not in cat.CATALOGUE]
    if unknown:
        raise DiagnosisInputError(f"config.effects: unknown effect(s) {unknown}")
    r.trials = trials
