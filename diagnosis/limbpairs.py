"""Pairs of position-servo effects (docs/diagnosis.md, "Pairs on position trials").

The exoskeleton diagnosis tries the named effect's residual against a second effect
(diagnosis.fitting.fit_second / refine_pair); this is the same forward selection for the
variable projection of diagnosis.limbfit:

1. the best single A (the one that would be named: lowest calibration objective, not
   flagged) leaves a calibration gap that is still significant (above
   ``significance_sigma`` standard errors of its Welch estimate plus ``floor_margin``
   times the floor: the test the nominal gap passes before any effect is fitted);
2. every other candidate B that can pair with A (:func:`pairable`) is fitted on top of it:
   A's nonlinear parameters (and discrete choices) fixed at its single fit, B's searched
   on its grid and refined (its discrete choices in turn), K, B, I and both effects'
   gain-like parameters from one least-squares solve; a torque-channel B (a delay, a
   sensor lag) delays A's torque too, so a delay of A is then held at its single value
   *minus* B's lag (:func:`channel_lag_s`): the single measured A's total delay;
3. the :data:`N_REFINED` pairs with the lowest calibration objective get one joint
   Nelder-Mead step on the nonlinear parameters of both; the pairs are ranked again;
4. that pair (the best only, as a single is named only when it ranks first) is named,
   both effects, when its second effect *adds significantly on held-out data*
   (:func:`second_adds`): the held-out gap drops from the single's by more than the same
   significance threshold taken on the single's held-out residual, the calibration gap
   drops too, no parameter of the pair is flagged (a search bound, a negative gain) and
   B's parameters are above its detectability floor.

A time- or state-varying effect in a pair is judged on its own held-out split
(diagnosis.varying_effects.split_masks); the single it is compared with is then solved
on that split too (its nonlinear parameters kept), so the drop compares like with like;
the pair's gaps are reported on the default split's scale as the varying singles' are.
Two effects that both change the limb's stiffness (the varying ones, the amplitude
dependence, the drift) are not paired: together they are one richer stiffness model.
"""

from __future__ import annotations

import math
from contextlib import nullcontext
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from . import catalogue as cat
from . import limb as lm
from . import varying_effects as vary

#: effects that change the limb's own stiffness (never two in one pair)
STIFFNESS_FAMILY = ("stiffness_amplitude", "stiffness_drift") + vary.EFFECTS
SCALED = ("stiffness_amplitude", "stiffness_drift")
#: the parameters a varying effect's columns read (the others are solved or read)
VARYING_SEARCHED = {"stiffness_saturating": ("time_constant_s",),
                    "stiffness_modulated": ("period_s",)}


#: forward pairs (best calibration objective first) refined jointly: a first effect that
#: absorbed part of the second in its single fit (a reflex delay that took a channel
#: delay's 10 ms) is moved back only by the joint step, and the best forward pair is not
#: always the best refined one
N_REFINED = 3


def pairable(a: str, b: str) -> bool:
    """True when ``b`` can be fitted on top of ``a`` (module docstring)."""
    return a != b and not (a in STIFFNESS_FAMILY and b in STIFFNESS_FAMILY)


def searched(lf, name: str) -> list:
    """The catalogue parameters searched for ``name`` in a pair (nonlinear ones)."""
    if vary.is_varying(name):
        keep = VARYING_SEARCHED.get(name, ())
        return [p for p in cat.get_effect(name).parameters if p.name in keep]
    return lf._nonlinear(name)


# ----------------------------------------------------------------------------- columns
def _extra_raw(pr, name, params):
    """Full-rate (N, n) torque column of a limb effect solved by its gain, or None."""
    if name == "stretch_reflex":
        return pr.reflex(params)
    if name == "wobbling_mass":
        p = lm.effect_params(name, params)
        b, a = lm.second_order_lowpass(float(p["frequency_hz"]), float(p["damping"]),
                                       pr.fs, numerator="spring_damper")
        return signal.lfilter(b, a, pr.alpha, axis=0)
    return None


def _extra_lp(pr, name, params):
    """:func:`_extra_raw` low-passed at the full rate, the last three kept per record (the
    forward stage varies the second effect only: the first's column is reused)."""
    key = (name, tuple(sorted((k, float(v)) for k, v in params.items())))
    cache = pr.__dict__.setdefault("_pair_extra", {})
    if key in cache:
        cache[key] = cache.pop(key)  # the most recent last
        return cache[key]
    ex = _extra_raw(pr, name, params)
    if len(cache) >= 3:
        cache.pop(next(iter(cache)))  # the least recent
    cache[key] = None if ex is None else pr.lp(ex, decimate=False)
    return cache[key]


#: a varying effect paired with a gain-like one (a reflex, a wobbling mass) varies that
#: effect's gain with the same basis (docs/diagnosis.md, "Pairs on position trials")
VARY_PARTNER_GAIN = True


