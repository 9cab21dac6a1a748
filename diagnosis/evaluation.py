"""Units of comparison and the evaluator: a candidate model's gap over measured stretches.

A :class:`Unit` is a stretch of one measured trial; :func:`split_units` makes the
calibration and held-out units; an :class:`Evaluator` re-simulates units through the
experiment (diagnosis.experiments) with a candidate model and computes their gap
(gap.py), caching every run.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from .config import DiagnosisConfig
from .errors import DiagnosisInputError
from .features import StorageContext
from .gap import GapResult, make_normaliser, set_gap


@dataclass
class Unit:
    """A stretch of one measured trial: simulate samples [0, stop), compare [start, stop)."""

    trial: object
    start: int
    stop: int
    role: str

    @property
    def key(self) -> str:
        return f"{self.trial.name}[{self.start}:{self.stop}]"

    @property
    def level(self):
        return (self.trial.meta.get("perturbation") or {}).get("level")


def split_units(trials, cfg: DiagnosisConfig) -> tuple[list, list, str]:
    """Calibration and held-out units, and the rule applied (docs/diagnosis.md).

    Trials are grouped by perturbed joint and sorted by (level, seed, name). A group of
    two or more alternates: even positions calibrate (at most
    ``calibration_trials_per_joint``, first ``calibration_s``), odd positions are held
    out (first ``held_out_s``). A group of one trial is split in time at
    ``time_split_fraction``: the fit sees the first part, the held-out part is the rest
    of the same run (simulated from t = 0 so that its initial state is right).

    Raises
    ------
    DiagnosisInputError
        A lone trial too short to split (names the trial and the samples needed).
    """
    nperseg = cfg.features.nperseg
    fs = trials[0].fs
    groups: dict = {}
    for t in trials:
        groups.setdefault(t.perturbed_dof, []).append(t)
    cal, held, rules = [], [], set()
    for k in sorted(groups, key=lambda v: -1 if v is None else v):
        group = sorted(groups[k], key=lambda t: (
            (t.meta.get("perturbation") or {}).get("level") or 0,
            (t.meta.get("perturbation") or {}).get("seed") or 0, t.name))
        if len(group) == 1:
            t = group[0]
            cut = int(round(cfg.time_split_fraction * t.n_samples))
            short = min(cut, t.n_samples - cut)
            if short < 3 * nperseg:
                raise DiagnosisInputError(
                    f"trial {t.name!r}: {t.n_samples} samples; a lone trial of its joint is "
                    f"split in time and each part needs at least {3 * nperseg} samples "
                    f"(3 spectral segments of {nperseg}), i.e. the trial at least "
                    f"{math.ceil(3 * nperseg / min(cfg.time_split_fraction, 1 - cfg.time_split_fraction))} samples")
            cal.append(Unit(t, 0, cut, "calibration"))
            held.append(Unit(t, cut, t.n_samples, "held_out"))
            rules.add("time")
            continue
        rules.add("trials")
        for pos, t in enumerate(group):
            if pos % 2 == 0 and pos // 2 < cfg.calibration_trials_per_joint:
                stop = min(t.n_samples, int(round(cfg.calibration_s * fs)))
                cal.append(Unit(t, 0, max(stop, min(t.n_samples, 4 * nperseg)), "calibration"))
            elif pos % 2 == 1:
                stop = min(t.n_samples, int(round(cfg.held_out_s * fs)))
                held.append(Unit(t, 0, max(stop, min(t.n_samples, 4 * nperseg)), "held_out"))
    rule = " + ".join(sorted(rules))
    return cal, held, rule


def storage_context(trial) -> StorageContext:
    """How ``trial``'s numbers were stored (read once per trial object)."""
    context = getattr(trial, "_storage_context", None)
    if context is None:
        context = StorageContext.from_trial(trial)
        trial._storage_context = context
    return context


def effects_key(effects: dict) -> str:
    """A canonical text of an effects dict (cache key)."""
    return json.dumps(effects, sort_keys=True)


class Evaluator:
    """Simulates units with candidate models and computes their gap; caches every run.

    Parameters
    ----------
    experiment : diagnosis.experiments.Experiment
        Says which signals are compared and how a segment is simulated.
    simulate : callable
        ``simulate(trial, effects, n_samples) -> Trial or None`` (None: the model
        diverges), usually ``experiment.simulator(model, ...)``.
    units : list of Unit
    cfg : DiagnosisConfig
    cache : dict, optional
        Runs shared with other evaluators: (trial name, effects key) -> (length, run).
    norms : dict, optional
        The normalisation fixed elsewhere from the nominal model (a parallel worker).

    The normalisation of each unit is fixed from the nominal model (gap.py).

    Raises
    ------
    DiagnosisInputError
        The nominal model diverges on a unit.
    """

    def __init__(self, experiment, simulate, units, cfg: DiagnosisConfig,
                 cache: dict | None = None, norms: dict | None = None):
        self.experiment, self.simulate, self.units, self.cfg = experiment, simulate, units, cfg
        self.n_dof = units[0].trial.n_dof
        self._sims: dict = {} if cache is None else cache
        self.n_simulations = 0
        # how each measured trial was stored: simulations are stored alike (storage.py)
        self.contexts = {u.trial.name: storage_context(u.trial) for u in units}
        self.measured = {u.key: experiment.features(u.trial, cfg.features, start=u.start,
                                                    stop=u.stop,
                                                    context=self.contexts[u.trial.name])
                         for u in units}
        if norms is not None:  # fixed by the nominal model elsewhere (a parallel worker)
            self.norms = norms
            return
        nominal = {u.key: self.features(u, {}) for u in units}
        if any(v is None for v in nominal.values()):
            bad = [k for k, v in nominal.items() if v is None]
            raise DiagnosisInputError(
                f"the nominal model diverges on {bad}{experiment.divergence_hint()}: the "
                f"declared set-up cannot reproduce these trials")
        self.norms = {u.key: make_normaliser(self.measured[u.key], nominal[u.key],
                                             cfg.features) for u in units}

    def simulation(self, unit: Unit, effects: dict):
        """The model's run of the unit's experiment, at least ``unit.stop`` samples long.

        Runs are causal, so one run serves every unit that is a prefix of it; the cache
        keeps the longest run per (trial, model) and may be shared between evaluators.
        """
        key = (unit.trial.name, effects_key(effects))
        have = self._sims.get(key)
        # a model that diverged once is not run again (it is unstable)
        if have is None or (have[1] is not None and have[0] < unit.stop):
            sim = self.simulate(unit.trial, effects, unit.stop)
            self._sims[key] = (unit.stop, sim)
            self.n_simulations += 1
        return self._sims[key][1]

    def features(self, unit: Unit, effects: dict):
        sim = self.simulation(unit, effects)
        if sim is None:
            return None
        context = self.contexts[unit.trial.name]
        return self.experiment.features(context.store(sim), self.cfg.features,
                                        start=unit.start, stop=unit.stop, context=context)

    def gap(self, effects: dict) -> GapResult | None:
        """Gap of the model ``nominal + effects`` over the units (None: it diverged)."""
        pairs = []
        for u in self.units:
            f = self.features(u, effects)
            if f is None:
                return None
            pairs.append((u.trial.name, u.level, self.measured[u.key], f, self.norms[u.key]))
        return set_gap(pairs)

    def gap_value(self, effects: dict) -> float:
        result = self.gap(effects)
        return math.inf if result is None else result.value

    def objective(self, effects: dict) -> float:
        """Unclipped excess gap (GapResult.excess), inf when the model diverges."""
        result = self.gap(effects)
        return math.inf if result is None else result.excess
