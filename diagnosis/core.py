"""The diagnosis: where the sim-to-real gap lies, which effect causes it, how far it shrinks.

:func:`diagnose` runs the pipeline of stages (diagnosis.pipeline: read, conventions and
storage, estimate the limb, nominal simulation, where, which, how far, verdict, report)
on the experiment that made the trials (diagnosis.experiments). A folder whose trials
declare several ``condition`` labels (e.g. the five reklab ankle recordings) is diagnosed
condition by condition (each is another limb state), with an index report.

The names earlier versions defined here are re-exported from the modules that hold them
now (config, evaluation, fitting, pipeline.*).
"""

from __future__ import annotations

from pathlib import Path

from .config import (AMPLITUDE_GAP, VERDICT_CONVENTION, VERDICT_EFFECT, VERDICT_NONE,  # noqa: F401
                     VERDICT_PARTLY, VERDICT_UNEXPLAINED, DiagnosisConfig)
from .evaluation import Evaluator, Unit, split_units, storage_context  # noqa: F401
from .fitting import EffectFit, fit_effect  # noqa: F401
from .pipeline import DiagnosisRun, run
from .pipeline.verdict import choose as _verdict  # noqa: F401
from .pipeline.verdict import pair_earns_second as _pair_earns_second  # noqa: F401
from .pipeline.where import amplitude_dependence, rest_where, where_breakdown  # noqa: F401
from .report import DiagnosisReport  # noqa: F401


def diagnose(source, out_dir=None, *, config: DiagnosisConfig = DiagnosisConfig(),
             plant=None, progress: bool = True, workers: int | None = None,
             scheduler=None, rk4_step: float | None = None, scheduling: str | None = None,
             stage_lines: bool | None = None):
    """Diagnose the sim-to-real gap of a folder of measured trials.

    Parameters
    ----------
    source : path or list of paths
        Folder of trials (``NAME.csv`` + ``NAME.json``, ``NAME.mat``, or a ``.mat`` of
        NLID ``nldat`` objects such as the reklab ankle recordings) or a list of files.
        Truth files (``NAME.truth.json``) and ``meta["simulation"]`` are never read.
    out_dir : path, optional
        Report folder (``report.md``, ``report.json``, PNG plots), written atomically; an
        existing folder that is not a diagnosis report is refused. A killed run re-run
        with the same inputs and options resumes from what it had finished.
    config : DiagnosisConfig, keyword-only
    plant : orchestrator.Plant or path, optional
        The plant FMU of an exoskeleton experiment (default: the reference plant).
    progress : bool
        Show tqdm progress bars.
    stage_lines : bool, optional
        One line on stderr as each stage of the pipeline starts (``diagnose: stage 6/10
        which (12.3 s)``, the time since the start) and ``diagnose: done (T s)`` at the end
        (default: as ``progress``; the command line prints them under ``--quiet`` too).
    workers : int, optional
        Local processes that run the simulations (default: one per core; 1: this
        process). The result does not depend on it.
    scheduler : str or distributed.Client, optional
        Dask scheduler address (e.g. ``tcp://HOST:8786``): run on that cluster instead.
    rk4_step : float [s], optional
        The plant's internal RK4 step; it must divide the trials' sample period (refused
        up front with both values). Default: the plant's, or the step nearest it that
        divides the period (any sample rate).
    scheduling : str, optional
        The scheduling variable (``--scheduling NAME``: an extra column, ``time``,
        ``angle[j]``), set as every trial's metadata ``scheduling``
        (trialformat.scheduling.request); refused up front, SchedulingError, where a trial
        has no usable variable of that name.

    Returns
    -------
    DiagnosisReport
        Or, for trials of several conditions, a :class:`DiagnosisSet` of one report per
        condition.

    Raises
    ------
    DiagnosisInputError
        No trial, disagreeing declared set-ups, trials too short, an out folder that
        would overwrite other files; the message names the file and key.
    """
    from .inputs import load_trials, split_conditions
    options = dict(config=config, plant=plant, progress=progress, workers=workers,
                   stage_lines=progress if stage_lines is None else bool(stage_lines),
                   scheduler=scheduler, rk4_step=rk4_step)
    from estimation.grouping import describe, trial_sets
    trials = load_trials(source, check=False)
    if scheduling is not None:
        from trialformat.scheduling import request
        for t in trials:
            request(t, scheduling)
    # the scheduling variable of each trial and whether the state-varying effects may use
    # it: the same refusal as estimate's parameter-varying fit (trialformat.scheduling)
    options["scheduling"] = _scheduling_usage(trials, requested=scheduling is not None)
    groups = split_conditions(trials)
    # the rule estimate and figures follow too, said in one line of each report
    options["grouping"] = describe(trial_sets(trials))
    grouping = options["grouping"]
    from estimation.grouping import near_duplicate_labels
    label_note = near_duplicate_labels(trials)
    if label_note:
        import warnings
        warnings.warn(label_note, stacklevel=2)
    if len(groups) == 1:
        trials = next(iter(groups.values()))
        return run(DiagnosisRun(source=source, out_dir=out_dir, trials=trials,
                                **options)).report
    from .pipeline.report import check_out_dir
    from .report import write_set_index
    if out_dir is not None:
        check_out_dir(out_dir, source)  # the index folder too holds nothing of the user's
    import warnings

    from estimation.grouping import unique_file_names
    folders, renamed = unique_file_names(list(groups), _safe)
    for note in renamed:  # one name, one output (issue 22)
        warnings.warn(f"report folders: {note}", stacklevel=2)
    reports = {}
    for (condition, trials), folder in zip(groups.items(), folders):
        sub = None if out_dir is None else Path(out_dir) / folder
        reports[condition] = run(DiagnosisRun(source=source, out_dir=sub, trials=trials,
                                              **options)).report
    result = DiagnosisSet(reports)
    result.notes = renamed
    result.grouping = grouping
    if out_dir is not None:
        result.out_dir = Path(out_dir)
        write_set_index(result, out_dir)
    return result