def pair_columns(pr, effects: dict):
    """Low-passed design columns (Nd, n, p) of a record with several effects at once, and
    the coefficient slice of each effect's own columns (``{name: slice}``).

    ``effects``: {name: nonlinear params and choices} (servo_bandwidth is ignored here:
    it acts on the angle). Layout: the 3 n^2 K, B, I columns (times the stiffness scale
    of an amplitude or drift effect), one column per gain-like effect (reflex, wobbling
    mass), the torque channel's effects (lag, delay) applied to all of these, then a
    varying effect's basis columns (diagnosis.varying_effects.columns, on the channel's
    K and B columns).
    """
    from .limbfit import _with_unit_linear
    n, N, nn = pr.n, pr.N, pr.n * pr.n
    eff = {k: _with_unit_linear(k, v) for k, v in effects.items() if k != "servo_bandwidth"}
    scaled = {k: eff[k] for k in eff if k in SCALED}
    if scaled:
        scale = lm.stiffness_scale(pr.rec.theta, pr.fs, scaled)
        blocks = [pr.lp(pr.intrinsic_raw(scale).reshape(N, -1),
                        decimate=False).reshape(N, n, 3 * nn)]
    else:
        blocks = [pr.base_full.reshape(N, n, 3 * nn)]
    layout, width = {}, 3 * nn
    for k in eff:
        ex = _extra_lp(pr, k, eff[k])
        if ex is not None:
            blocks.append(ex.reshape(N, n, 1))
            layout[k] = slice(width, width + 1)
            width += 1
    channel = {k: eff[k] for k in eff if k in lm.CHANNEL_EFFECTS}
    if channel:
        full = lm.channel_apply(np.concatenate(blocks, axis=2).reshape(N, -1), pr.fs,
                                channel)
        cols = full[::pr.D][:pr.Nd].reshape(pr.Nd, n, -1)
    else:  # the same samples, kept before they are put side by side (D times fewer)
        cols = np.concatenate([b[::pr.D][:pr.Nd] for b in blocks], axis=2)
    for k in eff:
        if not vary.is_varying(k):
            continue
        # the basis is already on the decimated samples (vary.basis): not decimated again;
        # a switching level is read with the partners' gain-like columns beside the limb's
        others = [o for o in eff if o in layout and not vary.is_varying(o)]
        partner = None
        if k == "stiffness_switching" and others:
            partner = (tuple((o, tuple(sorted((a, repr(b)) for a, b in eff[o].items())))
                             for o in others),
                       np.concatenate([cols[:, :, layout[o]] for o in others],
                                      axis=2).reshape(pr.Nd, -1))
        phi_d, q = vary.basis(pr, k, eff[k], partner)
        extra = [cols[:, :, :2 * nn] * phi_d[:, m, None, None] for m in range(phi_d.shape[1])]
        if q is not None:
            for m in range(q.shape[1]):
                c = np.zeros((pr.Nd, n, n))
                for j in range(n):
                    c[:, j, j] = q[:, m]
                extra.append(c)
        ext = np.concatenate(extra, axis=2)
        layout[k] = slice(width, width + ext.shape[2])
        width += ext.shape[2]
        cols = np.concatenate([cols, ext], axis=2)
        if others and VARY_PARTNER_GAIN:
            # the partner's gain follows the same state (a reflex's gain rises with the
            # co-contraction, falls with fatigue): its column times the basis too
            g = np.concatenate([cols[:, :, layout[o]] * phi_d[:, m, None, None]
                                for o in others for m in range(phi_d.shape[1])], axis=2)
            layout[k + ":partner_gain"] = slice(width, width + g.shape[2])
            width += g.shape[2]
            cols = np.concatenate([cols, g], axis=2)
    return cols, layout


# ----------------------------------------------------------------------------- problem
class PairProblem:
    """Calibration objective of a pair over the nonlinear parameters of both effects.

    ``fixed``: {name: discrete choices (and, for a varying effect, nothing else)};
    ``split``: the varying effect's (calibration, held-out) masks per record, or None.
    """

    def __init__(self, lf, preps, names, fixed, cfg, split=None, unit=1.0):
        self.lf, self.preps, self.names, self.cfg = lf, preps, tuple(names), cfg
        self.fixed = {k: dict(fixed.get(k, {})) for k in self.names}
        self.nl = [(k, p) for k in self.names for p in searched(lf, k)]
        self.split, self.unit, self.n_eval = split, unit or 1.0, 0
        self.active = None  # the search's subset of records (limbfit.on_subset)
        self.masks = None   # calibration rows per record of a jackknife replicate

    def context(self):
        return vary.swapped(self.preps, self.split) if self.split is not None else nullcontext()

    #: (first effect's delay at its single fit, its bounds) while the forward stage keeps
    #: the first's total delay through a channel partner (:func:`fit_second`), else None
    coupled = None

    def params(self, x) -> dict:
        out = {k: dict(v) for k, v in self.fixed.items()}
        for (k, p), xi in zip(self.nl, x):
            out[k][p.name] = self.lf._from_x(p, xi)
        if self.coupled is not None:
            a, b = self.names
            total, (lo, hi) = self.coupled
            out[a]["delay_s"] = min(max(total - channel_lag_s(b, out[b]), lo), hi)
        return out

    def evaluate(self, params: dict):
        """(objective, solution, angle residuals, layout); inf when the columns fail."""
        self.n_eval += 1
        lf = self.lf
        preps = self.preps if self.active is None else [self.preps[i] for i in self.active]
        with self.context():
            try:
                built = [pair_columns(pr, params) for pr in preps]
            except ValueError:
                return math.inf, None, None, None
            masks = (self.masks if self.masks is None or self.active is None
                     else [self.masks[i] for i in self.active])
            sol = lf._solve(preps, [c for c, _ in built], masks)
            ang = [lf._angle_residual(pr, params.get("servo_bandwidth")) for pr in preps]
            obj = sol.cal_energy
            for i, (pr, a) in enumerate(zip(preps, ang)):
                if a is not None:
                    m = pr.cal if masks is None else masks[i]
                    obj += float(np.sum(a[m] ** 2)) / pr.theta_norm ** 2
        return obj, sol, ang, built[0][1]

    def objective(self, x):
        return self.evaluate(self.params(x))[0] / self.unit

    def search(self, x0, free):
        """Grid over the coordinates ``free`` (indices into ``nl``; the others at ``x0``),
        the best ``refine_starts`` points refined over those coordinates by Nelder-Mead;
        with many records on a subset of them, polished on all (limbfit.on_subset)."""
        x0 = np.asarray(x0, float)
        if not free:
            return x0
        if self.active is None and self.lf.many_records(self):
            x = self.lf.on_subset(self, self.search, x0, free)

            def along(sub):
                y = x.copy()
                y[list(free)] = sub
                return self.objective(y)
            out = x.copy()
            out[list(free)] = self.lf.polish(along, x[list(free)])
            return out
        band = min(pr.band for pr in self.preps)
        grids = []
        for i in free:
            k, p = self.nl[i]
            n = (vary.PERIOD_GRID if k == "stiffness_modulated" else self.cfg.grid
                 if len(free) == 1 else
                 max(6, int(self.cfg.grid * (1.3 if p.name == "delay_s" else 0.7))))
            # coupled to a first effect's delay, a channel delay's misfit has basins
            # about 1 ms wide (a reflex over a 10 ms delay, measured): a grid 4 times
            # finer than the single's (1 / (32 band) apart)
            fine = self.coupled is not None and p.name == "delay_s"
            grids.append([self.lf._to_x(p, v)
                          for v in self.lf._grid(p, n, band * (4.0 if fine else 1.0))])
        pts = np.array(np.meshgrid(*grids, indexing="ij")).reshape(len(grids), -1).T

        def full(sub):
            x = x0.copy()
            x[list(free)] = sub
            return x
        vals = [self.objective(full(pt)) for pt in pts]
        best_x, best_v = x0, math.inf
        for i in np.argsort(vals)[:self.cfg.refine_starts]:
            if not np.isfinite(vals[i]):
                continue
            sub = self._refine(lambda s: self.objective(full(s)), pts[i])
            v = self.objective(full(sub))
            if v < best_v:
                best_x, best_v = full(sub), v
        return best_x

    @staticmethod
    def _refine(fn, x0, step=0.03, maxiter=None):
        from .limbfit import nelder_mead
        return nelder_mead(fn, x0, step=step, maxiter=maxiter)


