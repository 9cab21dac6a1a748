"""The diagnosis: where the sim-to-real gap lies, which effect causes it, how far it shrinks.

Flow of :func:`diagnose` (docs/diagnosis.md):

1. read the measured trials blind (inputs.py), estimate the arm (arm.py);
2. simulate every trial with the nominal model; the gap of every feature, broken down
   by signal, joint, band, kind and perturbation level, says *where*;
3. split the trials into calibration and held-out units (:func:`split_units`);
4. fit every catalogue effect alone on the calibration units, rank by calibration gap;
   pairs of the top-ranked when no single effect closes the gap;
5. evaluate each fitted model on the held-out units: the gap reduction there is the
   headline *how far* per effect;
6. a verdict: the effect(s), "no significant gap" or "unexplained".
"""

from __future__ import annotations

import json
import math
import uuid
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
from scipy import optimize
from scipy import signal as sps

from . import catalogue as cat
from .arm import (ArmModel, arm_behind_cuff, arm_behind_transmission, estimate_arm,
                  link_inertia)
from .conventions import apply_declared, check_angles, check_time, check_torque_sign
from .errors import DiagnosisInputError
from .features import FeatureConfig, StorageContext, trial_features
from .gap import GapResult, make_normaliser, set_gap
from .inputs import load_trials
from .parallel import Runner, worker_cache
from .simulate import NUMERICAL_RETRY_FACTOR, nominal_setup, simulate_like

VERDICT_EFFECT = "effect"
VERDICT_NONE = "no significant gap"
VERDICT_UNEXPLAINED = "unexplained"
VERDICT_PARTLY = "partly explained"
#: the only gap was a convention of the files (conventions.py), found and corrected
VERDICT_CONVENTION = "convention mismatch"
#: a residual whose coherent (FRF) part differs between perturbation levels of the same
#: joint by more than this (mean z^2 excess of the level difference) is amplitude-dependent
AMPLITUDE_GAP = 1.0


@dataclass(frozen=True)
class DiagnosisConfig:
    """Options of a diagnosis (defaults documented in docs/diagnosis.md).

    Attributes
    ----------
    features : FeatureConfig
    calibration_s : float [s]
        Length of the calibration segment simulated per calibration trial.
    held_out_s : float [s]
        Longest held-out segment simulated per held-out trial.
    time_split_fraction : float
        When a joint has one trial only: the first fraction is calibration, the rest
        held out.
    calibration_trials_per_joint : int
    significance_gap : float
        Nominal gap (all trials) above which a gap is significant; calibrated on
        nominal-vs-nominal sets (docs/diagnosis.md).
    explained_fraction : float
        Held-out gap reduction an effect needs to be reported at all ("partly
        explained").
    confident_fraction : float
        Held-out gap reduction an effect needs to be named as *the* explanation; between
        the two the verdict is "partly explained: EFFECT closes N %, the rest lies in ...".
    pair_gain : float
        A pair is preferred to the best single effect when its calibration gap is below
        this fraction of the single's.
    grid_points, refine_iterations : int
        Bounded 1-D search: coarse (log-)grid, then Brent refinement in the best bracket.
    effects : tuple of str
        Catalogue effects tried.
    """

    features: FeatureConfig = FeatureConfig()
    calibration_s: float = 12.0
    held_out_s: float = 16.0
    time_split_fraction: float = 0.6
    calibration_trials_per_joint: int = 1
    significance_gap: float = 0.25
    explained_fraction: float = 0.5
    confident_fraction: float = 0.9
    pair_gain: float = 0.5
    grid_points: int = 5
    refine_iterations: int = 6
    effects: tuple = cat.effects_for("exoskeleton")


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


def _effects_key(effects: dict) -> str:
    return json.dumps(effects, sort_keys=True)


