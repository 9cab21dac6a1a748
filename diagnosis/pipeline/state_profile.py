"""K over the scheduling variable for a named state-varying effect (issue 20): the named
model's stiffness K0 (1 + s (rho - rho_mid) + c (rho - rho_mid)^2) at the points
``armimp estimate`` reports its parameter-varying K(rho) at, beside that estimate with its
95 % intervals, so the two commands' answers on one recording can be read side by side.

The estimate is estimation.varying's Chebyshev expansion (with the reflex pathway when
the named model has a stretch reflex), the diagnosis's the catalogue's quadratic form
fitted inside limbfit: two forms, two fits, one limb.
"""

from __future__ import annotations

import numpy as np

#: the state-varying effects whose stiffness this profiles (diagnosis.varying_effects)
STATE_EFFECTS = ("stiffness_angle",)
#: points over the calibration's 1-99 % range when the estimate gives none
N_POINTS = 7


def _named_k(k0: float, p: dict, rho) -> np.ndarray:
    d = np.asarray(rho, float) - float(p["rho_mid"])
    return k0 * (1.0 + float(p["slope_rel"]) * d + float(p["curvature_rel"]) * d * d)


def _estimate(trials, reflex: bool):
    """The first parameter-varying estimate of ``trials`` (estimation.pvlab), or None."""
    from estimation.pvlab import varying_of_trials
    from types import SimpleNamespace
    fits, _ = varying_of_trials(trials, SimpleNamespace(reflex=reflex))
    return fits[0] if fits else None


def _band(replicates, name, rho):
    """Jackknife standard errors (P,) of K(rho) over the fit's replicates, or None."""
    if not replicates or any(name not in r for r in replicates):
        return None
    from ..limbfit import jackknife_se
    return jackknife_se([_named_k(r["K"], r[name], rho) for r in replicates])


def _form_widening(replicates, k0_interval) -> tuple[float, float]:
    """(below, above): the part of K0's reported interval that its own-form jackknife
    does not give (the form envelope and the derivative allowance of
    limbpairs.add_intervals), relative to K0, combined in quadrature below and above.

    K(rho)'s band takes the same relative widening: the form's choices scale the whole
    curve, not only its value at rho_mid. Zero without replicates or a K0 interval."""
    if not replicates or k0_interval is None or len(k0_interval) < 3 \
            or k0_interval[1] is None:
        return 0.0, 0.0
    from ..limbfit import jackknife_se
    k0, lo, hi = (float(v) for v in k0_interval[:3])
    own = 1.96 * float(jackknife_se([r["K"] for r in replicates]))
    extra = [max(0.0, w * w - own * own) ** 0.5 / k0 for w in (k0 - lo, hi - k0)]
    return extra[0], extra[1]


def _interval(k, se, widen) -> list:
    """[value, lo, hi] of K at one point: 1.96 se in quadrature with the widening."""
    if se is None:
        return [float(k), None, None]
    below = np.hypot(1.96 * se, widen[0] * k)
    above = np.hypot(1.96 * se, widen[1] * k)
    return [float(k), float(k - below), float(k + above)]


def profile(trials, named_model: dict, scheduling: list, replicates=None) -> dict | None:
    """``{"scheduling", "units", "form", "points": [{"rho", "K": [v, lo, hi],
    "K_estimate": [v, lo, hi] | None}], "estimate": {...} | None, "agreement",
    "reflex": {"named", "estimate"} | None}`` (each reflex's delay_ms, frequency_hz,
    damping and effective_ms: the delay plus its activation's low-frequency group delay) for a
    named state-varying effect, else None.

    ``trials``: the diagnosed (convention-corrected) trials; ``named_model``: the
    report's ``named_model`` (K in N m/rad, effect parameters as ``[value, lo, hi]``);
    ``scheduling``: the report's ``scheduling`` entries (name, units per trial).
    ``agreement``: the share of points where the named K lies inside the estimate's
    interval. ``replicates`` ([{"K": K0, effect: params}], a pair's jackknife,
    diagnosis.limbpairs.add_intervals): K's 95 % band, 1.96 jackknife standard errors of
    K(rho) over them, widened in quadrature by the share of K0's reported interval the
    jackknife does not give (the form envelope, the derivative allowance:
    ``_form_widening``); without them K's interval is None."""
    effects = (named_model or {}).get("effects") or {}
    name = next((e for e in STATE_EFFECTS if e in effects), None)
    if name is None or len(trials) != 1 or trials[0].n_dof != 1:
        return None
    p = {k: (v[0] if isinstance(v, list) else v) for k, v in effects[name].items()}
    k0 = float(named_model["K"][0])  # one joint: one [value, low, high]
    try:
        est = _estimate(trials, "stretch_reflex" in effects)
    except Exception as exc:  # the estimate is a comparison: its failure is said, not fatal
        est, why = None, f"{type(exc).__name__}: {exc}"
    else:
        why = None if est is not None else "the estimate gave no parameter-varying fit"
    if est is not None:
        rho = np.asarray(est.rho, float)
    else:
        mid, half = float(p["rho_mid"]), float(p["rho_half_range"])
        rho = np.linspace(mid - half, mid + half, N_POINTS)
    k = _named_k(k0, p, rho)
    se = _band(replicates, name, rho)
    widen = _form_widening(replicates, named_model.get("K"))
    pts = []
    for i, r in enumerate(rho):
        pt = {"rho": float(r), "K": _interval(k[i], None if se is None else se[i], widen)}
        pt["K_estimate"] = (None if est is None else
                            [float(est.values["K"][i]), float(est.lo["K"][i]),
                             float(est.hi["K"][i])])
        pts.append(pt)
    inside = [pt["K_estimate"][1] <= pt["K"][0] <= pt["K_estimate"][2]
              for pt in pts if pt["K_estimate"] is not None]
    # the two 95 % intervals overlap (where the named one is known)
    overlap = [max(pt["K_estimate"][1], pt["K"][1]) <= min(pt["K_estimate"][2], pt["K"][2])
               for pt in pts if pt["K_estimate"] is not None and pt["K"][1] is not None]
    reflex = None
    if "stretch_reflex" in effects:
        from .report import reflex_latency
        rf = None if est is None else est.reflex
        from estimation.reflex import activation_lag_ms
        reflex = {"named": reflex_latency(effects["stretch_reflex"]),
                  "estimate": None if not rf else {
                      "delay_ms": rf["delay_ms"], "frequency_hz": rf["cutoff_hz"],
                      "damping": rf["damping"],
                      "effective_ms": rf["delay_ms"]
                      + activation_lag_ms(rf["cutoff_hz"], rf["damping"])}}
    sch = next((s for s in scheduling or [] if s.get("trial") == trials[0].name), {})
    return {"scheduling": sch.get("name", "rho"), "units": sch.get("units", ""),
            "effect": name,
            "form": f"K0 (1 + s (rho - rho_mid) + c (rho - rho_mid)^2), K0 = {k0:.4g} N m/rad",
            "points": pts,
            "estimate": None if est is None else {
                "method": f"armimp estimate's parameter-varying fit (Chebyshev order "
                          f"{est.order}{', with the reflex pathway' if est.reflex else ''}; "
                          f"95 % jackknife intervals)",
                "heldout_vaf_pct": est.heldout_vaf_pct},
            "estimate_missing": why,
            # the two reflex pathways' delays: pure, and with the activation's lag
            "reflex": reflex,
            "agreement": None if not inside else float(np.mean(inside)),
            "intervals_overlap": None if not overlap else float(np.mean(overlap))}