# ----------------------------------------------------------------------------- results
@dataclass
class PairFit:
    """A pair fitted on the calibration part (effects: (first, second)).

    params : {effect: its parameters, as the single fits report them};
    calibration_gap, held_out_gap : on the default split's scale (relative gaps above
    noise); held_out_reduction : 1 - held-out gap / nominal held-out gap;
    test : the second effect's held-out addition (:func:`second_adds`): the single's and
    the pair's raw gaps on the split they share, the drop, the threshold, ``adds``.
    """

    effects: tuple
    params: dict
    limb: lm.LimbModel
    calibration_objective: float
    calibration_gap: float
    held_out_gap: float
    held_out_reduction: float | None
    at_search_bound: list = field(default_factory=list)
    n_evaluations: int = 0
    test: dict = field(default_factory=dict)
    split: dict | None = None
    #: {effect: {param: [low, high]}} 95 % one-step jackknife intervals (:func:`add_intervals`)
    intervals: dict | None = None
    #: 95 % half-widths of the limb's K, B, I with the pair ({"K_h", "B_h", "M_h"})
    limb_ci: dict | None = None
    #: the jackknife replicates: [{"K": K0 of joint 1, effect: params}] (add_intervals)
    replicates: list | None = None
    #: {effect: form-profile record} (:func:`profile_pair`); None when not profiled
    form_profile: dict | None = None

    @property
    def adds(self) -> bool:
        return bool(self.test.get("adds"))

    def as_dict(self) -> dict:
        return {"effects": list(self.effects), "params": self.params,
                "K": self.limb.K.tolist(), "B": self.limb.B.tolist(), "I": self.limb.I.tolist(),
                "calibration_objective": self.calibration_objective,
                "calibration_gap": self.calibration_gap, "held_out_gap": self.held_out_gap,
                "held_out_reduction": self.held_out_reduction,
                "at_search_bound": self.at_search_bound, "n_evaluations": self.n_evaluations,
                "second_effect_test": self.test,
                **({"split": self.split} if self.split else {}),
                **({"intervals": self.intervals, "limb_ci": self.limb_ci,
                    "replicates": self.replicates} if self.intervals else {}),
                **({"form_profile": self.form_profile} if self.form_profile else {})}

    @classmethod
    def from_dict(cls, d: dict) -> "PairFit":
        return cls(tuple(d["effects"]), d["params"], lm.LimbModel(d["K"], d["B"], d["I"]),
                   float(d["calibration_objective"]), float(d["calibration_gap"]),
                   float(d["held_out_gap"]),
                   None if d["held_out_reduction"] is None else float(d["held_out_reduction"]),
                   list(d["at_search_bound"]), int(d["n_evaluations"]),
                   dict(d["second_effect_test"]), d.get("split"), d.get("intervals"),
                   d.get("limb_ci"), d.get("replicates"), d.get("form_profile"))


def _split_of(preps, names):
    """(masks per record, info) of the varying effect among ``names``, or (None, None)."""
    v = [k for k in names if vary.is_varying(k)]
    if not v:
        return None, None
    masks = [vary.split_masks(pr, v[0]) for pr in preps]
    return [(c, h) for c, h, _, _ in masks], {"rule": masks[0][2], "why": masks[0][3]}


def _gaps(lf, preps, sol, ang, limb0, cfg, split):
    ctx = vary.swapped(preps, split) if split is not None else nullcontext()
    with ctx:
        return (lf._gap(preps, sol.residual, ang, limb0, cfg, "cal"),
                lf._gap(preps, sol.residual, ang, limb0, cfg, "held"))


