"""Intervals that include the form (issue 21, item 2): the named effect refitted at the
plausible alternatives of the choices its fit ties or picks, and its 95 % intervals taken
as the envelope of the jackknife intervals over those refits.

A catalogue fit ties some of its model's form to one value (the reflex's activation
damping 0.7, the wobbling mass's damping 0.3, the servo's damping 0.7) and picks a
discrete choice (the reflex rectified or not). The delete-one-block jackknife of
diagnosis.limbfit measures the parameters' scatter *given* that form; when the truth has
another form the fitted delay or mass moves by more than that scatter (labsim: a reflex of
activation damping 1.0 fitted with 0.7 moves the delay 5-15 %, its jackknife interval
~0.1 ms wide). Here the named effect is refitted (its nonlinear parameters refined by
Nelder-Mead from the fit's, K, B, I and the gains solved again) at every alternative of
:data:`FORM_GRID`, and at the other rectification choice; an alternative the data do not
reject is kept (its calibration gap exceeds the best profiled one's by at most
``significance_sigma`` standard errors of that gap plus ``floor_margin`` of its floor:
:func:`keep_tolerance`), its
jackknife is run, and
every parameter's interval becomes the envelope [min low, max high] over the kept
choices, and towards a rejected neighbour on the grid to where the data reject the choice
(bisection between the two grid values, :data:`BISECTIONS` refits; the data resolve the
damping more finely than the grid); the limb's K, B, I half-widths likewise (symmetric about
the point estimate, the largest distance to an end of a kept interval).

The point estimate is the best-fitting profiled choice (lowest calibration gap): the
fit's own when no alternative fits better, else the alternative's parameters, limb and
gaps replace the fit's (``point_estimate_changed`` in the record, the choice as a value
such as ``damping`` in the fit's parameters, which the named model simulates with).

The grid, from the physiology (docs/diagnosis.md, "Intervals that include the form"):

- reflex activation damping {0.5, 0.6, 0.7, 0.85, 1.0, 1.2}: the second-order reflex
  dynamics of the ankle's parallel-cascade identifications lie between under-damped and
  critically damped (Kearney, Stein & Parameswaran 1997; Mirbagheri et al. 2000: about
  0.5-1.0), and an activation of two real poles (excitation and contraction) is
  over-damped, hence 1.2; labsim draws 0.6-0.9 (0.4-1.2 in its ``reflex_other_damping``);
- wobbling-mass damping {0.1, 0.15, 0.2, 0.3, 0.45, 0.6}: soft-tissue damping ratios of wobbling-mass
  models, lightly damped to well damped (Gruber et al. 1998, about 0.1-0.5);
- servo damping {0.5, 0.7, 1.0}: the closed-loop damping of a position servo's tuning
  (labsim's PD servo 0.6-1.0);
- a rectified reflex's velocity threshold {0, 0.02, 0.05} rad/s (tied at 0: the rectifier
  passes any stretch velocity; reflexes have a velocity threshold, small against the
  perturbations' ~1-2 rad/s RMS velocity; labsim draws 0-0.05 rad/s);
- the reflex's rectification: the other choice (rectified or linear; a rectified
  alternative with both stretch signs), at the tied damping.

Cost: (number of alternatives) refinements plus one jackknife per kept alternative, for
the named (best) effect only, never for the other candidates.
"""

from __future__ import annotations

import math

import numpy as np

#: the tied continuous choices profiled, per effect: {effect: {param: (values...)}}; the
#: fit's own (tied) value is one of them
FORM_GRID = {
    "stretch_reflex": {"damping": (0.5, 0.6, 0.7, 0.85, 1.0, 1.2),
                       # of a rectified reflex only: the velocity the rectifier passes above
                       "threshold_rad_s": (0.0, 0.02, 0.05)},
    "wobbling_mass": {"damping": (0.1, 0.15, 0.2, 0.3, 0.45, 0.6)},
    "servo_bandwidth": {"damping": (0.5, 0.7, 1.0)},
}


def profiled(name: str) -> bool:
    """Whether :func:`profile` has alternatives for effect ``name``."""
    return name in FORM_GRID


def alternatives(name: str, fixed: dict) -> list:
    """[(label, fixed choices)] of the alternatives of effect ``name``'s form other than
    the fit's own (``fixed``: its discrete choices, without the tied values)."""
    from . import limb as lm
    tied = lm.DEFAULTS.get(name, {})
    out = []
    for key, values in FORM_GRID.get(name, {}).items():
        if key == "threshold_rad_s" and not fixed.get("rectified"):
            continue  # a threshold acts on a rectified reflex only
        own = float(fixed.get(key, tied.get(key)))
        for v in values:
            if not math.isclose(v, own):
                out.append((f"{key} = {v:g}", {**fixed, key: float(v)}))
    if name == "stretch_reflex" and "rectified" in fixed:
        if fixed["rectified"]:
            out.append(("rectified = False", {**fixed, "rectified": False, "stretch_sign": 1.0}))
        else:
            for sign in (1.0, -1.0):
                out.append((f"rectified = True, stretch_sign = {sign:+g}",
                            {**fixed, "rectified": True, "stretch_sign": sign}))
    return out


