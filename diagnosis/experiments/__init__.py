"""Experiments the diagnosis re-simulates (docs/diagnosis.md, "Experiments").

:func:`experiment_for` picks the class that models a set of measured trials:

- :class:`ExoskeletonIMBIC`: the exoskeleton under IMBIC, torque perturbation, the plant
  FMU driven by the orchestrator (n joints for which a plant exists);
- :class:`PositionServo`: ``perturbation.kind = "position"``: an actuator servo imposes
  the angle, a torque sensor between actuator and limb measures; the limb model
  (diagnosis.limb) is driven by the recorded reference through the servo, or by the
  measured angle when no reference was recorded;
- :class:`RenderedImpedance`: torque perturbation on a set-up with no plant model (no
  ``robot`` block, or no plant FMU of its joints): the robot renders M_rd, B_rd, K_rd.

A new apparatus is one new :class:`Experiment` subclass added to ``EXPERIMENTS``.
"""

from __future__ import annotations

from ..errors import DiagnosisInputError
from .base import Experiment
from .exoskeleton import ExoskeletonIMBIC
from .position import PositionServo
from .rendered import RenderedImpedance

#: tried in order; the first whose ``accepts(trials)`` is true models the trials
EXPERIMENTS = (PositionServo, RenderedImpedance, ExoskeletonIMBIC)


def experiment_for(trials) -> Experiment:
    """The experiment that made ``trials`` (one declared set-up).

    Raises
    ------
    DiagnosisInputError
        Trials of different kinds of experiment, or none of the known kinds (the
        message names the trials and their ``perturbation.kind``).
    """
    kinds = {t.name: t.perturbation_kind for t in trials}
    if len(set(kinds.values())) > 1:
        raise DiagnosisInputError(f"trials of different perturbation kinds in one "
                                  f"diagnosis: {kinds}; diagnose each kind on its own")
    for cls in EXPERIMENTS:
        if cls.accepts(trials):
            return cls(trials)
    raise DiagnosisInputError(f"no experiment models trials {sorted(kinds)} "
                              f"(perturbation.kind {sorted(set(kinds.values()))}); known: "
                              + ", ".join(c.__name__ for c in EXPERIMENTS))


__all__ = ["EXPERIMENTS", "Experiment", "ExoskeletonIMBIC", "PositionServo",
           "RenderedImpedance", "experiment_for"]