def _single_reference(lf, preps, single, nominal, cfg, split):
    """(calibration _Gap, held-out _Gap) of the single fit solved on ``split`` (its
    nonlinear parameters kept; its own split when it is varying)."""
    prob, x, _ = single._problem
    ctx = vary.swapped(preps, split) if split is not None else nullcontext()
    with ctx:
        _, sol, ang = prob.evaluate(prob.params(x))
    return _gaps(lf, preps, sol, ang, nominal["limb"], cfg, split)


def _nominal_on(lf, preps, nominal, cfg, split):
    """(calibration, held-out) nominal gap values on ``split`` (the default: as fitted)."""
    if split is None:
        return nominal["gaps"]["cal"].value, nominal["gaps"]["held"].value
    # the same split is asked for by every pair and every re-scored alternative on it:
    # kept with the nominal fit (a function of the records, the split and the settings)
    cache = nominal.setdefault("_gaps_on_split", {})
    key = (repr(cfg), tuple(hash(c.tobytes()) ^ hash(h.tobytes()) for c, h in split),
           tuple(id(pr) for pr in preps))
    hit = cache.get(key)
    if hit is not None and all(np.array_equal(c, c0) and np.array_equal(h, h0)
                               for (c, h), (c0, h0) in zip(split, hit[0])):
        return hit[1]
    cache[key] = ([(c.copy(), h.copy()) for c, h in split], _nominal_solved_on(
        lf, preps, nominal, cfg, split))
    return cache[key][1]


def _nominal_solved_on(lf, preps, nominal, cfg, split):
    with vary.swapped(preps, split):
        sol = lf._solve(preps, [pr.base for pr in preps])
        ang = [lf._angle_residual(pr, None) for pr in preps]
    g = _gaps(lf, preps, sol, ang, nominal["limb"], cfg, split)
    return g[0].value, g[1].value


def _choices(name):
    e = cat.get_effect(name)
    if not e.choices:
        return [{}]
    from itertools import product
    out = [dict(zip(e.choices, combo)) for combo in product(*e.choices.values())]
    return [c for c in out if c.get("rectified", True) or c.get("stretch_sign", 1.0) > 0]


def channel_lag_s(name, params) -> float:
    """The low-frequency lag [s] a torque-channel effect adds to every torque (a delay's
    delay, a first-order lag's time constant); 0 for the other effects."""
    if name == "channel_delay":
        return float(params["delay_s"])
    if name == "torque_sensor_lag":
        return float(params["time_constant_s"])
    return 0.0


def fit_second(lf, preps, single, other, nominal, cfg):
    """Forward selection: ``other`` fitted on top of the single fit (a limbfit.EffectFit
    with its ``_problem``), the single's nonlinear parameters fixed.

    Returns (PairProblem, x, objective) of the best discrete choice of ``other``."""
    found = [forward_choice(lf, preps, nominal, cfg, single.effect, single.params, other, i)
             for i in range(len(_choices(other)))]
    return forward_best(lf, preps, nominal, cfg, single.effect, single.params, other, found)


def _forward_problem(lf, preps, nominal, cfg, first, first_params, other, choice):
    """The PairProblem of ``other`` (its ``choice``-th discrete choice, :func:`_choices`)
    on top of the single fit of ``first`` (its reported parameters ``first_params``)."""
    split, _ = _split_of(preps, (first, other))
    choices_a = {k: first_params[k] for k in cat.get_effect(first).choices}
    return PairProblem(lf, preps, (first, other),
                       {first: choices_a, other: _choices(other)[choice]}, cfg, split,
                       nominal["solution"].cal_energy)


def forward_choice(lf, preps, nominal, cfg, first, first_params, other, choice):
    """One discrete choice of :func:`fit_second`'s forward step: (x, objective,
    evaluations) of ``other``'s ``choice``-th choice searched on top of ``first`` (its
    single fit's reported parameters ``first_params``). A task of its own (the choices
    and the partners are independent): picklable arguments and result."""
    prob = _forward_problem(lf, preps, nominal, cfg, first, first_params, other, choice)
    values_a = {p.name: float(first_params[p.name]) for p in searched(lf, first)}
    x0 = np.array([lf._to_x(p, values_a[p.name]) if k == first else 0.5
                   for k, p in prob.nl])
    free = [i for i, (k, _) in enumerate(prob.nl) if k == other]
    ia = next((i for i, (k, p) in enumerate(prob.nl)
               if k == first and p.name == "delay_s"), None)
    if other in lm.CHANNEL_EFFECTS and ia is not None:
        # the single's delay is the first effect's total delay as measured through
        # the torque channel: a channel partner takes its share of it (a reflex fitted
        # at 52 ms over a 10 ms channel delay; the pair's misfit between the two
        # splittings is higher than at either, so a local step never finds it)
        prob.coupled = (values_a["delay_s"], prob.nl[ia][1].bounds)
        x = prob.search(x0, free)
        x[ia] = lf._to_x(prob.nl[ia][1], prob.params(x)[first]["delay_s"])
        prob.coupled = None
    else:
        x = prob.search(x0, free)
    obj = prob.objective(x)
    return np.asarray(x, float), obj, prob.n_eval


def forward_best(lf, preps, nominal, cfg, first, first_params, other, found):
    """(PairProblem, x, objective) of the best of ``found`` (:func:`forward_choice`'s
    results, one per choice in order; the first of equal objectives), its evaluations
    those of every choice."""
    best = None
    for choice, (x, obj, _) in enumerate(found):
        if best is None or obj < best[2]:
            best = (choice, x, obj)
    prob = _forward_problem(lf, preps, nominal, cfg, first, first_params, other, best[0])
    prob.n_eval = sum(k for _, _, k in found)
    return prob, np.asarray(best[1], float), best[2]