def _own_label(name, fixed):
    from . import limb as lm
    tied = lm.DEFAULTS.get(name, {})
    parts = [f"{k} = {float(fixed.get(k, tied.get(k))):g}" for k in FORM_GRID.get(name, {})
             if k != "threshold_rad_s" or fixed.get("rectified")]
    if "rectified" in fixed:
        parts.append(f"rectified = {bool(fixed['rectified'])}")
    return ", ".join(parts) + " (the fit's)"


def flat_ci(ci: dict) -> np.ndarray:
    """The K, B, I half-widths {"K_h", "B_h", "M_h"} as one (3 n^2,) vector, the limb
    coefficients' order."""
    return np.concatenate([np.asarray(ci[k], float).reshape(-1) for k in ("K_h", "B_h", "M_h")])


def covering_half_widths(v0, items, n: int) -> dict:
    """{"K_h", "B_h", "M_h"}: half-widths about the limb coefficients ``v0`` (3 n^2,)
    covering every interval ``limb +- half`` of ``items`` [(limb, half)]."""
    half = np.zeros_like(np.asarray(v0, float))
    for limb, h in items:
        half = np.maximum(half, np.abs(np.asarray(limb, float) - v0) + h)
    nn = n * n
    return {key: half[i * nn:(i + 1) * nn].reshape(n, n).tolist()
            for i, key in enumerate(("K_h", "B_h", "M_h"))}


def keep_tolerance(gap, cfg) -> float:
    """How much more calibration gap than the best profiled choice a kept choice may
    leave: ``significance_sigma`` standard errors of the best's gap plus ``floor_margin``
    of its floor (the significance threshold of a gap without its model tolerance: the
    discrete model's own error is common to every choice fitted to the same samples; with
    it the tolerance, ~1e-4 of the torque energy, kept a rectified reflex beside a linear
    one 14 times better and a wobbling mass's interval 50-60 % wide)."""
    return cfg.significance_sigma * gap.se + cfg.floor_margin * gap.floor


def _values(lf, prob, x, sol, lin_names):
    params = prob.params(x)
    n = prob.preps[0].n
    vals = {p.name: float(params[p.name]) for p in prob.nl}
    vals.update({k: float(sol.coef[3 * n * n + i]) for i, k in enumerate(lin_names)})
    return vals


