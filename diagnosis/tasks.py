"""The parallel tasks of a diagnosis (diagnosis.parallel runs them).

Each task is ``fn(state, *args)``: ``state`` (:class:`TaskState`) is what every task of
one diagnosis reads, sent to each worker once; every worker keeps its own evaluators and
simulation cache (parallel.worker_cache).
"""

from __future__ import annotations

from dataclasses import dataclass

from .config import DiagnosisConfig
from .evaluation import Evaluator, Unit, effects_key
from .fitting import EffectFit, Search, fit_effect, fit_second, jsonable, refine_pair
from .parallel import worker_cache


@dataclass
class TaskState:
    """What every parallel task of one diagnosis reads (sent to each worker once)."""

    token: str
    trials: list
    experiment: object
    model: object
    config: DiagnosisConfig
    plant: str | None
    cal: list     # (trial index, start, stop, role)
    held: list
    rk4_step: float | None = None

    def simulator(self):
        return self.experiment.simulator(self.model, plant=self.plant, rk4_step=self.rk4_step)


def prefill(cache: dict, trials, effects: dict, sims) -> None:
    """Put full-length runs made by the workers into an evaluator cache."""
    key = effects_key(effects)
    for t, sim in zip(trials, sims):
        cache[(t.name, key)] = (t.n_samples, sim)


def _worker_evaluators(state: TaskState, norms_cal: dict, norms_held: dict):
    """The calibration and held-out evaluators of this worker (one simulation cache),
    with the normalisation the parent fixed from the nominal model."""
    def build():
        simulate = state.simulator()
        cache: dict = {}
        units = [[Unit(state.trials[i], a, b, role) for i, a, b, role in spec]
                 for spec in (state.cal, state.held)]
        return tuple(Evaluator(state.experiment, simulate, u, state.config, cache, norms=n)
                     for u, n in zip(units, (norms_cal, norms_held)))
    return worker_cache(state, "evaluators", build)


def task_simulate(state: TaskState, trial_index: int, effects: dict):
    """Full-length run of one trial with ``effects`` (None when it diverges)."""
    t = state.trials[trial_index]
    simulate = worker_cache(state, "simulate", state.simulator)
    return simulate(t, effects, t.n_samples)


def _with_held_out(fit: EffectFit, ev_held: Evaluator, n0: int, n_dof: int) -> EffectFit:
    fit.held_out_gap = ev_held.gap_value(fit.simulation_effects(n_dof))
    fit.n_evaluations += ev_held.n_simulations - n0
    return fit


def task_fit_single(state: TaskState, name: str, norms_cal: dict, norms_held: dict):
    """Fit one effect alone on the calibration units; its held-out gap."""
    ev_cal, ev_held = _worker_evaluators(state, norms_cal, norms_held)
    n_held = ev_held.n_simulations
    search = Search()
    params, gcal, nev, obj = fit_effect(name, ev_cal, search=search)
    fit = search.record(name, EffectFit((name,), {name: jsonable(params)}, gcal, nev,
                                        objective=obj))
    return _with_held_out(fit, ev_held, n_held, ev_cal.n_dof)


def task_fit_second(state: TaskState, best: EffectFit, other: str, norms_cal: dict,
                    norms_held: dict):
    """The effect ``other`` fitted on top of the best single; its held-out gap."""
    ev_cal, ev_held = _worker_evaluators(state, norms_cal, norms_held)
    n_held = ev_held.n_simulations
    fit = fit_second(best, other, ev_cal, ev_cal.n_dof)
    return _with_held_out(fit, ev_held, n_held, ev_cal.n_dof)


def task_refine_pair(state: TaskState, fit: EffectFit, norms_cal: dict, norms_held: dict):
    """One more coordinate step on the best pair; its held-out gap."""
    ev_cal, ev_held = _worker_evaluators(state, norms_cal, norms_held)
    n_held = ev_held.n_simulations
    refined = refine_pair(fit, ev_cal, ev_cal.n_dof)
    if refined is fit:
        return fit
    return _with_held_out(refined, ev_held, n_held, ev_cal.n_dof)


def _limbfit_setup(state: TaskState, cfg):
    """This worker's limbfit records, prepared signals and nominal fit of the state's
    trials (diagnosis.limbfit; built once per worker and FitConfig)."""
    from . import limbfit as lf

    def build():
        preps = lf.prepare([lf.PositionRecord.from_trial(t) for t in state.trials], cfg)
        return preps, lf.fit_nominal(preps, cfg)
    return worker_cache(state, ("limbfit", repr(cfg)), build)


def task_limbfit_call(state: TaskState, cfg, fn, args: tuple):
    """``fn(limbfit, preps, nominal, cfg, *args)`` on this worker's prepared records and
    nominal fit of the state's trials (:func:`_limbfit_setup`): the independent steps of
    a position diagnosis after its single fits (diagnosis.limbpairs.forward_choice and
    refine_task, diagnosis.limbties.score_task); ``fn`` a module-level function, its
    arguments and result picklable."""
    from . import limbfit as lf
    preps, nominal = _limbfit_setup(state, cfg)
    return fn(lf, preps, nominal, cfg, *args)


def task_limbfit(state: TaskState, name: str, cfg) -> dict:
    """A position experiment's fit of one effect (limbfit.fit_effect, no intervals) on
    the state's trials, as its JSON-able record (limbfit.fit_record: the parent rebuilds
    it bit for bit with limbfit.fit_from_record)."""
    from . import limbfit as lf
    preps, nominal = _limbfit_setup(state, cfg)
    return lf.fit_record(lf.fit_effect(preps, name, nominal, cfg, intervals=False))