def refine(prob, x):
    """One joint Nelder-Mead step over both effects' nonlinear parameters."""
    if not prob.nl:
        return np.asarray(x, float)
    if prob.lf.many_records(prob):  # on a subset, polished on all (limbfit.on_subset)
        x1 = prob.lf.polish(prob.objective, prob.lf.on_subset(
            prob, prob._refine, prob.objective, x, step=0.03, maxiter=40 * len(prob.nl)))
    else:
        x1 = prob._refine(prob.objective, x, step=0.03, maxiter=40 * len(prob.nl))
    return x1 if prob.objective(x1) <= prob.objective(x) else np.asarray(x, float)


def refine_task(lf, preps, nominal, cfg, first, first_params, other, choice, x):
    """:func:`refine` of the forward pair (``other``'s ``choice``-th choice on ``first``)
    at ``x``, as a task: (x, evaluations)."""
    prob = _forward_problem(lf, preps, nominal, cfg, first, first_params, other, choice)
    return refine(prob, np.asarray(x, float)), prob.n_eval


def _reported(lf, preps, name, params, coef, layout):
    """The effect's parameters as its single fit reports them (gains from the solve)."""
    nn = preps[0].n ** 2
    if vary.is_varying(name):
        sub = np.concatenate([coef[:3 * nn], coef[layout[name]]])
        out = vary.summary(preps, name, params, sub)
        pr = preps[0]
        last = getattr(pr, "_switch_partner_last", None)
        if name == "stiffness_switching" and last is not None and any(
                isinstance(v, slice) and k.endswith(":partner_gain") for k, v in layout.items()):
            out["n_changes"] = float(pr._switch_partnered[last][1])  # read beside the partner
        return out
    e = cat.get_effect(name)
    lin = {k: float(coef[layout[name]][i]) for i, k in enumerate(lf.LINEAR.get(name, ()))}
    full = {**params, **lin}
    out = {p.name: float(full[p.name]) for p in e.parameters}
    out.update({k: params[k] for k in e.choices})
    return out


def finish(lf, preps, single, prob, x, nominal, cfg) -> PairFit:
    """The PairFit of ``prob`` at ``x``: gaps, parameters, flags and the second's test."""
    params = prob.params(x)
    obj, sol, ang, layout = prob.evaluate(params)
    n = preps[0].n
    limb0 = nominal["limb"]
    g_cal, g_held = _gaps(lf, preps, sol, ang, limb0, cfg, prob.split)
    r_cal, r_held = _single_reference(lf, preps, single, nominal, cfg, prob.split)
    n_cal, n_held = _nominal_on(lf, preps, nominal, cfg, prob.split)
    d_cal, d_held = nominal["gaps"]["cal"].value, nominal["gaps"]["held"].value
    scale_cal = d_cal / n_cal if prob.split is not None and n_cal > 0 else 1.0
    scale_held = d_held / n_held if prob.split is not None and n_held > 0 else 1.0
    out = {k: _reported(lf, preps, k, params[k], sol.coef, layout) for k in prob.names}
    flags = []
    for k in prob.names:
        flags += [f"{k}: {m}" for m in cat.at_search_bound(k, out[k])]
        flags += [f"{k}: {g} = {out[k][g]:.4g} < 0 (unphysical)"
                  for g in lf.LINEAR.get(k, ()) if out[k][g] < 0]
    second = prob.names[1]
    drop = r_held.excess - g_held.excess
    threshold = cfg.significance_sigma * r_held.se + cfg.floor_margin * r_held.floor
    single_red = None if n_held <= 0 else 1.0 - r_held.value / n_held
    pair_red = None if n_held <= 0 else 1.0 - g_held.value / n_held
    test = {"single_held_out_gap": r_held.value, "pair_held_out_gap": g_held.value,
            "single_calibration_gap": r_cal.value, "pair_calibration_gap": g_cal.value,
            "held_out_drop": drop, "threshold": threshold,
            "single_held_out_reduction": single_red, "pair_held_out_reduction": pair_red,
            "second_adds_points": None if pair_red is None else pair_red - single_red,
            "below_detectability": bool(cat.below_detectability(second, out[second])),
            "split": "default" if prob.split is None else
            _split_of(preps, prob.names)[1]["rule"],
            # the residual floor included, on the same split (a clipped gap reads 0)
            "held_out_residual": g_held.residual_against(n_held)}
    test["adds"] = bool(not flags and drop > threshold and g_cal.excess < r_cal.excess
                        and not test["below_detectability"])
    fit = PairFit(prob.names, out, lf._limb_from(sol.coef, n),
                  obj, g_cal.value * scale_cal, g_held.value * scale_held,
                  None if n_held <= 0 else 1.0 - g_held.value / n_held, flags,
                  prob.n_eval, test,
                  None if prob.split is None else _split_of(preps, prob.names)[1])
    fit._problem = (prob, np.asarray(x, float))  # for add_intervals (not serialised)
    return fit


#: parameters that describe the data, not the fit (a schedule's centre and half range,
#: the number of switches read from the data): no interval
DESCRIPTORS = ("rho_mid", "rho_half_range", "n_changes")


def _shrunk(reps, limbs, scale):
    """The jackknife replicates moved towards their mean by ``scale`` (numbers only)."""
    limbs = np.asarray(limbs, float)
    limbs = limbs.mean(axis=0) + scale * (limbs - limbs.mean(axis=0))
    out = [{k: dict(v) for k, v in r.items()} for r in reps]
    for k in reps[0]:
        for p, v in reps[0][k].items():
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                continue
            vals = np.array([r[k][p] for r in reps], float)
            for r, y in zip(out, vals.mean() + scale * (vals - vals.mean())):
                r[k][p] = float(y)
    return out, list(limbs)


