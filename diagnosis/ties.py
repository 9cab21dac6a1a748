"""Ties and alternatives (issue 21, item 3): when another effect, or pair, explains the
held-out gap about as well as the named one, the verdict says that these trials cannot
tell them apart and what experiment would.

One shape for every experiment. An *alternative* is a row

    {"effects": [...], "name": "A" or "A + B", "params": {effect: {param: value}},
     "held_out_reduction": its reduction of the held-out gap ON THE NAMED FIT'S SPLIT,
     "named_held_out_reduction": the named fit's, on the same split,
     "points_behind": 100 (named - alternative), "split": that split, in words,
     "own_split": the alternative's own held-out split (None: the same),
     "own_held_out_reduction": its reduction there (as the ranking shows it),
     "named_on_own_split": the named model's reduction there (a re-solved row whose
     own figure comes within the margin of the named one's; for the reader, not the
     rule),
     "rescored": True when it was solved again on the named fit's split,
     "nameable": False for a fit with a flag (a search bound, a negative gain),
     "indistinguishable": bool, "closes_more": bool, "separate": what would separate it
     from the named one (text, None when not indistinguishable)}

The rule (:func:`judge`): a nameable alternative whose held-out reduction on the named
fit's split is at least the named one's minus :data:`TIE_SHARE` (5 points) is
*indistinguishable*; one that closes more there ("closes_more") too: the calibration
data prefer the named fit, the held-out data do not. The exoskeleton's fits all share
one held-out split (the evaluators' units), so its rows are read from the ranking
(:func:`rows_from_fits`); a position servo's time- and state-varying effects are judged
on splits of their own, so their reductions are not comparable with the others' and
diagnosis.limbties solves every alternative again on the named fit's split first.

What separates two effects (:func:`separation`) is specific to the pair: where in
frequency, amplitude, posture or time their models differ, e.g. a channel delay and a
first-order torque-sensor lag (both a phase lag growing with frequency) differ in
magnitude only around and above the sensor's corner 1 / (2 pi T).
"""

from __future__ import annotations

import math

#: an alternative within this share of the nominal held-out gap (5 points of reduction)
#: of the named fit, on the named fit's split, cannot be told from it on these trials
TIE_SHARE = 0.05

#: effect families (for the separation advice)
CHANNEL = ("channel_delay", "torque_sensor_lag", "delay", "actuator_lag")
TIME_VARYING = ("stiffness_drift", "stiffness_saturating", "stiffness_switching",
                "stiffness_modulated")
STATE_VARYING = ("stiffness_angle", "stiffness_torque")
MECHANICAL = ("wobbling_mass", "inertia_mismatch", "transmission_compliance",
              "interface_compliance")

GENERIC = ("a perturbation with a wider band, a recorded reference (an independent torque "
           "or angle sensor) or another amplitude would separate them")


def name_of(effects) -> str:
    return " + ".join(effects)


def row(effects, params, share, named_share, *, split, own_split=None, own_share=None,
        rescored=False, nameable=True) -> dict:
    """One alternative (module docstring); ``judge`` fills the verdict fields."""
    ok = share is not None and math.isfinite(share)
    return {"effects": list(effects), "name": name_of(effects),
            "params": {k: dict(v) for k, v in (params or {}).items()},
            "held_out_reduction": float(share) if ok else None,
            "named_held_out_reduction": None if named_share is None else float(named_share),
            "points_behind": (100.0 * (float(named_share) - float(share))
                              if ok and named_share is not None else None),
            "split": split, "own_split": own_split,
            "own_held_out_reduction": None if own_share is None else float(own_share),
            "named_on_own_split": None,
            "rescored": bool(rescored), "nameable": bool(nameable),
            "indistinguishable": False, "closes_more": False, "separate": None}


def judge(rows, named_effects, named_params, tie_share: float = TIE_SHARE,
          band_hz: float | None = None) -> list:
    """Fill ``indistinguishable``, ``closes_more`` and ``separate`` of every row (in
    place) and return the rows sorted best first (on the named fit's split)."""
    for r in rows:
        s, n = r["held_out_reduction"], r["named_held_out_reduction"]
        tie = bool(r["nameable"] and s is not None and n is not None and s >= n - tie_share)
        r["indistinguishable"] = tie
        r["closes_more"] = bool(tie and s > n)
        r["separate"] = (separation(named_effects, named_params, r["effects"], r["params"],
                                    band_hz) if tie else None)
    return sorted(rows, key=lambda r: -(r["held_out_reduction"]
                                        if r["held_out_reduction"] is not None else -math.inf))