def _scheduling_usage(trials, requested: bool = False) -> list:
    """trialformat.scheduling.usage of every trial that has a scheduling variable; a
    named variable refused for a varying fit is warned about with estimate's notice."""
    import warnings

    from trialformat.errors import SchedulingError
    from trialformat.scheduling import usage
    out = []
    for t in trials:
        try:
            u = usage(t)
        except SchedulingError:  # a malformed declaration: the state effects go without
            continue
        if u is None:
            continue
        if requested:  # --scheduling NAME (request wrote it into the metadata)
            u["how"] = "requested"
        if u["refusal"] and u["how"] != "default":
            warnings.warn(u["refusal"], stacklevel=3)
        out.append(u)
    return out


def _safe(name: str) -> str:
    """A condition's report folder: the file-name form ``figures`` uses too
    (estimation.grouping.safe_name), so ``"PF 10%"`` is ``PF_10`` in both."""
    from estimation.grouping import safe_name
    return safe_name(name, "condition")


class DiagnosisSet:
    """The reports of a diagnosis over several conditions (one limb state each).

    Attributes
    ----------
    reports : dict condition -> DiagnosisReport
    """

    def __init__(self, reports: dict):
        self.reports = reports
        self.out_dir = None
        self.notes = []  # output names made unique (issue 22)

    @property
    def verdict(self) -> str:
        return "; ".join(f"{c}: {r.verdict}" for c, r in self.reports.items())

    @property
    def named(self) -> list:
        return sorted({n for r in self.reports.values() for n in r.named})

    @property
    def summary(self) -> str:
        return " ".join(f"[{c}] {r.summary}" for c, r in self.reports.items())

    def to_dict(self) -> dict:
        return {"format": "arm-impedance-diagnosis-set/1",
                "conditions": {c: r.to_dict() for c, r in self.reports.items()}}