def add_intervals(lf, preps, fit: PairFit, cfg) -> PairFit:
    """95 % delete-one-block jackknife intervals of a pair's parameters and limb, in place.

    Each of ``cfg.n_jackknife`` replicates drops one contiguous block of every record's
    calibration rows (on the pair's own split) and takes one Newton step from the full
    fit's nonlinear parameters (limbfit.newton_step: the one-step jackknife the singles
    use with many records); where the step is refused the replicate keeps them and
    refits the linear ones. The form (the reflex's tied activation damping) is not
    profiled here: the intervals hold the data's uncertainty at this form only
    (:func:`profile_pair` widens them). With more records than ``cfg.search_trials`` the
    replicates run on the search's subset of records (limbfit.on_subset), their spread
    scaled by the square root of the subset's share of the calibration rows (exchangeable
    records of one condition), so a session of 200 trials costs what 16 do."""
    prob, x = fit._problem
    if lf.many_records(prob) and prob.active is None:
        return lf.on_subset(prob, add_intervals, lf, preps, fit, cfg)
    m = cfg.n_jackknife
    reps, limbs = [], []
    with prob.context():  # the block masks of the pair's own calibration rows
        blocks = [lf._block_masks(preps, m, b) for b in range(m)]
    n = preps[0].n
    try:
        for masks in blocks:
            prob.masks = masks
            xb = lf.newton_step(prob.objective, x) if prob.nl else None
            params = prob.params(x if xb is None else xb)
            _, sol, _, layout = prob.evaluate(params)
            if sol is None:
                return fit
            reps.append({k: _reported(lf, preps, k, params[k], sol.coef, layout)
                         for k in prob.names})
            limbs.append(np.asarray(sol.coef[:3 * n * n], float))
    finally:
        prob.masks = None
    if prob.active is not None:  # the subset's spread, scaled to all the records' rows
        rows = np.array([int(pr.cal.sum()) for pr in preps], float)
        reps, limbs = _shrunk(reps, limbs, math.sqrt(rows[prob.active].sum() / rows.sum()))
    out = {}
    for k in prob.names:
        out[k] = {}
        skip = set(cat.get_effect(k).choices) | set(DESCRIPTORS)
        for p, v in fit.params[k].items():
            if (p in skip or isinstance(v, bool) or not isinstance(v, (int, float))
                    or p not in reps[0][k]):
                continue
            se = float(lf.jackknife_se([r[k][p] for r in reps]))
            out[k][p] = [float(v) - 1.96 * se, float(v) + 1.96 * se]
    fit.intervals = out
    fit.limb_ci = lf._limb_half_widths(np.array(limbs), n)
    # each replicate's K0 and parameters: the band of a derived curve (K over the state)
    fit.replicates = [{"K": float(lb[0]), **r} for lb, r in zip(limbs, reps)]
    fit.n_evaluations = prob.n_eval
    return fit


def _forward_cost(lf, name, cfg) -> float:
    """A rough cost of one forward choice of partner ``name`` (its grid points)."""
    nl = len(searched(lf, name))
    if name == "stiffness_modulated":
        return float(vary.PERIOD_GRID)
    return float((cfg.grid if nl <= 1 else max(6, int(cfg.grid * 1.3))) ** max(nl, 0))


def needs_pair(lf, preps, single, nominal, cfg) -> bool:
    """The single's calibration residual is still significant (module docstring, 1)."""
    if single.at_search_bound or not hasattr(single, "_problem"):
        return False
    r_cal, _ = _single_reference(lf, preps, single, nominal, cfg,
                                 getattr(single._problem[0], "split", None))
    return bool(r_cal.significant(cfg))


def search_pairs(lf, preps, fits, nominal, cfg, partners=None, *, run=None) -> list:
    """Pairs built on ``fits[0]`` (limbfit.EffectFit's, best first), best first: every
    pairable partner forward-selected, the best N_REFINED refined jointly. [] when the best single
    is flagged or leaves no significant calibration gap.

    ``run(fn, arg_tuples, desc)``, optional: ``[fn(lf, preps, nominal, cfg, *a) for a in
    arg_tuples]``, e.g. on worker processes holding the same records (the forward step of
    every partner and choice, and the joint refits, are independent tasks:
    :func:`forward_choice`, :func:`refine_task`); default: in this process. The pairs
    are the same either way."""
    if not fits or not needs_pair(lf, preps, fits[0], nominal, cfg):
        return []
    first = fits[0]
    names = [f.effect for f in fits[1:] if math.isfinite(f.calibration_objective)]
    if partners is not None:
        names = [k for k in names if k in partners]
    names = [k for k in names if pairable(first.effect, k)]
    if not names:
        return []
    if run is None:
        def run(fn, arg_tuples, desc=""):
            return [fn(lf, preps, nominal, cfg, *a) for a in arg_tuples]
    a = (first.effect, dict(first.params))
    # every partner's every discrete choice is a task of its own (the costliest first:
    # the workers take them in this order)
    tasks = sorted(((k, c) for k in names for c in range(len(_choices(k)))),
                   key=lambda kc: -_forward_cost(lf, kc[0], cfg))
    done = dict(zip(tasks, run(forward_choice, [a + kc for kc in tasks], "limbfit pairs")))
    forward = [(k,) + forward_best(lf, preps, nominal, cfg, *a, k,
                                   [done[(k, c)] for c in range(len(_choices(k)))])
               for k in names]
    forward.sort(key=lambda t: t[3])
    top = forward[:N_REFINED]
    refined = run(refine_task, [a + (k, _choices(k).index(prob.fixed[k]), x)
                                for k, prob, x, _ in top], "limbfit pair refits")
    out = []
    for i, (k, prob, x, _) in enumerate(forward):
        if i < len(top):
            x, k_eval = refined[i]
            prob.n_eval += k_eval
        out.append(finish(lf, preps, first, prob, x, nominal, cfg))
    out.sort(key=lambda p: p.calibration_objective)
    if out and out[0].adds and cfg.n_jackknife >= 2:
        add_intervals(lf, preps, out[0], cfg)  # only the best pair can be named
        if cfg.form_profile:  # and its intervals include the form (profile_pair)
            profile_pair(lf, preps, out[0], nominal, cfg)
    return out


