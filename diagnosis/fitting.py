"""Fitting catalogue effects on the calibration units (bounded searches by re-simulation).

Each effect is fitted in its one-parameter family (catalogue.py): a bounded 1-D search
(coarse grid, then Brent refinement in the best bracket), an integer scan, the sample
grid read from the data, or the sensor noise read from the noise floors. A search whose
best value lies on a bound of its range widens it, inside the parameter's physical
limits (catalogue.Parameter.widened, at most catalogue.MAX_WIDENINGS times), and the fit
records what it searched (:class:`Search`). Pairs are fitted
by forward selection: the second effect on top of the best single, then one coordinate
step of the first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize
from scipy import signal as sps

from . import catalogue as cat
from .evaluation import Evaluator
from .features import FeatureConfig


def merge(*dicts) -> dict:
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
    #: effect -> {param: [low, high]} 95 % intervals, where the fit gives them
    intervals: dict | None = None
    #: the limb re-estimated with the effect (an experiment whose fit re-estimates it)
    model: object = None
    #: further reasons never to name this fit, as free text (e.g. from another fitter)
    bound_flags: list = field(default_factory=list)
    #: further reasons as ``(effect, param, note)``, e.g. ``("stretch_reflex", "gain",
    #: "< 0 (unphysical)")``: formatted with the value of ``params`` they are shown with
    value_flags: list = field(default_factory=list)
    #: effect -> {param: [low, high]}: the range searched where it was widened beyond the
    #: declared one (bound flags are read against it)
    searched: dict = field(default_factory=dict)
    #: the widenings made, ``[effect, param, side, [low, high] before, [low, high] after]``
    widenings: list = field(default_factory=list)

    def simulation_effects(self, n_dof) -> dict:
        return {e: cat.expand_effect(e, self.params[e], n_dof) for e in self.effects}

    def flag_notes(self) -> list:
        """Every reason never to name this fit, structured: ``[effect, param, note]``
        (a parameter on a search bound, a value flag) or ``[None, None, text]`` (free
        text); the values are not in them (:func:`format_flags` adds those)."""
        notes = [[e, k, note] for e in self.effects
                 for k, note in cat.bound_notes(e, self.params[e],
                                                searched=self.searched.get(e))]
        notes += [[e, k, note] for e, k, note in self.value_flags
                  if [e, k, note] not in notes]
        shown = format_flags(notes, self.params)
        notes += [[None, None, f] for f in self.bound_flags
                  if not any(f in g for g in shown)]
        return notes

    @property
    def at_search_bound(self) -> list:
        """Scored parameters fitted on a search bound (catalogue.at_search_bound), as
        ``"effect: param = value at upper search bound"``, and the other flags; such a
        fit is never named. Values as fitted (the report shows them in the file's units:
        :func:`format_flags` on its converted parameters)."""
        return format_flags(self.flag_notes(), self.params)

    def widening_notes(self) -> list:
        """The widenings, as ``"gravity: tilt_deg search widened from [0.2, 30] to
        [0.2, 90] (best fit at its upper bound)"``."""
        return [widening_note(*w) for w in self.widenings]

    @property
    def nameable(self) -> bool:
        return math.isfinite(self.calibration_gap) and not self.at_search_bound


def widening_note(effect, param, side, before, after, scale: float = 1.0) -> str:
    """One widening as text (``scale``: the factor to the file's units); ``after`` equal
    to ``before``: every model beyond the bound diverged and the range stayed."""
    fmt = lambda b: f"[{b[0] * scale:.4g}, {b[1] * scale:.4g}]"  # noqa: E731
    if list(after) == list(before):
        return (f"{effect}: {param} search tried beyond its {side} bound of {fmt(before)} "
                f"(best fit there): every model beyond diverged, the range stays")
    return (f"{effect}: {param} search widened from {fmt(before)} to {fmt(after)} "
            f"(best fit at its {side} bound)")


@dataclass
class Search:
    """What one search of an effect covered: {param: [low, high]} where the range was
    widened, and the widenings ``[param, side, before, after]``."""

    searched: dict = field(default_factory=dict)
    widenings: list = field(default_factory=list)

    def record(self, name: str, fit: "EffectFit") -> "EffectFit":
        """Put this search's ranges and widenings of effect ``name`` into ``fit``."""
        if self.searched:
            fit.searched = {**fit.searched, name: dict(self.searched)}
        fit.widenings = [w for w in fit.widenings if w[0] != name] + \
            [[name] + list(w) for w in self.widenings]
        return fit


