"""The one result object a diagnosis passes from stage to stage (diagnosis.pipeline)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from ..config import DiagnosisConfig


@dataclass
class DiagnosisRun:
    """Everything one diagnosis knows, filled in stage by stage.

    The options come first (set by :func:`diagnosis.diagnose`); each stage reads what
    earlier stages wrote and adds its own part: ``read`` the trials; ``conventions`` the
    findings and the experiment; ``estimate`` the limb model; ``nominal`` the units,
    evaluators and nominal gaps; ``where`` the breakdown; ``which`` the fits; ``how_far``
    their held-out reductions; ``verdict`` the verdict and the named model's runs;
    ``report`` the report (and its folder).
    """

    source: object
    out_dir: object = None
    config: DiagnosisConfig = DiagnosisConfig()
    plant: object = None
    progress: bool = True
    stage_lines: bool = False      # one stderr line per stage (pipeline.run)
    workers: int | None = None
    scheduler: object = None
    rk4_step: float | None = None
    grouping: str = ""             # the one line of the grouping rule (estimation.grouping)
    scheduling: list = field(default_factory=list)  # trialformat.scheduling.usage per trial
    t0: float = field(default_factory=time.perf_counter)
    resume: object = None          # pipeline.resume.ResumeStore or None
    # read, conventions
    trials: list = field(default_factory=list)
    findings: list = field(default_factory=list)
    experiment: object = None
    effects: tuple = ()
    skipped_effects: tuple = ()
    units: dict | None = None      # {signal: divisor} the trials were rescaled by, or None
    # estimate
    model: object = None
    # nominal
    cal: list = field(default_factory=list)
    held: list = field(default_factory=list)
    rule: str = ""
    runner: object = None
    state: object = None
    cache: dict = field(default_factory=dict)
    ev_all: object = None
    ev_cal: object = None
    ev_held: object = None
    nominal_all: object = None
    g0_cal: float = float("nan")
    g0_held: float = float("nan")
    numerics: list = field(default_factory=list)
    # where
    where: dict = field(default_factory=dict)
    when: dict = field(default_factory=dict)   # pipeline.when: the gap in time
    # which, how far
    singles: list = field(default_factory=list)
    pairs: list = field(default_factory=list)
    significant: bool = False
    n_worker_sims: int = 0
    fit_measure: dict | None = None   # an experiment's own fit measure (which)
    #: an experiment's own judge of the named fit's alternatives (which; None: the
    #: ranking's shared split, diagnosis.ties.rows_from_fits)
    alternatives: object = None
    ranking: list = field(default_factory=list)
    pair_rows: list = field(default_factory=list)
    # verdict
    verdict: str = ""
    named: list = field(default_factory=list)
    chosen: object = None
    after: object = None
    ev_named: object = None
    amplitude: dict = field(default_factory=dict)
    summary: str = ""
    timings: list = field(default_factory=list)
    #: alternatives to the named fit (diagnosis.ties rows) and the tied ones' names
    alternative_rows: list = field(default_factory=list)
    indistinguishable: list = field(default_factory=list)
    # report
    report: object = None

    @property
    def n_dof(self) -> int:
        return self.trials[0].n_dof

    def map(self, fn, arg_tuples, desc: str) -> list:
        """``self.runner.map``, through the resume store when there is one (a task whose
        result it holds is not run again)."""
        if self.resume is not None:
            return self.resume.map(self.runner, fn, list(arg_tuples), desc)
        return self.runner.map(fn, list(arg_tuples), desc=desc)