def named_pair(pairs, name_reduction: float):
    """The best pair when its second adds significantly and it closes ``name_reduction``
    of the held-out gap, else None (only the best pair can be named)."""
    if not pairs:
        return None
    p = pairs[0]
    if p.adds and p.held_out_reduction is not None and p.held_out_reduction >= name_reduction:
        return p
    return None


def profile_pair(lf, preps, fit: PairFit, nominal, cfg) -> dict | None:
    """Intervals that include the form, for a pair (issue 21, item 2): the pair refitted
    (both effects' nonlinear parameters refined jointly, K, B, I and the gains solved
    again) at every alternative of each member's tied or picked choices
    (diagnosis.formprofile.alternatives: the reflex's activation damping, threshold and
    rectification, the servo's damping, the wobbling mass's damping), one member at a
    time; an alternative the data do not reject (formprofile.keep_tolerance on the
    calibration gap, against the best profiled one) gets its one-step jackknife
    (:func:`add_intervals`), and every parameter's interval becomes the envelope over
    the kept choices, the limb's K, B, I half-widths likewise (symmetric about the
    point estimate, the largest distance to an end of a kept interval); a delay's also
    +- half a sample period (the delay model's resolution). The point estimate stays the
    pair's own (unlike a single's profile, which moves it to the best-fitting choice).

    ``fit`` must hold its jackknife intervals (:func:`add_intervals`). Sets
    ``fit.intervals``, ``fit.limb_ci`` and ``fit.form_profile`` ({effect: record, as
    formprofile.profile's}); returns the latter, None when no member has alternatives."""
    from types import SimpleNamespace
    from . import formprofile as fpm
    if fit.intervals is None or not hasattr(fit, "_problem"):
        return None
    prob, x = fit._problem
    if lf.many_records(prob):
        # refits of every alternative on all records would cost more than the pair's
        # search: the intervals stay the jackknife's at the tied form (said in the report)
        return None
    alts = [(k, label, fixed) for k in prob.names if fpm.profiled(k)
            for label, fixed in fpm.alternatives(k, prob.fixed[k])]
    if not alts:
        return None
    limb0 = nominal["limb"]
    n = preps[0].n
    n_eval0 = prob.n_eval

    def scored(pa, xa):
        params = pa.params(xa)
        o, sol, ang, layout = pa.evaluate(params)
        if sol is None or not math.isfinite(o):
            return None
        g_cal, _ = _gaps(lf, preps, sol, ang, limb0, cfg, pa.split)
        rep = {k: _reported(lf, preps, k, params[k], sol.coef, layout) for k in pa.names}
        return g_cal, rep, np.asarray(sol.coef[:3 * n * n], float)

    own = scored(prob, np.asarray(x, float))
    if own is None:
        return None
    rows = [{"effect": None, "fixed": prob.fixed, "choice": "the fit's", "gap": own[0],
             "params": own[1],
             "limb": own[2], "intervals": fit.intervals, "limb_ci": fit.limb_ci,
             "kept": True, "_prob": (prob, np.asarray(x, float))}]
    n_eval = 0
    for k, label, fixed in alts:
        pa = PairProblem(lf, preps, prob.names, {**prob.fixed, k: fixed}, cfg, prob.split,
                         prob.unit)
        xa = refine(pa, np.asarray(x, float))
        s = scored(pa, xa)
        n_eval += pa.n_eval
        if s is None:
            continue
        rows.append({"effect": k, "fixed": pa.fixed, "choice": label, "gap": s[0],
                     "params": s[1],
                     "limb": s[2], "intervals": None, "limb_ci": None, "kept": False,
                     "_prob": (pa, xa)})
    best = min(rows, key=lambda r: r["gap"].excess)
    tol = fpm.keep_tolerance(best["gap"], cfg)
    for r in rows[1:]:
        r["kept"] = bool(r["gap"].excess - best["gap"].excess <= tol)
        if r["kept"]:
            pa, xa = r["_prob"]
            k0 = pa.n_eval
            shell = SimpleNamespace(_problem=(pa, xa), params=r["params"], intervals=None,
                                    limb_ci=None, replicates=None, n_evaluations=0)
            add_intervals(lf, preps, shell, cfg)
            n_eval += pa.n_eval - k0
            r["intervals"], r["limb_ci"] = shell.intervals, shell.limb_ci
    kept = [r for r in rows if r["kept"] and r["intervals"] is not None]
    # a truth between a kept grid value and a rejected neighbour: bisected to where the
    # data reject the choice (formprofile._edges, for the pair)
    keep = lambda g: g.excess - best["gap"].excess <= tol  # noqa: E731
    mids, k_edges = _pair_edges(lf, preps, prob, rows, keep, scored)
    n_eval += k_edges
    half_delay = 0.5 / min(pr.fs for pr in preps)
    envelope = {}
    for k, ci in fit.intervals.items():
        envelope[k] = {}
        for p in ci:
            lo = min([r["intervals"][k][p][0] for r in kept if p in r["intervals"].get(k, {})]
                     + [m[0][k][p] for m in mids if p in m[0].get(k, {})])
            hi = max([r["intervals"][k][p][1] for r in kept if p in r["intervals"].get(k, {})]
                     + [m[0][k][p] for m in mids if p in m[0].get(k, {})])
            if p == "delay_s":
                lo, hi = lo - half_delay, hi + half_delay
            envelope[k][p] = [float(lo), float(hi)]
    limb_ci = fit.limb_ci
    if fit.limb_ci is not None and all(r["limb_ci"] is not None for r in kept):
        h0 = fpm.flat_ci(fit.limb_ci)
        # every kept choice's interval, and a bisection's limb with the fit's own scatter
        limb_ci = fpm.covering_half_widths(
            own[2], [(r["limb"], fpm.flat_ci(r["limb_ci"])) for r in kept]
            + [(lb, h0) for _, lb in mids], n)
    # and the pipeline's own form: its derivatives (limbfit.derivative_allowance)
    allowance = None
    if limb_ci is not None:
        allowance = lf.derivative_allowance(preps, lf._limb_from(own[2], n))
        limb_ci = {q: (np.asarray(limb_ci[q], float) + np.asarray(allowance[q], float)).tolist()
                   for q in limb_ci}
    rule = ("the pair refitted at each member's alternatives; an alternative is kept when "
            "its calibration gap exceeds the best profiled one's by at most "
            f"significance_sigma standard errors plus floor_margin of its floor ({tol:.3g}); "
            "the interval is the envelope of the kept one-step jackknife intervals (a "
            "delay's also +- half a sample period; the limb's half-widths also plus what the "
            "pipeline's derivatives move K, B, I by, limbfit.derivative_allowance); the point "
            "estimate is the pair's own")
    records = {}
    for k in prob.names:
        if not fpm.profiled(k):
            continue
        own_fixed = prob.fixed[k]
        records[k] = {
            "profiled": {q: list(v) for q, v in fpm.FORM_GRID[k].items()
                         if q != "threshold_rad_s" or own_fixed.get("rectified")},
            "rule": rule,
            "alternatives": [{"choice": r["choice"] if r["effect"] in (None, k) else
                              f"{r['effect']}: {r['choice']}",
                              "params": r["params"][k],
                              "calibration_gap": float(r["gap"].value),
                              "calibration_excess": float(r["gap"].excess),
                              "intervals": None if r["intervals"] is None else
                              r["intervals"].get(k),
                              "kept": r["kept"]} for r in rows],
            "jackknife_intervals": dict(fit.intervals.get(k, {})),
            "jackknife_limb_ci": fit.limb_ci,
            "derivative_allowance": allowance,
            "intervals": envelope.get(k, {}),
            "best_fitting": best["choice"] if best["effect"] in (None, k) else
            f"{best['effect']}: {best['choice']}",
            "point_estimate_changed": False,
            "delay_resolution_s": half_delay,
            "n_evaluations": int(n_eval)}
    fit.intervals = envelope
    fit.limb_ci = limb_ci
    fit.form_profile = records
    fit.n_evaluations = int(n_eval0 + n_eval)
    return records


