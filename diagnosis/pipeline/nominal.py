"""Stage 4, nominal simulation: the calibration / held-out split, the workers, the
nominal run of every trial, and the evaluators whose normalisation it fixes."""

from __future__ import annotations

import uuid

from ..evaluation import Evaluator, Unit, split_units
from ..parallel import Runner
from ..tasks import TaskState, prefill, task_simulate


def run(r) -> None:
    """Fill the split, ``r.runner`` (closed by the pipeline), the evaluators, the nominal
    gaps and the numerical retries."""
    trials, cfg = r.trials, r.config
    r.cal, r.held, r.rule = split_units(trials, cfg)
    index = {t.name: i for i, t in enumerate(trials)}
    plant_ref = getattr(r.plant, "path", r.plant)
    r.state = TaskState(token=uuid.uuid4().hex, trials=trials, experiment=r.experiment,
                        model=r.model, config=cfg,
                        plant=None if plant_ref is None else str(plant_ref),
                        cal=[(index[u.trial.name], u.start, u.stop, u.role) for u in r.cal],
                        held=[(index[u.trial.name], u.start, u.stop, u.role) for u in r.held],
                        rk4_step=r.rk4_step)
    r.runner = Runner(r.state, workers=r.workers, scheduler=r.scheduler,
                      progress=r.progress)
    # nominal runs of every trial (the calibration and held-out units are prefixes)
    sims = r.map(task_simulate, [(i, {}) for i in range(len(trials))], "nominal runs")
    prefill(r.cache, trials, {}, sims)
    r.numerics = [{"trial": t.name, **sim.meta["simulation"]["numerical_retry"]}
                  for t, sim in zip(trials, sims)
                  if sim is not None and "numerical_retry" in sim.meta.get("simulation", {})]
    _keep_retry_step(r)
    simulate = r.experiment.simulator(r.model, plant=plant_ref, rk4_step=r.rk4_step)
    full = [Unit(t, 0, t.n_samples, "all") for t in trials]
    r.ev_all = Evaluator(r.experiment, simulate, full, cfg, r.cache)
    r.nominal_all = r.ev_all.gap({})
    r.ev_cal = Evaluator(r.experiment, simulate, r.cal, cfg, r.cache)
    r.ev_held = Evaluator(r.experiment, simulate, r.held, cfg, r.cache)
    r.g0_cal, r.g0_held = r.ev_cal.gap_value({}), r.ev_held.gap_value({})
    r.significant = bool(r.nominal_all.value > cfg.significance_gap)


def _keep_retry_step(r) -> None:
    """When the nominal runs needed a smaller RK4 step (a stiff plant: LuGre sigma0 1e6),
    every candidate model starts from it: a candidate's run that fails at the default step
    would otherwise diverge (its torque limit, not retried) and be scored as a model that
    cannot reproduce the trials. The workers are restarted with the step (they hold the
    state they were started with)."""
    if r.rk4_step is not None or not r.numerics:
        return
    import dataclasses
    r.rk4_step = min(float(n["rk4_step"]) for n in r.numerics)
    r.state = dataclasses.replace(r.state, rk4_step=r.rk4_step, token=uuid.uuid4().hex)
    timings = list(r.runner.timings)
    r.runner.close()
    r.runner = Runner(r.state, workers=r.workers, scheduler=r.scheduler,
                      progress=r.progress)
    r.runner.timings[:0] = timings