def indistinguishable(rows, named=None) -> list:
    """The models these trials cannot tell apart: the named one (``named``, its effects)
    first, then the tied alternatives, best first; [] when no alternative ties."""
    tied = [r["name"] for r in rows if r["indistinguishable"]]
    if not tied:
        return []
    return ([name_of(named)] if named else []) + tied


def sentence(named, rows, tie_share: float = TIE_SHARE) -> str:
    """The summary's sentence of the ties ("" when none): the shares on the named fit's
    split, which closes more, and per alternative what would separate it."""
    tied = [r for r in rows if r["indistinguishable"]]
    if not tied:
        return ""
    nm = name_of(named)
    n = tied[0]["named_held_out_reduction"]
    split = tied[0]["split"]
    parts = []
    near = [r for r in tied if not r["closes_more"]]
    more = [r for r in tied if r["closes_more"]]
    if near:
        parts.append(", ".join(f"{r['name']} ({_pct(r['held_out_reduction'])} %)" for r in near)
                     + f" close{'s' if len(near) == 1 else ''} the held-out gap within "
                     f"{100 * tie_share:.0f} points of {nm} ({_pct(n)} %)")
    if more:
        parts.append(", ".join(f"{r['name']} ({_pct(r['held_out_reduction'])} %)" for r in more)
                     + f" close{'s' if len(more) == 1 else ''} more of it than {nm} "
                     f"({_pct(n)} %), which fits the calibration data better")
    text = (f"Indistinguishable here: on the named fit's held-out split ({split}), "
            + "; ".join(parts) + ": these trials cannot tell them apart.")
    for r in tied:
        text += f" To separate {nm} from {r['name']}: {r['separate']}."
    return text


def _pct(share) -> str:
    if share is None or not math.isfinite(share):
        return "-"
    from .pipeline.verdict import _digits
    v = 100 * share
    if 0.99 <= share < 1.0:
        return f"{v:.{_digits(share)}f}"
    return f"{v:.1f}" if abs(v) < 10 else f"{v:.0f}"


def rows_from_fits(chosen, singles, pairs, g0_held) -> list:
    """Alternatives of ``chosen`` (a fitting.EffectFit) read from the ranking: every
    single and pair fit that is not the named one and does not merely contain its effects
    (a single inside a named pair is the pair's own first step), all on the split the
    ranking shares (the exoskeleton's; a position servo's default-split fits)."""
    from .pipeline.how_far import reduction
    named = tuple(chosen.effects)
    share = reduction(g0_held, chosen.held_out_gap)
    out = []
    for f in list(singles) + list(pairs):
        eff = tuple(f.effects)
        if eff == named or set(eff) <= set(named) or set(named) <= set(eff):
            continue
        out.append(row(eff, getattr(f, "params", {}), reduction(g0_held, f.held_out_gap), share,
                       split="the held-out units every fit shares",
                       nameable=bool(getattr(f, "nameable", True))))
    return out


# ----------------------------------------------------------------------------- advice
def _p(params, effect, key):
    try:
        return float(params[effect][key])
    except (KeyError, TypeError, ValueError):
        return None


def _corner(effect, params):
    """The corner frequency [Hz] of a first-order lag effect (1 / (2 pi T)), or None."""
    for key in ("time_constant_s",):
        v = _p(params, effect, key)
        if v and v > 0 and effect in ("torque_sensor_lag", "actuator_lag"):
            return 1.0 / (2 * math.pi * v)
    return None


def _paren(first: str | None, band_hz) -> str:
    """`` (first; these trials are analysed to B Hz)``, either part optional."""
    parts = [x for x in (first, None if not band_hz else
                         f"these trials are analysed to {band_hz:.0f} Hz") if x]
    return f" ({'; '.join(parts)})" if parts else ""


def separation(a_effects, a_params, b_effects, b_params, band_hz: float | None = None) -> str:
    """What experiment would separate the model ``a`` from ``b`` (each: effects and
    {effect: params}): the first rule that applies to an effect of ``a`` against one of
    ``b`` that differs from it (the effects both share separate nothing), else
    :data:`GENERIC`."""
    a_only = [e for e in a_effects if e not in b_effects] or list(a_effects)
    b_only = [e for e in b_effects if e not in a_effects] or list(b_effects)
    params = {**(b_params or {}), **(a_params or {})}
    for a in a_only:
        for b in b_only:
            text = _pair_advice(a, b, params, band_hz) or _pair_advice(b, a, params, band_hz)
            if text:
                return text
    return GENERIC