def format_flags(notes, params: dict) -> list:
    """``["effect: param = value note", ...]`` from :meth:`EffectFit.flag_notes` with the
    values of ``params`` ({effect: {param: value}}), so that flags and parameters shown
    together are in the same units (a report converts ``params`` to the file's units
    first)."""
    out = []
    for e, k, note in notes:
        if e is None:
            out.append(note)
        else:
            out.append(f"{e}: " + cat.format_flag(k, params[e][k], note))
    return out


def fit_effect(name: str, ev: Evaluator, base: dict | None = None,
               around: dict | None = None, search: Search | None = None
               ) -> tuple[dict, float, int, float]:
    """Fit effect ``name`` (added to the ``base`` effects) on the calibration units.

    Returns ``(primary params, calibration gap, simulations run, calibration excess)``.
    ``around`` narrows a scalar search to a factor 3 about a previous estimate (pairs).
    ``search`` (optional) receives the ranges searched where a best value on a bound
    widened them (scalar and integer searches), and the widenings.
    """
    effect = cat.get_effect(name)
    base = base or {}
    search = search if search is not None else Search()
    n0 = ev.n_simulations
    full = lambda p: merge(base, {name: effect.expand(p, ev.n_dof)})  # noqa: E731
    if effect.fit == "grid":
        params = _grid_estimate(ev)
    elif effect.fit == "noise":
        params = _noise_estimate(ev, base)
    elif effect.fit == "integer":
        params = _integer_search(effect, ev, full, search)
    else:
        params = _scalar_search(effect, ev, full, around, search)
    return params, ev.gap_value(full(params)), ev.n_simulations - n0, ev.objective(full(params))


def _integer_search(effect, ev, full, search: Search) -> dict:
    """Every integer of the range; widened (inside the physical limits) while the best
    is the range's largest or smallest value."""
    p = effect.parameters[0]
    bounds = tuple(search.searched.get(p.name, p.bounds))
    gaps: dict = {}
    for _ in range(cat.MAX_WIDENINGS + 1):
        for v in range(int(math.ceil(bounds[0])), int(math.floor(bounds[1])) + 1):
            if v not in gaps:
                gaps[v] = ev.objective(full({p.name: v}))
        best = min(gaps, key=gaps.get)
        side = "upper" if best >= bounds[1] else "lower" if (
            best <= bounds[0] and not p.physical_low) else None
        wider = None if side is None else p.widened(bounds, side)
        if wider is None:
            break
        wider = (math.ceil(wider[0]), math.floor(wider[1]))
        if wider == bounds:
            break
        search.widenings.append([p.name, side, list(bounds), list(wider)])
        bounds = wider
    if bounds != tuple(p.bounds):
        search.searched[p.name] = list(bounds)
    return {p.name: min(gaps, key=gaps.get)}


