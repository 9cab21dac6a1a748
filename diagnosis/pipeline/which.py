"""Stage 6, which: every applicable catalogue effect fitted alone on the calibration
units (each task also gives its held-out gap), ranked by calibration gap; pairs of the
top-ranked when the best single leaves a significant gap (forward selection, then one
coordinate step of the first effect)."""

from __future__ import annotations

import math

from .. import catalogue as cat
from ..tasks import task_fit_second, task_fit_single, task_refine_pair


def residual_needs_pair(best, cfg) -> bool:
    """A pair is tried when the best single leaves a calibration gap that is still
    significant (above the nominal-vs-nominal threshold): whatever is left is more than
    noise, however much the single closed."""
    return best.calibration_gap > cfg.significance_gap


def run(r) -> None:
    """Fill ``r.singles`` and ``r.pairs`` (sorted by calibration gap, then objective).

    An experiment with its own fits (``fit_effects``, e.g. the position servo's variable
    projection) gives the fits, their held-out gaps and the nominal gaps of its measure.
    """
    own = getattr(r.experiment, "fit_effects", None)
    if own is not None:
        out = own(r.trials, r.effects, r.config, store=r.resume, runner=r.runner)
        r.singles, r.pairs = out["fits"], list(out.get("pairs", []))
        r.g0_cal, r.g0_held, r.significant = out["g0_cal"], out["g0_held"], out["significant"]
        r.fit_measure = {k: v for k, v in out.items()
                         if k not in ("fits", "pairs", "nominal_limb", "alternatives")}
        # the experiment's own judge of the named fit's alternatives (verdict stage)
        r.alternatives = out.get("alternatives")
        r.n_worker_sims += sum(f.n_evaluations for f in r.singles + r.pairs)
        return
    norms = (r.ev_cal.norms, r.ev_held.norms)
    key = lambda f: (f.calibration_gap, f.objective)  # noqa: E731
    # the costliest (scalar searches) first so that the workers stay busy
    order = sorted(r.effects, key=lambda n: cat.get_effect(n).fit != "scalar")
    singles = r.map(task_fit_single, [(n,) + norms for n in order], "effects")
    r.n_worker_sims += sum(f.n_evaluations for f in singles)
    singles.sort(key=key)
    pairs = []
    best = next((f for f in singles if f.nameable), None)
    if r.significant and best is not None and residual_needs_pair(best, r.config):
        partners = [f.effects[0] for f in singles
                    if f is not best and math.isfinite(f.calibration_gap)]
        seconds = r.map(task_fit_second, [(best, o) + norms for o in partners], "pairs")
        r.n_worker_sims += sum(f.n_evaluations for f in seconds)
        seconds.sort(key=key)
        if seconds:
            refined = r.map(task_refine_pair, [(seconds[0],) + norms], "pair refit")[0]
            r.n_worker_sims += refined.n_evaluations - seconds[0].n_evaluations
            pairs = [refined] + seconds[1:]
        pairs.sort(key=key)
    r.singles, r.pairs = singles, pairs
