"""Stage 7, how far: the gap reduction of every fitted model on the calibration units
and, the headline, on the held-out units the fit did not see."""

from __future__ import annotations

import math

import numpy as np


def reduction(before: float, after: float) -> float:
    """(before - after) / before; -inf for a diverging model, 0 without a gap."""
    if not np.isfinite(after):
        return -math.inf
    if before <= 0:
        return 0.0
    return float((before - after) / before)


def ranking_row(fit, g0_cal: float, g0_held: float) -> dict:
    """One row of the report's ranking table."""
    return {"effects": list(fit.effects), "params": fit.params,
            "calibration_gap": fit.calibration_gap,
            "calibration_reduction": reduction(g0_cal, fit.calibration_gap),
            "held_out_gap": fit.held_out_gap,
            "held_out_reduction": reduction(g0_held, fit.held_out_gap),
            "n_simulations": fit.n_evaluations,
            "at_search_bound": fit.at_search_bound,
            # the flags' parts, to format them again with the values in the file's units
            "flag_notes": fit.flag_notes(),
            # a search range widened because the best fit lay on its bound (fitting.py)
            **({"widened": fit.widening_notes(), "widenings": fit.widenings,
                "searched": fit.searched} if getattr(fit, "widenings", None) else {}),
            **({"intervals": fit.intervals} if getattr(fit, "intervals", None) else {}),
            # which tied choices the intervals were profiled over (diagnosis.formprofile)
            **({"form_profile": fit.form_profile} if getattr(fit, "form_profile", None)
               else {}),
            # the held-out split of a varying effect (diagnosis.varying_effects) and why
            **({"split": fit.split} if getattr(fit, "split", None) else {}),
            # a position pair's second effect on held-out data (diagnosis.limbpairs)
            **({"second_effect_test": fit.second_test}
               if getattr(fit, "second_test", None) else {}),
            **({"preferred_over": fit.preferred_over}
               if getattr(fit, "preferred_over", None) else {})}


def run(r) -> None:
    """Fill ``r.ranking`` and ``r.pair_rows``."""
    r.ranking = [ranking_row(f, r.g0_cal, r.g0_held) for f in r.singles]
    r.pair_rows = [ranking_row(f, r.g0_cal, r.g0_held) for f in r.pairs]