def profile(lf, fit, cfg) -> dict | None:
    """Refit ``fit`` (a limbfit.EffectFit with its jackknife intervals) at the
    alternatives of its form; set its intervals to the envelope, and its point estimate to
    the best-fitting choice (:func:`apply`). Returns the record (also
    ``fit.form_profile``), None when the effect has no alternatives.

    ``lf``: the diagnosis.limbfit module. The record: ``profiled`` {choice: [values]},
    ``alternatives`` (the fit's own first: ``choice``, ``params``, ``calibration_gap``,
    ``calibration_excess``, ``intervals`` (jackknife, None when not kept), ``kept``),
    ``rule`` (the keep test; a delay's envelope also +- half a sample period, the delay
    model's resolution), ``jackknife_intervals`` (the fit's own), ``intervals`` (the
    envelope), ``best_fitting``, ``point_estimate_changed`` (the best-fitting choice is
    not the fit's own: the point estimate, limb and gaps are its), ``chosen`` (what
    :func:`apply` sets), ``n_evaluations``."""
    prob, x, lin = fit._problem
    name = fit.effect
    if not profiled(name) or fit.intervals is None:
        return None
    alts = alternatives(name, prob.fixed)
    if not alts:
        return None
    preps = prob.preps
    lin_names = list(lin)
    n = preps[0].n
    limb0 = fit.limb
    n_eval = 0
    prob.masks = None
    obj, sol, ang = prob.evaluate(prob.params(x))
    g_own = lf._gap(preps, sol.residual, ang, limb0, cfg, "cal")
    rows = [{"choice": _own_label(name, prob.fixed), "fixed": dict(prob.fixed),
             "params": _values(lf, prob, x, sol, lin_names),
             "calibration_gap": g_own.value, "calibration_excess": g_own.excess,
             "objective": obj / prob.unit, "intervals": dict(fit.intervals), "kept": True,
             "limb": np.asarray(sol.coef[:3 * n * n], float), "limb_ci": fit.limb_ci,
             "_gap": g_own, "_prob": (prob, np.asarray(x, float)), "_sol": (sol, ang)}]
    for label, fixed in alts:
        pa = lf._Problem(preps, name, fixed, cfg, prob.unit)
        xa = pa._refine(np.asarray(x, float))
        o, s, a = pa.evaluate(pa.params(xa))
        n_eval += pa.n_eval
        if s is None or not math.isfinite(o):
            continue
        g = lf._gap(preps, s.residual, a, limb0, cfg, "cal")
        rows.append({"choice": label, "fixed": dict(fixed),
                     "params": _values(lf, pa, xa, s, lin_names),
                     "calibration_gap": g.value, "calibration_excess": g.excess,
                     "objective": o / pa.unit, "intervals": None, "kept": False,
                     "limb": np.asarray(s.coef[:3 * n * n], float), "limb_ci": None,
                     "_gap": g, "_prob": (pa, xa), "_sol": (s, a)})
    best = min(rows, key=lambda r: r["calibration_excess"])
    g_best = best["_gap"]
    tol = keep_tolerance(g_best, cfg)
    for row in rows:
        row["kept"] = bool(row["calibration_excess"] - g_best.excess <= tol)
        if row["kept"] and row["intervals"] is None and cfg.n_jackknife >= 2:
            pa, xa = row["_prob"]
            k0 = pa.n_eval
            ci, _ = lf._jackknife(pa, xa, {k: row["params"][k] for k in lin_names}, cfg)
            n_eval += pa.n_eval - k0
            row["intervals"] = ci
            row["limb_ci"] = pa.limb_ci
    kept = [r for r in rows if r["kept"] and r["intervals"] is not None]
    half_delay = 0.5 / min(pr.fs for pr in preps)
    # a truth between a kept grid value and a rejected neighbour: the fit half-way
    # between them (the parameters interpolated) joins the envelope
    keep = lambda excess: excess - g_best.excess <= tol  # noqa: E731
    mids, k_edges = _edges(lf, name, rows, keep, cfg, prob.unit, limb0)
    n_eval += k_edges
    envelope = {}
    for k in fit.intervals:
        los = [r["intervals"][k][0] for r in kept if k in r["intervals"]]
        his = [r["intervals"][k][1] for r in kept if k in r["intervals"]]
        los += [m[k] for m in mids if k in m]
        his += [m[k] for m in mids if k in m]
        envelope[k] = [float(min(los)), float(max(his))]
        if k == "delay_s":
            # the delay model's resolution: a fractional delay by linear interpolation
            # between samples leaves a kink in the misfit at every whole sample, where
            # the fits (and all the jackknife's) stick: +- half a sample period
            envelope[k] = [envelope[k][0] - half_delay, envelope[k][1] + half_delay]
    # the limb: symmetric half-widths about the point estimate covering every kept interval
    limb_ci = None
    if all(r["limb_ci"] is not None for r in kept):
        limb_ci = covering_half_widths(best["limb"], [(r["limb"], flat_ci(r["limb_ci"]))
                                                      for r in kept], n)
    changed = best is not rows[0]
    pb, xb = best["_prob"]
    sb, ab = best["_sol"]
    g_held = lf._gap(preps, sb.residual, ab, limb0, cfg, "held")
    chosen = {"fixed": dict(best["fixed"]), "x": [float(v) for v in np.atleast_1d(xb)],
              "lin": {k: best["params"][k] for k in lin_names},
              "params": dict(best["params"]),
              "K": _limb_part(best["limb"], n, 0), "B": _limb_part(best["limb"], n, 1),
              "I": _limb_part(best["limb"], n, 2),
              "calibration_objective": float(best["objective"]),
              "calibration_gap": float(best["calibration_gap"]),
              "held_out_gap": float(g_held.value),
              "held_out_reduction": _reduction(fit, g_held.value)}
    record = {
        "profiled": {**{k: list(v) for k, v in FORM_GRID[name].items()
                        if k != "threshold_rad_s" or prob.fixed.get("rectified")},
                     **({"rectified": [False, True]} if "rectified" in prob.fixed else {})},
        "rule": ("an alternative is kept when its calibration gap exceeds the best profiled "
                 "one's by at most significance_sigma standard errors of that gap plus "
                 "floor_margin of its floor "
                 f"({tol:.3g}); the interval is the envelope of the kept jackknife "
                 "intervals (a delay's also +- half a sample period); the point estimate "
                 "is the best-fitting choice"),
        "alternatives": [{k: v for k, v in r.items() if not k.startswith("_")
                          and k not in ("limb", "limb_ci", "fixed")} for r in rows],
        "jackknife_intervals": dict(fit.intervals),
        "intervals": envelope,
        "limb_ci": limb_ci,
        "delay_resolution_s": half_delay,
        "best_fitting": best["choice"],
        "point_estimate_changed": bool(changed),
        "chosen": chosen,
        "n_evaluations": int(n_eval),
    }
    apply(lf, fit, record, cfg)
    return record