def _scalar_search(effect, ev, full, around, search: Search | None = None) -> dict:
    """Coarse grid over the range (search scale), Brent refinement in the best bracket;
    while the best lies on a bound (within catalogue.BOUND_TOLERANCE of the span) that is
    not a physical limit, the range is widened on that side (catalogue
    Parameter.widened) and the new stretch searched the same way, at most
    catalogue.MAX_WIDENINGS times. A narrowed search (``around``) never widens."""
    p = effect.parameters[0]
    search = search if search is not None else Search()
    to_x = (lambda v: math.log(v)) if p.log else (lambda v: v)
    from_x = (lambda x: math.exp(x)) if p.log else (lambda x: x)
    # a search that continues an earlier one (a pair's refit) starts from its range
    start = tuple(search.searched.get(p.name, p.bounds))
    lo, hi = to_x(start[0]), to_x(start[1])
    if around is not None:
        c = to_x(around[p.name])
        half = math.log(3.0) if p.log else 0.25 * (hi - lo)
        lo, hi = max(lo, c - half), min(hi, c + half)
    cache: dict = {}

    def objective(x):
        x = float(x)
        if x not in cache:
            cache[x] = ev.objective(full({p.name: from_x(x)}))
        return cache[x]

    _grid_and_refine(objective, lo, hi, ev.cfg)
    bounds = start
    for _ in range(cat.MAX_WIDENINGS if around is None else 0):
        best = from_x(min(cache, key=cache.get))
        side = p.search_bound_hit(best, bounds=bounds)
        if side is None or p.physical_hit(best, bounds=bounds) is not None:
            break
        wider = p.widened(bounds, side)
        if wider is None or (p.log and not wider[0] > 0):
            break
        # the new stretch, from the grid point next to the old bound inwards
        step = (to_x(bounds[1]) - to_x(bounds[0])) / max(ev.cfg.grid_points - 1, 1)
        if side == "upper":
            _grid_and_refine(objective, to_x(bounds[1]) - step, to_x(wider[1]), ev.cfg)
        else:
            _grid_and_refine(objective, to_x(wider[0]), to_x(bounds[0]) + step, ev.cfg)
        beyond = [v for x, v in cache.items()
                  if (x > to_x(bounds[1]) if side == "upper" else x < to_x(bounds[0]))]
        if not any(math.isfinite(v) for v in beyond):
            # every model beyond the old bound diverged: the range stays (and the fit on
            # its bound stays flagged)
            search.widenings.append([p.name, side, list(bounds), list(bounds)])
            break
        search.widenings.append([p.name, side, list(bounds), list(wider)])
        bounds = wider
    if bounds != (p.bounds[0], p.bounds[1]):
        search.searched[p.name] = list(bounds)
    best = min(cache, key=cache.get)
    return {p.name: float(from_x(best))}


def _grid_and_refine(objective, lo: float, hi: float, cfg) -> None:
    """``cfg.grid_points`` on [lo, hi] (search scale), then bounded Brent refinement in
    the best grid point's bracket; every value lands in ``objective``'s cache."""
    grid = np.linspace(lo, hi, cfg.grid_points)
    values = [objective(x) for x in grid]
    i = int(np.argmin(values))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    if np.isfinite(values[i]) and cfg.refine_iterations > 0:
        optimize.minimize_scalar(lambda x: objective(float(np.clip(x, a, b))),
                                 bounds=(a, b), method="bounded",
                                 options={"maxiter": cfg.refine_iterations,
                                          "xatol": 0.01 * (b - a)})


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
            ev.simulation(u, merge(base, {"sensor_noise": cat.expand_effect(
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


def jsonable(params: dict) -> dict:
    return {k: (float(v) if not isinstance(v, int) else v) for k, v in params.items()}



def _carried(fit: EffectFit, name: str) -> Search:
    """The search record of effect ``name`` in ``fit`` (to carry into a pair)."""
    return Search(dict(fit.searched.get(name, {})),
                  [list(w[1:]) for w in fit.widenings if w[0] == name])


def fit_second(best: EffectFit, other: str, ev_cal: Evaluator,
                n_dof: int) -> EffectFit:
    """Forward selection: fit effect ``other`` on top of the best single (its full
    bounds, widened as a single's: what it fitted alone, under the first effect's gap,
    says little). The first effect keeps the range its single searched."""
    ea, eb = best.effects[0], other
    pa = best.params[ea]
    n0 = ev_cal.n_simulations
    search = Search()
    pb, gap, _, obj = fit_effect(eb, ev_cal, base={ea: cat.expand_effect(ea, pa, n_dof)},
                                 search=search)
    fit = EffectFit((ea, eb), {ea: dict(pa), eb: jsonable(pb)}, gap,
                    ev_cal.n_simulations - n0, objective=obj)
    return search.record(eb, _carried(best, ea).record(ea, fit))


def refine_pair(fit: EffectFit, ev_cal: Evaluator, n_dof: int) -> EffectFit:
    """One more coordinate step on the best pair: the first effect refitted (search
    narrowed to a factor 3) with the second in place."""
    ea, eb = fit.effects
    pb = fit.params[eb]
    n0 = ev_cal.n_simulations
    search = _carried(fit, ea)  # narrowed about the first fit, inside its range
    pa, gap, _, obj = fit_effect(ea, ev_cal, base={eb: cat.expand_effect(eb, pb, n_dof)},
                                 around=fit.params[ea], search=search)
    if not gap < fit.calibration_gap:
        return fit
    out = EffectFit((ea, eb), {ea: jsonable(pa), eb: dict(pb)}, gap,
                    fit.n_evaluations + ev_cal.n_simulations - n0, objective=obj)
    return search.record(ea, _carried(fit, eb).record(eb, out))
