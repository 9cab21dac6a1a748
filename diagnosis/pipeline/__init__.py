"""The diagnosis as a pipeline of stages passing one :class:`DiagnosisRun` forward.

====  ============  ==========================================================
 1    read          the measured trials, blind (inputs.py); options checked
 2    conventions   declared conventions, angles, ``t``, storage; the experiment
 3    estimate      the limb, with the trials' sampling and leakage; torque sign
 4    nominal       split; workers; nominal runs; evaluators and nominal gaps
 5    where         the gap by signal, joint, band, kind, level
 6    which         each applicable effect fitted alone; pairs
 6b   when          the gap per time block of the shared time-variation test
 7    how_far       calibration and held-out reductions of every fit
 8    verdict       the named effect(s); the named model's runs; the summary
 9    report        DiagnosisReport; the report folder, written atomically
====  ============  ==========================================================

Each stage is a module with ``run(r)``; the data flow one way, from stage to stage
through ``r``. Stages 4-8 share the workers (``r.runner``) and, with an out folder, the
resume store (pipeline.resume), so a killed diagnosis re-run with the same inputs and
options redoes only the tasks it had not finished.
"""

from __future__ import annotations

from . import (conventions, estimate, how_far, nominal, read, report, verdict, when, where,
               which)
from .resume import ResumeStore, run_key
from .state import DiagnosisRun

STAGES = (read, conventions, estimate, nominal, where, which, when, how_far, verdict, report)


def run(r: DiagnosisRun) -> DiagnosisRun:
    """Run every stage on ``r`` (its options set); returns ``r`` with ``r.report``."""
    if r.out_dir is not None:
        report.check_out_dir(r.out_dir, r.source)
    try:
        for i, stage in enumerate(STAGES):
            if r.stage_lines:
                stage_line(r, i)
            if stage is nominal and r.out_dir is not None:
                r.resume = ResumeStore(r.out_dir, run_key(r.trials, r.config, r.plant,
                                                          r.rk4_step))
            if stage is report and r.runner is not None:
                r.runner.close()
            stage.run(r)
        if r.stage_lines:
            stage_line(r, len(STAGES))
    except BaseException:
        # Ctrl-C, SIGTERM or an error: running tasks are stopped now, not waited for (what
        # finished is in the resume store)
        if r.runner is not None:
            r.runner.close(now=True)
        raise
    finally:
        if r.runner is not None:
            r.runner.close()
    return r


def stage_line(r: DiagnosisRun, i: int) -> None:
    """``diagnose: stage I/N NAME (T s)`` on stderr as stage ``i`` starts (``i`` =
    len(STAGES): ``diagnose: done (T s)``), T the time since the diagnosis started; the
    condition's label first when the trials have one."""
    import sys
    import time
    cond = r.trials[0].meta.get("condition") if r.trials else None
    head = "diagnose: " + (f"[{cond}] " if cond is not None else "")
    elapsed = f"({time.perf_counter() - r.t0:.1f} s)"
    if i >= len(STAGES):
        text = f"{head}done {elapsed}"
    else:
        name = STAGES[i].__name__.rsplit(".", 1)[-1]
        text = f"{head}stage {i + 1}/{len(STAGES)} {name} {elapsed}"
    print(text, file=sys.stderr, flush=True)


__all__ = ["DiagnosisRun", "STAGES", "run", "stage_line"]