def _pair_advice(a, b, params, band_hz):  # noqa: C901 - one rule per pair of families
    """The advice for effects ``a`` and ``b`` (None: no rule for this order)."""
    pair = {a, b}
    if pair == {"channel_delay", "torque_sensor_lag"} or pair == {"delay", "actuator_lag"} \
            or pair == {"delay", "torque_sensor_lag"} or pair == {"actuator_lag",
                                                                  "torque_sensor_lag"}:
        lag = next(e for e in (a, b) if e in ("torque_sensor_lag", "actuator_lag"))
        fc = _corner(lag, params)
        where = _paren(f"1 / (2 pi T) = {fc:.0f} Hz for the fitted lag" if fc else None,
                       band_hz)
        if pair == {"actuator_lag", "torque_sensor_lag"}:
            return (f"a recorded motor command or current beside the torque sensor, or a "
                    f"perturbation band above the lag's corner{where}: one lag acts on the "
                    f"applied torque, the other only on its measurement")
        if lag == "actuator_lag":
            return (f"a perturbation band reaching above the actuator lag's corner{where}, "
                    f"where a first-order lag attenuates the applied torque and a pure "
                    f"delay does not (both are a phase lag growing with frequency below "
                    f"it); or a recorded motor current answering a command step")
        return (f"a perturbation band reaching above the sensor's corner{where}, where a "
                f"first-order lag attenuates the torque and a pure delay does not (both "
                f"are a phase lag growing with frequency below it); or a step or "
                f"calibration test of the torque channel alone")
    if a in CHANNEL and b == "servo_bandwidth":
        return ("an independent angle sensor at the limb, or the servo's tracking recorded "
                "without the limb (theta_ref against theta): a servo lag changes the "
                "imposed angle, a torque-channel lag only the measured torque")
    if a in CHANNEL and b in ("wobbling_mass", "inertia_mismatch"):
        f = _p(params, "wobbling_mass", "frequency_hz")
        at = _paren(f"fitted at {f:.1f} Hz" if f else None, band_hz)
        return (f"a perturbation band reaching through and beyond the mass's resonance"
                f"{at}, where an inertia changes the torque's magnitude and a channel lag "
                f"only its phase; or a run of the apparatus without the limb (a channel "
                f"lag stays, a soft-tissue mass goes)")
    if a == "stretch_reflex":
        if b in TIME_VARYING + STATE_VARYING + ("stiffness_amplitude",):
            return ("a recorded EMG of the stretched muscle (a reflex shows at its delay), "
                    "or trials held at fixed angles and background torques (a varying "
                    "stiffness follows the state; a reflex follows the stretch velocity, "
                    "rectified, so another velocity amplitude changes it)")
        if b in CHANNEL:
            return ("trials with the subject relaxed and active (a reflex changes with "
                    "the background contraction, a channel lag does not), or a recorded "
                    "EMG; a perturbation without power near the reflex's loop frequency "
                    "removes it")
        return ("a recorded EMG of the stretched muscle, or the same perturbation with the "
                "subject relaxed and active (a reflex changes with the contraction, a "
                "mechanical effect does not), or another velocity amplitude (a rectified "
                "reflex grows with it)")
    if a == "stiffness_amplitude" or b == "stiffness_amplitude":
        return ("trials at another perturbation amplitude (at least twice or half this "
                "one's): an amplitude-dependent stiffness changes with it, the other "
                "effect does not")
    if a in TIME_VARYING and b in TIME_VARYING:
        return ("a longer recording, or repeated trials over the same time: a drift that "
                "settles, a switch and a modulation part ways after one time constant, "
                "level or period")
    if a in TIME_VARYING and b in STATE_VARYING:
        return ("the movement repeated in another order or at another rate (an angle- or "
                "torque-dependent stiffness follows the state, a time variation the "
                "clock), or trials held at fixed angles")
    if pair == {"stiffness_angle", "stiffness_torque"}:
        return ("trials at one angle with different background torques, or the same "
                "angles at another background torque")
    if pair == {"transmission_compliance", "interface_compliance"}:
        return ("an encoder on the link (or the arm) besides the motor's, or a trial with "
                "the arm detached (the cuff's compliance goes, the transmission's stays)")
    if pair == {"gravity", "inertia_mismatch"}:
        return ("trials at other postures or a slower perturbation: gravity depends on the "
                "angle, an inertia error on the acceleration")
    if a == "friction" and b in ("quantization", "sensor_noise"):
        return ("another perturbation amplitude or velocity: friction's share changes with "
                "the velocity, a resolution or noise floor does not")
    if a in CHANNEL and b in CHANNEL:
        return (f"a perturbation band reaching higher{_paren(None, band_hz)}, where the two "
                f"lags' phases and magnitudes part")
    return None
