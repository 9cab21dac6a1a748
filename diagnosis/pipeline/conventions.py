"""Stage 2, conventions and storage: declared conventions, absolute angles, degrees, a
rounded ``t`` (diagnosis.conventions), how the numbers were stored (storage.py, read
once per trial), and the experiment that made the trials (diagnosis.experiments)."""

from __future__ import annotations

from ..conventions import apply_declared, check_angles, check_time, normalise_units
from ..errors import DiagnosisInputError
from ..evaluation import storage_context
from ..experiments import experiment_for


def run(r) -> None:
    """Correct ``r.trials``, fill ``r.findings``, ``r.experiment``, ``r.effects``,
    ``r.units``."""
    sources = {t.name: getattr(t, "_source", t.name) for t in r.trials}
    trials, findings = apply_declared(r.trials)
    trials, found = check_angles(trials)
    findings += found + check_time(trials)
    for t in trials:
        storage_context(t)
    r.trials, r.findings = trials, findings
    r.experiment = experiment_for(trials)
    check_plant_options(r)
    if r.experiment.scale_free:
        trials, r.units, found = normalise_units(trials, sources.get)
        findings += found
        r.trials, r.findings = trials, findings
    from ..catalogue import CATALOGUE
    if tuple(r.config.effects) != tuple(CATALOGUE):  # a selection (--effects): all usable
        r.experiment.check_selected_effects(tuple(r.config.effects))
    r.effects = r.experiment.applicable_effects(r.config.effects)
    r.skipped_effects = tuple(e for e in r.config.effects if e not in r.effects)


def check_plant_options(r) -> None:
    """Refuse a plant FMU or an RK4 step for an experiment that simulates no plant (the
    position servo's limb model, the rendered impedance): silently ignoring them would
    let a user believe their plant was used. For a plant experiment, an RK4 step that
    does not divide the sample period (:func:`check_rk4_divides`). This order makes the
    first message the one that applies: a position trial is told to leave ``--rk4-step``
    out, not to use another step.

    Raises
    ------
    DiagnosisInputError
        Naming the option, the trials and the model the experiment re-simulates.
    """
    if r.experiment.uses_plant:
        check_rk4_divides(r)
        return
    names = ", ".join(t.name for t in r.trials[:3]) + (" ..." if len(r.trials) > 3 else "")
    what = {"position": "the limb model of diagnosis.limb driven by the measured angle "
                        "(or the servo reference)",
            "rendered": "the rendered impedance M_rd, B_rd, K_rd"}.get(
        r.experiment.kind, f"its own model ({type(r.experiment).__name__})")
    for option, value in (("--fmu", r.plant), ("--rk4-step", r.rk4_step)):
        if value is not None:
            shown = getattr(value, "path", value)
            raise DiagnosisInputError(
                f"{option} {shown}: trials {names} are {r.experiment.kind} experiments, "
                f"re-simulated by {what}, not by a plant FMU; leave {option} out")
    import os
    import warnings

    from orchestrator.trial import PLANT_ENV, PLANT_PARAMETERS_ENV
    for option, env in (("--plant", PLANT_ENV), ("--plant-parameter", PLANT_PARAMETERS_ENV)):
        if os.environ.get(env):  # the option, or a variable a lab exported for all runs
            warnings.warn(f"{option} / ${env} = {os.environ[env]} is not used: trials "
                          f"{names} are {r.experiment.kind} experiments, re-simulated by "
                          f"{what}", stacklevel=2)


def check_rk4_divides(r) -> None:
    """Refuse an RK4 step that does not divide the trials' sample period, naming the
    first trial, its rate and a step that would (orchestrator.trial.check_rk4_step)."""
    if r.rk4_step is None:
        return
    from orchestrator.trial import check_rk4_step
    first = r.trials[0]
    try:
        check_rk4_step(r.rk4_step, 1.0 / first.fs)
    except ValueError as exc:
        raise DiagnosisInputError(f"{first.name}: fs = {first.fs:g} Hz: {exc}") from None
