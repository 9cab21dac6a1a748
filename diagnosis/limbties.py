"""Ties on position-servo trials (issue 21, item 3): every alternative to the named fit
judged on the named fit's own held-out split (diagnosis.ties gives the rule, the row
shape and the advice).

Why a module of its own: the position fits (diagnosis.limbfit) are not all judged on one
split. A time-varying effect is held out on interleaved blocks, a state-varying one on
blocks stratified by its scheduling variable, the others on the last part of every
trial (diagnosis.varying_effects, "Held-out split"). Each held-out reduction in the
ranking is ``1 - gap(effect) / gap(nominal)`` on the effect's own split, so two rows of
different splits are not comparable: on the measured pilot recording the ranking gave
stretch_reflex 78 % (last 40 %) beside the named stiffness_angle 56 % (stratified
blocks), and the old sentence called the reflex a tie "within 5 points" of it.

Here an alternative whose split differs from the named fit's is solved again on the
named fit's split: its discrete choices kept, its nonlinear parameters refined locally
from its own fit (Nelder-Mead, as the jackknife's replicates are) on that split's
calibration samples, K, B, I and its gain-like parameters solved there
(diagnosis.limbpairs.PairProblem, which takes one effect or two); its held-out gap is
then read on that split's held-out samples, against the nominal model solved on the
same calibration samples. An alternative of the same split keeps its own figures (its
fit saw the same calibration samples) and flags; a re-solved one is judged by the flags
of its fit on the named split (a search bound, a negative gain): a drift rate on its
search bound over the last 40 % of the trial may lie well inside it on interleaved
blocks. The named fit keeps its own reduction. For the reader (not the rule) the named
model is also solved the same way on the own split of each alternative whose own figure
comes within the margin of the named one's (``named_on_own_split``, else None): the
splits suit each effect's form (a switching model
interpolating between interleaved blocks follows any slow change), so the rule compares
on the split of the fit the verdict names.

Alternatives: to a named single, every other single fitted (the pairs are all built on
the named single: it plus a partner, not an alternative to it); to a named pair, the
other pairs and every single that is not one of its two effects.
"""

from __future__ import annotations

import math

import numpy as np

from . import catalogue as cat
from . import limbpairs as lp
from . import ties
from . import varying_effects as vary


def split_of(preps, effects, cfg):
    """(masks per record or None for the default split, the split in words)."""
    masks, info = lp._split_of(preps, effects)
    if masks is None:
        return None, (f"the last {100 * cfg.held_out_fraction:.0f} % of every trial, "
                      f"the default split")
    v = next(k for k in effects if vary.is_varying(k))
    return masks, f"{info['rule']}, {v}'s own split"


def same_split(preps, a, b) -> bool:
    """True when two splits (masks per record or None) hold the same samples."""
    if a is None or b is None:
        return a is None and b is None
    return all(np.array_equal(ca, cb) and np.array_equal(ha, hb)
               for (ca, ha), (cb, hb) in zip(a, b))


def _start(lf, name, params):
    """(discrete choices, nonlinear values) of an effect's reported parameters."""
    e = cat.get_effect(name)
    choices = {k: params[k] for k in (e.choices or {})}
    values = {p.name: float(params[p.name]) for p in lp.searched(lf, name)}
    return choices, values


def score(lf, preps, params, nominal, cfg, split, refine: bool = True):
    """(held-out reduction, reported parameters, flags, evaluations) of the model
    ``params`` ({effect: its reported parameters}, one effect or two) solved on
    ``split`` (masks per record, None: the default one), its nonlinear parameters
    refined there from these values when ``refine``. Reduction None when the model
    fails (columns that cannot be built) or there is no nominal held-out gap."""
    names = tuple(params)
    start = {k: _start(lf, k, params[k]) for k in names}
    prob = lp.PairProblem(lf, preps, names, {k: c for k, (c, _) in start.items()}, cfg,
                          split, nominal["solution"].cal_energy)
    x0 = np.array([lf._to_x(p, min(max(start[k][1][p.name], p.bounds[0]), p.bounds[1]))
                   for k, p in prob.nl])
    x = x0
    if refine and prob.nl:
        if lf.many_records(prob):  # Newton steps (Nelder-Mead where refused)
            x1 = lf.polish(prob.objective, x0)
        else:
            x1 = prob._refine(prob.objective, x0, step=0.01, maxiter=15 * len(prob.nl))
        x = x1 if prob.objective(x1) <= prob.objective(x0) else x0
    p = prob.params(x)
    obj, sol, ang, layout = prob.evaluate(p)
    if sol is None or not math.isfinite(obj):
        return None, dict(params), ["the model cannot be built on this split"], prob.n_eval
    _, g_held = lp._gaps(lf, preps, sol, ang, nominal["limb"], cfg, split)
    _, n_held = lp._nominal_on(lf, preps, nominal, cfg, split)
    share = None if n_held <= 0 else 1.0 - g_held.value / n_held
    out = {k: lp._reported(lf, preps, k, p[k], sol.coef, layout) for k in names}
    flags = []
    for k in names:
        flags += [f"{k}: {m}" for m in cat.at_search_bound(k, out[k])]
        flags += [f"{k}: {g} < 0 (unphysical)" for g in lf.LINEAR.get(k, ()) if out[k][g] < 0]
    return share, out, flags, prob.n_eval