def _pair_edges(lf, preps, prob, rows, keep, scored) -> tuple:
    """formprofile._edges for a pair: between a kept grid value of a member's tied
    continuous choice and a rejected neighbour, formprofile.BISECTIONS refits half-way
    (geometric), each kept one joining the envelope, then the parameters and limb
    interpolated half-way between the last kept and the last rejected. Returns
    ([(reported params {effect: {param: value}}, limb coefficients)], evaluations)."""
    from . import formprofile as fpm
    out, n_eval = [], 0
    own = rows[0]["fixed"]
    for k in prob.names:
        tied = lm.DEFAULTS.get(k, {})
        for key in fpm.FORM_GRID.get(k, {}):
            def value(r):
                return float(r["fixed"][k].get(key, tied.get(key, 0.0)))
            line = [rows[0]] + [r for r in rows[1:] if r["effect"] == k and all(
                r["fixed"][k].get(c) == own[k].get(c)
                for c in set(own[k]) | set(r["fixed"][k]) if c != key)]
            if len(line) < 2:
                continue
            line.sort(key=value)
            for a, b in zip(line, line[1:]):
                if a["kept"] == b["kept"]:
                    continue
                good, bad = (a, b) if a["kept"] else (b, a)
                zg, zb = value(good), value(bad)
                pg, lg, xg = good["params"], good["limb"], good["_prob"][1]
                pb, lb = bad["params"], bad["limb"]
                for _ in range(fpm.BISECTIONS):
                    zm = math.sqrt(zg * zb) if min(zg, zb) > 0 else 0.5 * (zg + zb)
                    pa = PairProblem(lf, preps, prob.names,
                                     {**own, k: {**own[k], key: zm}}, prob.cfg, prob.split,
                                     prob.unit)
                    xm = refine(pa, np.asarray(xg, float))
                    sm = scored(pa, xm)
                    n_eval += pa.n_eval
                    if sm is None:
                        zb = zm
                        continue
                    if keep(sm[0]):
                        zg, pg, lg, xg = zm, sm[1], sm[2], xm
                        out.append((sm[1], sm[2]))
                    else:
                        zb, pb, lb = zm, sm[1], sm[2]
                half = {e: {q: 0.5 * (v + pb[e][q]) for q, v in pg[e].items()
                            if isinstance(v, (int, float)) and not isinstance(v, bool)
                            and isinstance(pb[e].get(q), (int, float))}
                        for e in pg}
                out.append((half, 0.5 * (lg + lb)))
    return out, n_eval