#: bisection steps between a kept grid value and a rejected neighbour
BISECTIONS = 3


def _edges(lf, name, rows, keep, cfg, unit, limb0) -> tuple:
    """Where the kept region of a tied continuous choice ends between a kept grid value
    and a rejected neighbour (the data resolve the damping more finely than the grid):
    BISECTIONS refits half-way (on the log scale), each kept one's parameters joining the
    envelope, then the parameters interpolated half-way between the last kept and the
    last rejected. Returns ([{param: value}], evaluations)."""
    from . import limb as lm
    out, n_eval = [], 0
    for key in FORM_GRID.get(name, {}):
        own = rows[0]["fixed"]
        tied = lm.DEFAULTS.get(name, {}).get(key)
        line = [r for r in rows if all(r["fixed"].get(c) == own.get(c)
                                       for c in set(own) | set(r["fixed"]) if c != key)]
        line.sort(key=lambda r: float(r["fixed"].get(key, tied)))
        for a, b in zip(line, line[1:]):
            if a["kept"] == b["kept"]:
                continue
            good, bad = (a, b) if a["kept"] else (b, a)
            zg, zb = float(good["fixed"].get(key, tied)), float(bad["fixed"].get(key, tied))
            pg, xg = good["params"], good["_prob"][1]
            pb = bad["params"]
            for _ in range(BISECTIONS):
                zm = math.sqrt(zg * zb) if min(zg, zb) > 0 else 0.5 * (zg + zb)
                pa = lf._Problem(good["_prob"][0].preps, name, {**own, key: zm}, cfg, unit)
                xm = pa._refine(np.asarray(xg, float))
                o, s, an = pa.evaluate(pa.params(xm))
                n_eval += pa.n_eval
                if s is None or not math.isfinite(o):
                    zb = zm
                    continue
                pm = _values(lf, pa, xm, s, [k for k in pg if k not in
                                             {p.name for p in pa.nl}])
                g = lf._gap(pa.preps, s.residual, an, limb0, cfg, "cal")
                if keep(g.excess):
                    zg, pg, xg = zm, pm, xm
                    out.append(pm)
                else:
                    zb, pb = zm, pm
            out.append({k: 0.5 * (pg[k] + pb[k]) for k in pg})
    return out, n_eval


def _reduction(fit, held):
    """1 - held / the nominal's held-out gap (limbfit keeps it on the fit as
    ``nominal_held_out_gap``; else from the fit's own gap and reduction)."""
    nom = getattr(fit, "nominal_held_out_gap", None)
    if nom is None and fit.held_out_reduction is not None and fit.held_out_reduction != 1.0:
        nom = fit.held_out_gap / (1.0 - fit.held_out_reduction)
    return None if not nom or nom <= 0 else float(1.0 - held / nom)


def _limb_part(coef, n, i):
    nn = n * n
    return np.asarray(coef[i * nn:(i + 1) * nn], float).reshape(n, n).tolist()


def apply(lf, fit, record, cfg) -> None:
    """Set ``fit`` (a limbfit.EffectFit of the same data) to the profile ``record``: the
    envelope intervals, and, when the best-fitting choice is not the fit's own, that
    choice's parameters, limb, gaps and search state (a resumed diagnosis reads the
    record back and applies it)."""
    from . import catalogue as cat
    from . import limb as lm
    fit.form_profile = record
    fit.intervals = {k: list(v) for k, v in record["intervals"].items()}
    if record.get("limb_ci") is not None:
        fit.limb_ci = record["limb_ci"]
    fit.n_evaluations += int(record.get("n_evaluations", 0))
    if not record.get("point_estimate_changed"):
        return
    ch = record["chosen"]
    prob, _, _ = fit._problem
    pa = lf._Problem(prob.preps, fit.effect, ch["fixed"], cfg, prob.unit)
    fit._problem = (pa, np.asarray(ch["x"], float), dict(ch["lin"]))
    params = {p.name: ch["params"][p.name] for p in cat.get_effect(fit.effect).parameters}
    params.update({k: ch["fixed"][k] for k in ch["fixed"]})
    fit.params = params
    fit.limb = lm.LimbModel(ch["K"], ch["B"], ch["I"])
    fit.calibration_objective = float(ch["calibration_objective"])
    fit.calibration_gap = float(ch["calibration_gap"])
    fit.held_out_gap = float(ch["held_out_gap"])
    fit.held_out_reduction = ch["held_out_reduction"]
    fit.at_search_bound = cat.at_search_bound(fit.effect, params) + [
        f"{k} = {v:.4g} < 0 (unphysical)" for k, v in ch["lin"].items() if v < 0]