def _candidates(named, fits, pairs):
    """(effects, params {effect: params}, own reduction, flagged, fit) of every
    alternative to ``named`` (module docstring)."""
    eff = tuple(named.effects) if hasattr(named, "effects") else (named.effect,)
    out = []
    for f in fits:
        if f.effect in eff or not math.isfinite(f.calibration_objective):
            continue
        out.append(((f.effect,), {f.effect: dict(f.params)}, f.held_out_reduction,
                    bool(f.at_search_bound), f))
    if len(eff) > 1:
        for p in pairs:
            if tuple(p.effects) == eff or not math.isfinite(p.calibration_objective):
                continue
            out.append((tuple(p.effects), {k: dict(v) for k, v in p.params.items()},
                        p.held_out_reduction, bool(p.at_search_bound), p))
    return out


def score_task(lf, preps, nominal, cfg, params, split_effects):
    """:func:`score` of ``params`` on the split of ``split_effects`` (:func:`split_of`),
    as a task (picklable arguments and result)."""
    return score(lf, preps, params, nominal, cfg, split_of(preps, split_effects, cfg)[0])


def alternatives(lf, preps, nominal, cfg, named, fits, pairs=(), *,
                 tie_share: float = ties.TIE_SHARE, run=None) -> dict:
    """The alternatives to ``named`` (a limbfit.EffectFit of ``fits`` or a
    limbpairs.PairFit of ``pairs``), each on the named fit's split, judged
    (diagnosis.ties.judge). Returns {"rows" (best first), "indistinguishable" (the named
    fit's name and the tied alternatives', [] when none ties),
    "split" (in words), "named_held_out_reduction", "n_evaluations"}.

    ``run(fn, arg_tuples, desc)``, optional: ``[fn(lf, preps, nominal, cfg, *a) for a in
    arg_tuples]``, e.g. on worker processes holding the same records (every score is an
    independent task, :func:`score_task`); default: in this process."""
    eff = tuple(named.effects) if hasattr(named, "effects") else (named.effect,)
    params = ({k: dict(v) for k, v in named.params.items()} if len(eff) > 1
              else {eff[0]: dict(named.params)})
    split, text = split_of(preps, eff, cfg)
    share = named.held_out_reduction
    band = min(pr.band for pr in preps)
    rows, n_eval = [], 0
    # the scores needed first (independent tasks: ``run`` may map them on workers), then
    # the rows in the candidates' order
    cands = [(c, split_of(preps, c[0], cfg)) for c in _candidates(named, fits, pairs)]
    tasks, own_task, named_task = [], {}, {}
    for i, ((a_eff, a_params, own, _, _), (a_split, a_text)) in enumerate(cands):
        if same_split(preps, split, a_split):
            continue
        own_task[i] = len(tasks)
        tasks.append((a_params, eff))       # the alternative on the named fit's split
        # for the reader, not the rule: the named model on the alternative's split,
        # where the alternative's own figure comes within the margin of the named one's
        # (the comparison the ranking invites)
        near = own is not None and share is not None and own >= share - tie_share
        if near and a_text not in named_task:
            named_task[a_text] = len(tasks)
            tasks.append((params, a_eff))
    if run is None:
        def run(fn, arg_tuples, desc=""):
            return [fn(lf, preps, nominal, cfg, *a) for a in arg_tuples]
    scores = run(score_task, tasks, "limbties scores") if tasks else []
    n_eval += sum(k for _, _, _, k in scores)
    for i, ((a_eff, a_params, own, flagged, _), (a_split, a_text)) in enumerate(cands):
        if i not in own_task:
            rows.append(ties.row(a_eff, a_params, own, share, split=text,
                                 nameable=not flagged))
            continue
        s, shown, flags, _ = scores[own_task[i]]
        near = own is not None and share is not None and own >= share - tie_share
        # judged as fitted on the named split: a fit on a search bound of its own split
        # may be inside its bounds there (and the other way round)
        r = ties.row(a_eff, shown, s, share, split=text, own_split=a_text,
                     own_share=own, rescored=True, nameable=not flags)
        r["named_on_own_split"] = scores[named_task[a_text]][0] if near else None
        rows.append(r)
    rows = ties.judge(rows, eff, params, tie_share, band_hz=band)
    return {"rows": rows, "indistinguishable": ties.indistinguishable(rows, eff), "split": text,
            "named_held_out_reduction": share, "n_evaluations": n_eval}