class Evaluator:
    """Simulates units with candidate models and computes their gap; caches every run.

    The normalisation of each unit is fixed from the nominal model (gap.py).
    """

    def __init__(self, setup, units, cfg: DiagnosisConfig, plant=None,
                 cache: dict | None = None, setup_for=None, norms: dict | None = None,
                 rk4_step: float | None = None):
        self.setup, self.units, self.cfg, self.plant = setup, units, cfg, plant
        self.rk4_step = rk4_step
        # the set-up a candidate is simulated with (the arm behind a candidate cuff)
        self.setup_for = setup_for or (lambda effects: setup)
        self.n_dof = units[0].trial.n_dof
        self._sims: dict = {} if cache is None else cache
        self.n_simulations = 0
        # how each measured trial was stored: simulations are stored alike (storage.py)
        self.contexts = {u.trial.name: storage_context(u.trial) for u in units}
        self.measured = {u.key: trial_features(u.trial, cfg.features, start=u.start,
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
                f"the nominal model diverges on {bad}, also with the plant's RK4 step "
                f"divided by {NUMERICAL_RETRY_FACTOR} (so not a numerical failure): the "
                f"declared set-up cannot reproduce these trials")
        self.norms = {u.key: make_normaliser(self.measured[u.key], nominal[u.key],
                                             cfg.features) for u in units}

    def simulation(self, unit: Unit, effects: dict):
        """The model's run of the unit's experiment, at least ``unit.stop`` samples long.

        Runs are causal, so one run serves every unit that is a prefix of it; the cache
        keeps the longest run per (trial, model) and may be shared between evaluators.
        """
        key = (unit.trial.name, _effects_key(effects))
        have = self._sims.get(key)
        # a model that diverged once is not run again (it is unstable)
        if have is None or (have[1] is not None and have[0] < unit.stop):
            sim = simulate_like(unit.trial, self.setup_for(effects), effects, unit.stop,
                                plant=self.plant, rk4_step=self.rk4_step)
            self._sims[key] = (unit.stop, sim)
            self.n_simulations += 1
        return self._sims[key][1]

    def features(self, unit: Unit, effects: dict):
        sim = self.simulation(unit, effects)
        if sim is None:
            return None
        context = self.contexts[unit.trial.name]
        return trial_features(context.store(sim), self.cfg.features, start=unit.start,
                              stop=unit.stop, context=context)

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


# ----------------------------------------------------------------------------- fitting


def _merge(*dicts) -> dict:
    out = {}
    for d in dicts:
        out.update(d)
    return out


@dataclass
class EffectFit:
    """Fitted parameters of one effect (or pair) on the calibration units."""

    effects: tuple
    params: dict            # effect -> primary params
    calibration_gap: float
    n_evaluations: int
    held_out_gap: float = math.nan
    objective: float = math.nan

    def simulation_effects(self, n_dof) -> dict:
        return {e: cat.expand_effect(e, self.params[e], n_dof) for e in self.effects}

    @property
    def at_search_bound(self) -> list:
        """Scored parameters fitted on a search bound (catalogue.at_search_bound), as
        ``"effect: param = value at upper search bound"``; such a fit is never named."""
        return [f"{e}: {flag}" for e in self.effects
                for flag in cat.at_search_bound(e, self.params[e])]

    @property
    def nameable(self) -> bool:
        return math.isfinite(self.calibration_gap) and not self.at_search_bound


def fit_effect(name: str, ev: Evaluator, base: dict | None = None,
               around: dict | None = None) -> tuple[dict, float, int]:
    """Fit effect ``name`` (added to the ``base`` effects) on the calibration units.

    Returns ``(primary params, calibration gap, simulations run, calibration excess)``. ``around`` narrows a
    scalar search to a factor 3 about a previous estimate (used for pairs).
    """
    effect = cat.get_effect(name)
    base = base or {}
    n0 = ev.n_simulations
    full = lambda p: _merge(base, {name: effect.expand(p, ev.n_dof)})  # noqa: E731
    if effect.fit == "grid":
        params = _grid_estimate(ev)
    elif effect.fit == "noise":
        params = _noise_estimate(ev, base)
    elif effect.fit == "integer":
        p = effect.parameters[0]
        values = range(int(p.bounds[0]), int(p.bounds[1]) + 1)
        gaps = {v: ev.objective(full({p.name: v})) for v in values}
        params = {p.name: min(gaps, key=gaps.get)}
    else:
        params = _scalar_search(effect, ev, full, around)
    return params, ev.gap_value(full(params)), ev.n_simulations - n0, ev.objective(full(params))


def _scalar_search(effect, ev, full, around):
    p = effect.parameters[0]
    cfg = ev.cfg
    to_x = (lambda v: math.log(v)) if p.log else (lambda v: v)
    from_x = (lambda x: math.exp(x)) if p.log else (lambda x: x)
    lo, hi = to_x(p.bounds[0]), to_x(p.bounds[1])
    if around is not None:
        c = to_x(around[p.name])
        half = math.log(3.0) if p.log else 0.25 * (hi - lo)
        lo, hi = max(lo, c - half), min(hi, c + half)
    cache: dict = {}

    def objective(x):
        x = float(np.clip(x, lo, hi))
        if x not in cache:
            cache[x] = ev.objective(full({p.name: from_x(x)}))
        return cache[x]

    grid = np.linspace(lo, hi, cfg.grid_points)
    values = [objective(x) for x in grid]
    i = int(np.argmin(values))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    if np.isfinite(values[i]) and cfg.refine_iterations > 0:
        optimize.minimize_scalar(objective, bounds=(a, b), method="bounded",
                                 options={"maxiter": cfg.refine_iterations,
                                          "xatol": 0.01 * (b - a)})
    best = min(cache, key=cache.get)
    return {p.name: float(from_x(best))}


def _grid_estimate(ev: Evaluator) -> dict:
    """Quantisation steps read from the grid the measured samples sit on (tolerant of
    the storage rounding, storage.find_grid); 0 where no grid is resolvable."""
    enc, tor = [], []
    for u in ev.units:
        t, context = u.trial, ev.contexts[u.trial.name]
        for j in range(t.n_dof):
            enc.append(context.grid("theta", j, t.theta[u.start:u.stop, j]).step)
            tor.append(context.grid("tau_h", j, t.tau_h[u.start:u.stop, j]).step)
    enc_deg = float(np.degrees(np.median(enc)))
    return {"encoder_resolution_deg": enc_deg, "torque_resolution_nm": float(np.median(tor))}


NOISE_PROBE = {"theta_noise_std_rad": 2e-5, "tau_noise_std_nm": 0.01}
NOISE_SIGNALS = ("theta", "tau_h")


def _band_powers(trial, start, stop, cfg: FeatureConfig) -> np.ndarray:
    """Mean PSD of theta and tau_h, per joint, in the noise bands above 60 Hz."""
    out = []
    for s in NOISE_SIGNALS:
        f, p = sps.welch(trial.signal(s)[start:stop], fs=trial.fs, nperseg=cfg.nperseg,
                         noverlap=cfg.noverlap, axis=0)
        for band in cfg.noise_bands:
            if band[0] >= 60.0:
                out.append(p[(f >= band[0]) & (f <= band[1])].mean(axis=0))
    return np.concatenate(out)


def _noise_estimate(ev: Evaluator, base: dict) -> dict:
    """Sensor noise read from the high-frequency power of theta and tau_h.

    In a linear closed loop each band power is P0 + a sigma_theta^2 + b sigma_tau^2: two
    probe simulations (one noise source each, at NOISE_PROBE) give a and b, and the
    variances follow by non-negative least squares on the measured powers (relative
    errors), pooled over the calibration units.
    """
    n = ev.n_dof
    rows, rhs = [], []
    probes = [{"theta_noise_std_rad": NOISE_PROBE["theta_noise_std_rad"], "tau_noise_std_nm": 0.0},
              {"theta_noise_std_rad": 0.0, "tau_noise_std_nm": NOISE_PROBE["tau_noise_std_nm"]}]
    for u in ev.units:
        sims = [ev.simulation(u, base)] + [
            ev.simulation(u, _merge(base, {"sensor_noise": cat.expand_effect(
                "sensor_noise", p, n)})) for p in probes]
        if any(s is None for s in sims):
            continue
        p0, pa, pb = (_band_powers(s, u.start, u.stop, ev.cfg.features) for s in sims)
        pm = _band_powers(u.trial, u.start, u.stop, ev.cfg.features)
        a = (pa - p0) / NOISE_PROBE["theta_noise_std_rad"] ** 2
        b = (pb - p0) / NOISE_PROBE["tau_noise_std_nm"] ** 2
        w = 1.0 / np.maximum(pm, np.finfo(float).tiny)
        rows.append(np.column_stack([a * w, b * w]))
        rhs.append((pm - p0) * w)
    if not rows:
        return {"theta_noise_std_rad": 0.0, "tau_noise_std_nm": 0.0}
    var, _ = optimize.nnls(np.vstack(rows), np.concatenate(rhs))
    return {"theta_noise_std_rad": float(math.sqrt(var[0])),
            "tau_noise_std_nm": float(math.sqrt(var[1]))}


# ----------------------------------------------------------------------------- report


@dataclass
class DiagnosisReport:
    """Result of :func:`diagnose`; ``to_dict()`` is the report's JSON (docs/diagnosis.md)."""

    verdict: str
    named: list
    summary: str
    amplitude: dict
    conventions: list
    numerics: list
    timing: dict
    fitted: dict
    ranking: list
    pairs: list
    gap: dict
    where: dict
    arm: dict
    split: dict
    config: dict
    n_simulations: int
    elapsed_s: float
    trials: list
    out_dir: object = None
    extras: dict = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict:
        return {"format": "arm-impedance-diagnosis/1", "verdict": self.verdict,
                "summary": self.summary, "named_effects": self.named,
                "fitted_parameters": self.fitted, "amplitude_dependence": self.amplitude,
                "conventions": self.conventions, "numerical_retries": self.numerics,
                "timing": self.timing,
                "ranking": self.ranking, "pairs": self.pairs, "gap": self.gap,
                "where": self.where, "arm": self.arm, "split": self.split,
                "trials": self.trials, "n_simulations": self.n_simulations,
                "elapsed_s": self.elapsed_s, "config": self.config}


def where_breakdown(result: GapResult) -> dict:
    """The gap broken down for the report (keys documented in docs/diagnosis.md)."""
    def rows(*keys):
        return [{**dict(zip(keys, k)), "gap": v}
                for k, v in sorted(result.breakdown(*keys).items(), key=lambda kv: -kv[1])]
    bands = rows("kind", "signal", "joint", "band")
    return {"total": result.value, "coherent_share": result.coherent_share(),
            "by_signal": rows("signal"), "by_joint": rows("joint"), "by_kind": rows("kind"),
            "by_level": rows("level"), "by_signal_kind": rows("signal", "kind"),
            "by_band": bands, "top_bands": bands[:5]}


def _jsonable(params: dict) -> dict:
    return {k: (float(v) if not isinstance(v, int) else v) for k, v in params.items()}


def diagnose(source, out_dir=None, *, config: DiagnosisConfig = DiagnosisConfig(),
             plant=None, progress: bool = True, workers: int | None = None,
             scheduler=None, rk4_step: float | None = None) -> DiagnosisReport:
    """Diagnose the sim-to-real gap of a folder of measured trials.

    Parameters
    ----------
    source : path or list of paths
        Folder of trials (``NAME.csv`` + ``NAME.json``) or a list of ``NAME.csv``.
        Truth files (``NAME.truth.json``) and ``meta["simulation"]`` are never read.
    out_dir : path, optional
        Where to write the report (``report.md``, ``report.json``, PNG plots).
    config : DiagnosisConfig, keyword-only
    plant : orchestrator.Plant or path, optional
        The plant FMU (default: the reference plant).
    progress : bool
        Show tqdm progress bars.
    workers : int, optional
        Local processes that run the simulations (default: one per core; 1: this
        process). The result does not depend on it.
    scheduler : str or distributed.Client, optional
        Dask scheduler address (e.g. ``tcp://HOST:8786``): run on that cluster instead.
    rk4_step : float [s], optional
        The plant's internal RK4 step; it must divide the trials' sample period (refused
        up front with both values). Default: the plant's, or the step nearest it that
        divides the period (any sample rate).

    Returns
    -------
    DiagnosisReport

    Raises
    ------
    DiagnosisInputError
        No trial, disagreeing declared set-ups, trials too short; the message names the file.
    """
    import time
    t0 = time.perf_counter()
    trials = load_trials(source)
    for t in trials:
        if t.n_samples < 4 * config.features.nperseg:
            raise DiagnosisInputError(f"trial {t.name!r}: {t.n_samples} samples, fewer than "
                                      f"4 spectral segments of {config.features.nperseg}")
    unknown = [e for e in config.effects if e not in cat.CATALOGUE]
    if unknown:
        raise DiagnosisInputError(f"config.effects: unknown effect(s) {unknown}")
    if rk4_step is not None:
        from orchestrator.trial import check_rk4_step
        try:
            check_rk4_step(rk4_step, 1.0 / trials[0].fs)
        except ValueError as exc:
            raise DiagnosisInputError(f"{trials[0].name}: fs = {trials[0].fs:g} Hz: "
                                      f"{exc}") from None
    trials, findings = apply_declared(trials)
    trials, found = check_angles(trials)
    findings += found + check_time(trials)
    arm = estimate_arm(trials)
    trials, arm, found = check_torque_sign(trials, arm, estimate_arm)
    findings += found
    cal, held, rule = split_units(trials, config)
    setup = nominal_setup(trials[0].meta, arm)
    setup_for = _setup_factory(trials[0].meta, arm, setup)
    full_units = [Unit(t, 0, t.n_samples, "all") for t in trials]
    n_dof = trials[0].n_dof
    index = {t.name: i for i, t in enumerate(trials)}
    plant_ref = getattr(plant, "path", plant)
    state = _State(token=uuid.uuid4().hex, trials=trials, meta=trials[0].meta, arm=arm,
                   setup=setup, config=config, plant=None if plant_ref is None else str(plant_ref),
                   cal=[(index[u.trial.name], u.start, u.stop, u.role) for u in cal],
                   held=[(index[u.trial.name], u.start, u.stop, u.role) for u in held],
                   rk4_step=rk4_step)
    cache: dict = {}
    with Runner(state, workers=workers, scheduler=scheduler, progress=progress) as runner:
        # nominal runs of every trial (the calibration and held-out units are prefixes)
        sims = runner.map(_task_simulate, [(i, {}) for i in range(len(trials))],
                          desc="nominal runs")
        _prefill(cache, trials, {}, sims)
        numerics = [{"trial": t.name, **sim.meta["simulation"]["numerical_retry"]}
                    for t, sim in zip(trials, sims)
                    if sim is not None and "numerical_retry" in sim.meta["simulation"]]
        ev_all = Evaluator(setup, full_units, config, plant_ref, cache, setup_for,
                           rk4_step=rk4_step)
        nominal_all = ev_all.gap({})
        ev_cal = Evaluator(setup, cal, config, plant_ref, cache, setup_for, rk4_step=rk4_step)
        ev_held = Evaluator(setup, held, config, plant_ref, cache, setup_for,
                            rk4_step=rk4_step)
        g0_cal, g0_held = ev_cal.gap_value({}), ev_held.gap_value({})
        norms = (ev_cal.norms, ev_held.norms)
        # every effect alone, fitted on the calibration units, with its held-out gap;
        # the costliest (scalar searches) first so that the workers stay busy
        order = sorted(config.effects, key=lambda n: cat.get_effect(n).fit != "scalar")
        singles = runner.map(_task_fit_single, [(n,) + norms for n in order],
                             desc="effects")
        n_worker_sims = sum(f.n_evaluations for f in singles)
        singles.sort(key=lambda f: (f.calibration_gap, f.objective))
        significant = nominal_all.value > config.significance_gap
        pairs = []
        best = next((f for f in singles if f.nameable), None)
        if significant and best is not None and _residual_needs_pair(best, g0_cal, config):
            partners = [f.effects[0] for f in singles
                        if f is not best and math.isfinite(f.calibration_gap)]
            seconds = runner.map(_task_fit_second, [(best, o) + norms for o in partners],
                                 desc="pairs")
            n_worker_sims += sum(f.n_evaluations for f in seconds)
            seconds.sort(key=lambda f: (f.calibration_gap, f.objective))
            if seconds:
                refined = runner.map(_task_refine_pair, [(seconds[0],) + norms],
                                     desc="pair refit")[0]
                n_worker_sims += refined.n_evaluations - seconds[0].n_evaluations
                pairs = [refined] + seconds[1:]
            pairs.sort(key=lambda f: (f.calibration_gap, f.objective))
        verdict, named, chosen = _verdict(significant, singles, pairs, g0_held, config)
        after = None
        if chosen is not None:
            effects = chosen.simulation_effects(n_dof)
            runs = runner.map(_task_simulate, [(i, effects) for i in range(len(trials))],
                              desc="named model runs")
            _prefill(cache, trials, effects, runs)
            after = ev_all.gap(effects)
        timings = list(runner.timings)
    n_parent_sims = len(trials) * (2 if chosen is not None else 1)
    residual = after if after is not None else nominal_all
    amplitude = amplitude_dependence(residual, trials)
    if amplitude["amplitude_dependent"] and verdict == VERDICT_EFFECT:
        verdict = VERDICT_PARTLY  # no linear catalogue effect explains that
    summary = _verdict_text(verdict, named, chosen, g0_held, residual, amplitude)
    if numerics:
        summary += (" Numerical: the plant's RK4 step failed on "
                    + ", ".join(f"{n['trial']} at {n['failed_rk4_step']:.3g} s" for n in numerics)
                    + f" and was run at {numerics[0]['rk4_step']:.3g} s (a numerical failure, "
                    "not a model mismatch).")
    mismatches = [f for f in findings if not f.name.startswith("declared")]
    if mismatches:
        if verdict == VERDICT_NONE:
            verdict = VERDICT_CONVENTION
        summary = ("set-up/convention mismatch found and corrected: "
                   + "; ".join(f.text() for f in mismatches) + ". After correction: "
                   + summary)
    ranking = [_ranking_row(f, g0_cal, g0_held) for f in singles]
    pair_rows = [_ranking_row(f, g0_cal, g0_held) for f in pairs]
    report = DiagnosisReport(
        verdict=verdict, named=named, summary=summary, amplitude=amplitude,
        conventions=[f.to_dict() for f in findings], numerics=numerics,
        timing={"workers": workers, "scheduler": None if scheduler is None else str(scheduler),
                "phases": timings},
        fitted={} if chosen is None else chosen.params,
        ranking=ranking, pairs=pair_rows,
        gap={"nominal_all": nominal_all.value, "nominal_calibration": g0_cal,
             "nominal_held_out": g0_held, "significance_threshold": config.significance_gap,
             "significant": bool(significant),
             "named_held_out": None if chosen is None else chosen.held_out_gap,
             "named_held_out_reduction": None if chosen is None else
             _reduction(g0_held, chosen.held_out_gap),
             "named_all": None if after is None else after.value},
        where={"conventions": [f.text() for f in findings],
               "storage": {t.name: storage_context(t).describe() for t in trials},
               "grid": _grids(trials),
               "nominal": where_breakdown(nominal_all),
               "named": None if after is None else where_breakdown(after)},
        arm={**arm.to_dict(), "behind_named_compliance": None if chosen is None else
             _behind_dict(arm, chosen.simulation_effects(trials[0].n_dof), trials[0].meta)},
        split={"rule": rule,
               "calibration": [{"trial": u.trial.name, "start": u.start, "stop": u.stop}
                               for u in cal],
               "held_out": [{"trial": u.trial.name, "start": u.start, "stop": u.stop}
                            for u in held]},
        config=_config_dict(config),
        n_simulations=n_parent_sims + n_worker_sims,
        elapsed_s=time.perf_counter() - t0, trials=[t.name for t in trials],
        extras={"nominal_all": nominal_all, "after_all": after, "ev_all": ev_all,
                "chosen": chosen, "trials": trials})
    if out_dir is not None:
        from pathlib import Path

        from .report import write_report
        report.out_dir = Path(out_dir)
        write_report(report, out_dir)
    return report


def _prefill(cache: dict, trials, effects: dict, sims) -> None:
    """Put full-length runs made by the workers into an evaluator cache."""
    key = _effects_key(effects)
    for t, sim in zip(trials, sims):
        cache[(t.name, key)] = (t.n_samples, sim)


@dataclass
class _State:
    """What every parallel task of one diagnosis reads (sent to each worker once)."""

    token: str
    trials: list
    meta: dict
    arm: object
    setup: object
    config: DiagnosisConfig
    plant: str | None
    cal: list     # (trial index, start, stop, role)
    held: list
    rk4_step: float | None = None


def _worker_evaluators(state: _State, norms_cal: dict, norms_held: dict):
    """The calibration and held-out evaluators of this worker (one simulation cache),
    with the normalisation the parent fixed from the nominal model."""
    def build():
        setup_for = _setup_factory(state.meta, state.arm, state.setup)
        cache: dict = {}
        units = [[Unit(state.trials[i], a, b, role) for i, a, b, role in spec]
                 for spec in (state.cal, state.held)]
        return tuple(Evaluator(state.setup, u, state.config, state.plant, cache, setup_for,
                               norms=n, rk4_step=state.rk4_step)
                     for u, n in zip(units, (norms_cal, norms_held)))
    return worker_cache(state, "evaluators", build)


def _task_simulate(state: _State, trial_index: int, effects: dict):
    """Full-length run of one trial with ``effects`` (None when it diverges)."""
    t = state.trials[trial_index]
    setup_for = worker_cache(state, "setup_for",
                             lambda: _setup_factory(state.meta, state.arm, state.setup))
    return simulate_like(t, setup_for(effects), effects, t.n_samples, plant=state.plant,
                         rk4_step=state.rk4_step)


def _with_held_out(fit: EffectFit, ev_held: Evaluator, n0: int, n_dof: int) -> EffectFit:
    fit.held_out_gap = ev_held.gap_value(fit.simulation_effects(n_dof))
    fit.n_evaluations += ev_held.n_simulations - n0
    return fit


def _task_fit_single(state: _State, name: str, norms_cal: dict, norms_held: dict):
    """Fit one effect alone on the calibration units; its held-out gap."""
    ev_cal, ev_held = _worker_evaluators(state, norms_cal, norms_held)
    n_held = ev_held.n_simulations
    params, gcal, nev, obj = fit_effect(name, ev_cal)
    fit = EffectFit((name,), {name: _jsonable(params)}, gcal, nev, objective=obj)
    return _with_held_out(fit, ev_held, n_held, ev_cal.n_dof)


def _task_fit_second(state: _State, best: EffectFit, other: str, norms_cal: dict,
                     norms_held: dict):
    ev_cal, ev_held = _worker_evaluators(state, norms_cal, norms_held)
    n_held = ev_held.n_simulations
    fit = _fit_second(best, other, ev_cal, ev_cal.n_dof)
    return _with_held_out(fit, ev_held, n_held, ev_cal.n_dof)


def _task_refine_pair(state: _State, fit: EffectFit, norms_cal: dict, norms_held: dict):
    ev_cal, ev_held = _worker_evaluators(state, norms_cal, norms_held)
    n_held = ev_held.n_simulations
    refined = _refine_pair(fit, ev_cal, ev_cal.n_dof)
    if refined is fit:
        return fit
    return _with_held_out(refined, ev_held, n_held, ev_cal.n_dof)


#: effects that sit between the robot's sensors and the arm: a candidate is simulated
#: with the arm estimate seen through it removed (arm.py)
COMPLIANCES = ("transmission_compliance", "interface_compliance")


def _arm_for(arm, effects: dict, meta: dict):
    """The arm a candidate model simulates: the estimate with the candidate's
    transmission and/or cuff removed (motor side first), else the estimate itself.
    None when the removal fails."""
    out = arm
    trans = effects.get("transmission_compliance")
    if trans and out is not None:
        out = arm_behind_transmission(out, trans["k_t"], trans["c_t"], link_inertia(meta))
    cuff = effects.get("interface_compliance")
    if cuff and out is not None:
        out = arm_behind_cuff(out, cuff["k_s"], cuff["c_s"])
    return out


def _behind_dict(arm, effects: dict, meta: dict):
    if not any(e in effects for e in COMPLIANCES):
        return None
    behind = _arm_for(arm, effects, meta)
    return None if behind is None else behind.to_dict()


def _setup_factory(meta: dict, arm, nominal):
    """effects -> Setup: the nominal one, or one with the arm behind a candidate
    compliance; cached per compliance."""
    cache: dict = {}

    def setup_for(effects: dict):
        if not any(e in effects for e in COMPLIANCES):
            return nominal
        key = _effects_key({e: effects.get(e) for e in COMPLIANCES})
        if key not in cache:
            behind = _arm_for(arm, effects, meta)
            cache[key] = nominal if behind is None else nominal_setup(meta, behind)
        return cache[key]
    return setup_for


def _config_dict(cfg: DiagnosisConfig) -> dict:
    out = {k: v for k, v in cfg.__dict__.items() if k != "features"}
    out["effects"] = list(cfg.effects)
    out["features"] = cfg.features.to_dict()
    return out


def _reduction(before: float, after: float) -> float:
    if not np.isfinite(after):
        return -math.inf
    if before <= 0:
        return 0.0
    return float((before - after) / before)


def _ranking_row(fit: EffectFit, g0_cal: float, g0_held: float) -> dict:
    return {"effects": list(fit.effects), "params": fit.params,
            "calibration_gap": fit.calibration_gap,
            "calibration_reduction": _reduction(g0_cal, fit.calibration_gap),
            "held_out_gap": fit.held_out_gap,
            "held_out_reduction": _reduction(g0_held, fit.held_out_gap),
            "n_simulations": fit.n_evaluations,
            "at_search_bound": fit.at_search_bound}


def _residual_needs_pair(best: EffectFit, g0_cal: float, cfg: DiagnosisConfig) -> bool:
    """A pair is tried when the best single leaves a calibration gap that is still
    significant (above the nominal-vs-nominal threshold): whatever is left is more than
    noise, however much the single closed."""
    return best.calibration_gap > cfg.significance_gap


def _fit_second(best: EffectFit, other: str, ev_cal: Evaluator,
                n_dof: int) -> EffectFit:
    """Forward selection: fit effect ``other`` on top of the best single (its full
    bounds: what it fitted alone, under the first effect's gap, says little)."""
    ea, eb = best.effects[0], other
    pa = best.params[ea]
    n0 = ev_cal.n_simulations
    pb, gap, _, obj = fit_effect(eb, ev_cal, base={ea: cat.expand_effect(ea, pa, n_dof)})
    return EffectFit((ea, eb), {ea: dict(pa), eb: _jsonable(pb)}, gap,
                     ev_cal.n_simulations - n0, objective=obj)


def _refine_pair(fit: EffectFit, ev_cal: Evaluator, n_dof: int) -> EffectFit:
    """One more coordinate step on the best pair: the first effect refitted (search
    narrowed to a factor 3) with the second in place."""
    ea, eb = fit.effects
    pb = fit.params[eb]
    n0 = ev_cal.n_simulations
    pa, gap, _, obj = fit_effect(ea, ev_cal, base={eb: cat.expand_effect(eb, pb, n_dof)},
                                 around=fit.params[ea])
    if not gap < fit.calibration_gap:
        return fit
    return EffectFit((ea, eb), {ea: _jsonable(pa), eb: dict(pb)}, gap,
                     fit.n_evaluations + ev_cal.n_simulations - n0, objective=obj)


def _verdict(significant, singles, pairs, g0_held, cfg):
    """(verdict, named effects, chosen fit) from the ranked fits.

    Only fits with no parameter on a search bound are candidates. The best such single is
    replaced by a pair only when the pair's second effect earns its place on both the
    calibration gap and the held-out gap (:func:`_pair_earns_second`).
    """
    if not significant:
        return VERDICT_NONE, [], None
    best = next((f for f in singles if f.nameable), None)
    if best is None:
        return VERDICT_UNEXPLAINED, [], None
    chosen = next((p for p in pairs if p.nameable and p.effects[0] == best.effects[0]
                   and _pair_earns_second(p, best, cfg)), best)
    reduction = _reduction(g0_held, chosen.held_out_gap)
    if reduction >= cfg.confident_fraction:
        return VERDICT_EFFECT, list(chosen.effects), chosen
    if reduction >= cfg.explained_fraction:
        return VERDICT_PARTLY, list(chosen.effects), chosen
    return VERDICT_UNEXPLAINED, [], None


def amplitude_dependence(result: GapResult, trials) -> dict:
    """Does the residual change with the perturbation amplitude?

    For every two trials of the same perturbed joint at different perturbation levels,
    the coherent (FRF) features of the residual are compared: a model error that is linear
    leaves the same difference d = measured - model at every amplitude (FRFs do not
    depend on it), so ``mean(((d_a - d_b)^2 - 2 v_a - 2 v_b) / (sigma_a^2 + sigma_b^2))``
    is ~0 (v the statistical variances); a nonlinearity the model lacks makes it large. Returns ``{"statistic", "threshold", "amplitude_dependent",
    "pairs": [{trials, levels, statistic}]}`` (statistic None without two levels).
    """
    info = {t.name: (t.perturbed_dof, (t.meta.get("perturbation") or {}).get("level"))
            for t in trials}
    by_trial: dict = {}
    for pos, lab in enumerate(result.labels):
        if lab[2] == "frf":
            by_trial.setdefault(lab[0], []).append(pos)
    pairs = []
    names = sorted(by_trial)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            (ka, la), (kb, lb) = info[a], info[b]
            if ka != kb or la is None or lb is None or la == lb:
                continue
            pa, pb = by_trial[a], by_trial[b]
            if len(pa) != len(pb):
                continue
            sa, sb = result.sigma[pa], result.sigma[pb]
            use = np.isfinite(sa) & np.isfinite(sb)
            if not use.any():
                continue
            da, db = result.z[pa][use] * sa[use], result.z[pb][use] * sb[use]
            va = result.expected[pa][use] * sa[use] ** 2 / 2.0  # e = 2 v / sigma^2
            vb = result.expected[pb][use] * sb[use] ** 2 / 2.0
            diff = np.angle(np.exp(1j * (da - db)))  # phases: wrapped; ln|H|: small
            stat = float(np.mean((diff ** 2 - 2 * va - 2 * vb)
                                 / (sa[use] ** 2 + sb[use] ** 2)))
            pairs.append({"trials": [a, b], "levels": [la, lb], "statistic": stat})
    worst = max((p["statistic"] for p in pairs), default=None)
    return {"statistic": worst, "threshold": AMPLITUDE_GAP,
            "amplitude_dependent": bool(worst is not None and worst > AMPLITUDE_GAP),
            "pairs": pairs}


def rest_where(result: GapResult, n: int = 3) -> list:
    """The feature groups that carry most of a residual, as readable strings."""
    rows = where_breakdown(result)["top_bands"][:n]
    return [f"{r['signal']}[{r['joint']}] {r['kind']} {r['band']} (gap {r['gap']:.3g})"
            for r in rows if r["gap"] > 0]


def _grids(trials) -> dict:
    """The quantisation grid found in theta and tau_h of every trial, with its
    uncertainty (step 0: none resolvable at the storage precision)."""
    out = {}
    for t in trials:
        context = storage_context(t)
        out[t.name] = {s: [context.grid(s, j, t.signal(s)[:, j]).to_dict()
                           for j in range(t.n_dof)] for s in ("theta", "tau_h")}
    return out


def _verdict_text(verdict, named, chosen, g0_held, residual, amplitude) -> str:
    """One sentence: the verdict, what the named effect closes, where the rest lies."""
    amp = (" The residual is amplitude-dependent (its FRF part differs between "
           "perturbation levels): no linear catalogue effect explains that."
           if amplitude["amplitude_dependent"] else "")
    if verdict == VERDICT_NONE:
        return "no significant gap: the nominal model reproduces the trials within noise."
    if chosen is None:
        return ("unexplained: no catalogue effect closes half of the held-out gap; the gap "
                "lies in " + "; ".join(rest_where(residual)) + "." + amp)
    share = 100 * _reduction(g0_held, chosen.held_out_gap)
    text = f"{' + '.join(named)} closes {share:.0f} % of the held-out gap"
    if verdict == VERDICT_PARTLY:
        return ("partly explained: " + text + "; the rest lies in "
                + "; ".join(rest_where(residual)) + "." + amp)
    return f"{verdict}: {text}." + amp


def _pair_earns_second(pair: EffectFit, single: EffectFit, cfg: DiagnosisConfig) -> bool:
    """True when adding the pair's second effect shrinks the gap significantly: below
    ``pair_gain`` times the single's gap on the calibration units AND on the held-out
    units, and on the held-out units by more than the significance threshold (what
    nominal-vs-nominal noise can do), with the second effect fitted above its measured
    detectability floor (catalogue.below_detectability). A second effect that only fits
    the calibration units, or at a strength no data set shows, is absorbing noise or model
    error, not measuring an effect."""
    second = pair.effects[-1]
    held_drop = single.held_out_gap - pair.held_out_gap
    return bool(pair.calibration_gap < cfg.pair_gain * single.calibration_gap
                and pair.held_out_gap < cfg.pair_gain * single.held_out_gap
                and held_drop > cfg.significance_gap
                and not cat.below_detectability(second, pair.params[second]))
