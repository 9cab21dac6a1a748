"""The catalogue of unmodelled effects, as the diagnosis sees it (docs/diagnosis.md).

Every effect of docs/spec/effects.md is described here once, as data: its parameters,
the *realistic magnitudes* the validation draws from, the bounds a fit searches, and how
the fit treats it. Each effect is fitted in a one-parameter family per *primary* parameter:
per-joint parameters are one value broadcast to every joint, and secondary parameters
(dampings, friction shape) are tied to the primary one by the fixed ratios below, which
the validation's truth models obey as well.

Effects of the position-servo experiments (``kinds`` contains ``"position"``: the limb's
own effects and the servo's apparatus, diagnosis.limb) are fitted jointly in all their
primary parameters, with the limb's K, B, I re-estimated alongside, by diagnosis.limbfit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import DiagnosisInputError

# Tied secondary parameters (documented in docs/diagnosis.md).
FRICTION_FS_OVER_FC = 1.5          # Fs = 1.5 Fc, as in every reference level
FRICTION_SIGMA2_OVER_FC = 0.2      # sigma2 [N m s/rad] = 0.2 [s/rad] * Fc
TRANSMISSION_DAMPING_TIME_S = 1e-3  # c_t = 1 ms * k_t
INTERFACE_DAMPING_TIME_S = 5e-3     # c_s = 5 ms * k_s

# A fitted value within this fraction of the search span (log span for log parameters)
# of a search bound is "at search bound": the fit wanted to go further. Inside the
# parameter's physical limits the search then widens (fitting.py, at most MAX_WIDENINGS
# times, each by WIDENING_SPAN of the declared search span); a value still on the bound
# of the widest search, or on a physical limit, is absorbing model error rather than
# measuring the effect, and the effect is not named.
BOUND_TOLERANCE = 0.02
MAX_WIDENINGS = 2
WIDENING_SPAN = 0.5
INF = math.inf


@dataclass(frozen=True)
class Parameter:
    """One fitted (primary) parameter of an effect.

    Attributes
    ----------
    name : str
        Key in the effect's parameter dict (effects.md).
    unit : str
    realistic : tuple of float
        (low, high) range the validation draws from.
    bounds : tuple of float
        (low, high) range a fit searches (wider than ``realistic``).
    log : bool
        Draw and search on a log scale.
    off : float
        The value meaning "effect absent" (used for relative parameter errors).
    scored : bool
        Counted in the parameter-error target; False for a parameter the experiment
        cannot identify (documented in docs/diagnosis.md), which is still reported.
    detectable_from : float or None
        Measured detectability floor (bench/bench_diagnosis.py --calibrate, 2 trials of
        12 s, perturbation level 3): weaker values give a nominal gap below the
        significance threshold, so a validation set drawn there is reported but not
        counted as a miss, and a pair's second effect fitted there is not named
        (core._pair_earns_second). None: no floor measured inside the search range.
    physical_low : bool
        The lower bound is a physical limit (not flagged "at search bound").
    draw_log : bool
        Draw the realistic magnitude log-uniformly although the search is linear (a
        parameter whose search range straddles ``off``, e.g. a channel delay of either
        sign).
    physical : tuple of float
        (low, high) physical limits, apart from the search range (which they contain):
        a search widens up to them, a value on one (or beyond) is not named. ``-inf`` /
        ``inf`` where physics sets none (a widening then stops after MAX_WIDENINGS).
    """

    name: str
    unit: str
    realistic: tuple
    bounds: tuple
    log: bool = True
    off: float = 0.0
    scored: bool = True
    detectable_from: float | None = None
    physical_low: bool = False
    draw_log: bool = False
    physical: tuple | None = None

    def __post_init__(self):
        if self.physical is None:
            raise ValueError(f"parameter {self.name!r}: declare its physical limits "
                             f"(physical=(low, high), -inf/inf where physics sets none)")
        lo, hi = self.physical
        if not (lo <= self.bounds[0] <= self.bounds[1] <= hi):
            raise ValueError(f"parameter {self.name!r}: search bounds {self.bounds} lie "
                             f"outside its physical limits {self.physical}")
        if self.log and not lo >= 0:
            raise ValueError(f"parameter {self.name!r}: a log-scale search needs a "
                             f"physical lower limit >= 0, not {lo}")

    def physical_hit(self, value: float, tol: float = BOUND_TOLERANCE,
                     bounds: tuple | None = None) -> str | None:
        """``"non-physical"`` beyond the physical limits (or not finite), ``"lower"`` /
        ``"upper"`` on a finite physical limit (within ``tol`` of the span of ``bounds``,
        default the declared search range, on the search scale), else None. A lower
        limit that is the effect's smallest member (``physical_low``) is never hit."""
        lo, hi = self.physical
        v = float(value)
        if not math.isfinite(v) or v < lo or v > hi:
            return "non-physical"
        b = bounds or self.bounds
        if hi < INF and b[1] >= hi and self._near(v, b, tol) == "upper":
            return "upper"
        if lo > -INF and b[0] <= lo and not self.physical_low \
                and self._near(v, b, tol) == "lower":
            return "lower"
        return None

    def widened(self, bounds: tuple, side: str) -> tuple | None:
        """``bounds`` widened on ``side`` by WIDENING_SPAN of the declared search span
        (search scale), clipped to the physical limits; None when that side already is
        a physical limit."""
        lo, hi = (float(v) for v in bounds)
        if side == "upper" and hi >= self.physical[1]:
            return None
        if side == "lower" and lo <= self.physical[0]:
            return None
        if self.log:
            step = WIDENING_SPAN * math.log(self.bounds[1] / self.bounds[0])
            if side == "upper":
                return (lo, min(self.physical[1], hi * math.exp(step)))
            return (max(self.physical[0], lo * math.exp(-step)), hi)
        step = WIDENING_SPAN * (self.bounds[1] - self.bounds[0])
        if side == "upper":
            return (lo, min(self.physical[1], hi + step))
        return (max(self.physical[0], lo - step), hi)

    def _near(self, value: float, bounds: tuple, tol: float) -> str | None:
        """``"lower"``/``"upper"`` when ``value`` lies within ``tol`` of the span of
        ``bounds`` (search scale) of that bound or beyond it."""
        lo, hi = bounds
        if self.log:
            if not value > 0:
                return "lower"
            lo = max(lo, 1e-300)  # a physical lower limit of 0
            x, xlo, xhi = math.log(value), math.log(lo), math.log(hi)
        else:
            x, xlo, xhi = float(value), float(lo), float(hi)
        margin = tol * (xhi - xlo)
        if x >= xhi - margin:
            return "upper"
        if x <= xlo + margin:
            return "lower"
        return None

    def search_bound_hit(self, value: float, tol: float = BOUND_TOLERANCE,
                         bounds: tuple | None = None) -> str | None:
        """``"lower"``/``"upper"`` when ``value`` lies on (within ``tol`` of the search
        span) or beyond that bound of the search ``bounds`` (default: the declared
        search range), else None.

        The span is measured on the search scale (log for log parameters); a lower bound
        flagged ``physical_low`` is never reported.
        """
        if self.log and not value > 0:
            return None if self.physical_low else "lower"
        side = self._near(float(value), bounds or self.bounds, tol)
        return None if side == "lower" and self.physical_low else side


@dataclass(frozen=True)
class Effect:
    """A catalogue effect: name, physics, primary parameters and fit strategy.

    Attributes
    ----------
    name : str
    physics : str
    parameters : tuple of Parameter
        Primary parameters (one value each, broadcast to joints).
    fit : str
        ``"scalar"`` (bounded 1-D search by re-simulation), ``"integer"`` (try each
        integer in bounds), ``"grid"`` (read from the sample grid of the data, no search),
        ``"noise"`` (read from the noise floors, then refined by re-simulation).
    needs_robust_tuning : callable or None
        f(params) -> True when a lab would have had to run the robust tuning.
    sign_choice : bool
        Realistic values lie on both sides of ``off`` (inertia scale).
    kinds : tuple of str
        Experiment kinds the effect applies to: ``"exoskeleton"`` (IMBIC with torque
        perturbations, simulated by the plant FMU) and/or ``"position"`` (a position
        servo with a torque sensor, simulated by diagnosis.limb and fitted by
        diagnosis.limbfit).
    choices : dict
        Discrete parameters {name: (options...)} (e.g. a reflex rectified or not): drawn
        uniformly by the validation, chosen by the fit, reported, not in the 20 % target.
    """

    name: str
    physics: str
    parameters: tuple
    fit: str = "scalar"
    robust_above: dict = field(default_factory=dict)
    always_robust: bool = False
    sign_choice: bool = False
    kinds: tuple = ("exoskeleton",)
    choices: dict = field(default_factory=dict)

    def needs_robust_tuning(self, params: dict) -> bool:
        """True when the closed loop needs the robust tuning (effects.md) for ``params``."""
        if self.always_robust:
            return True
        return any(params[k] > v for k, v in self.robust_above.items())

    def expand(self, params: dict, n_dof: int = 2) -> dict:
        """Full effect dict for ``simulate_trial(effects=...)`` from primary values."""
        return expand_effect(self.name, params, n_dof)

    def draw(self, rng: np.random.Generator) -> dict:
        """Primary parameters drawn uniformly (log-uniformly) from the realistic ranges."""
        out = {}
        for p in self.parameters:
            lo, hi = p.realistic
            if self.fit == "integer":
                out[p.name] = int(rng.integers(int(lo), int(hi) + 1))
            elif p.log or p.draw_log:
                out[p.name] = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
            else:
                out[p.name] = float(rng.uniform(lo, hi))
            if self.sign_choice and rng.random() < 0.5:
                out[p.name] = float(2 * p.off - out[p.name])  # mirror about "off"
        for key, options in self.choices.items():
            out[key] = options[int(rng.integers(len(options)))]
        return out

    def applies_to(self, kind: str) -> bool:
        """True when the effect belongs to experiments of ``kind``."""
        return kind in self.kinds


def _p(*args, **kw) -> Parameter:
    return Parameter(*args, **kw)


#: physical limits of a magnitude (a stiffness, a time constant, a friction force)
POS = (0.0, INF)


CATALOGUE: dict[str, Effect] = {e.name: e for e in (
    Effect("friction", "LuGre friction in the robot joints beyond the declared friction",
           (_p("Fc", "N m", (0.1, 0.4), (0.02, 1.0), physical=POS),)),
    Effect("quantization", "encoder and torque-sensor resolution",
           (_p("encoder_resolution_deg", "deg", (1.758e-3, 7.031e-3), (1e-5, 0.1),
               physical=POS),
            _p("torque_resolution_nm", "N m", (0.005, 0.02), (1e-5, 0.5), physical=POS)),
           fit="grid"),
    Effect("sensor_noise", "white Gaussian noise on every encoder and torque sample",
           (_p("theta_noise_std_rad", "rad", (5e-6, 5e-5), (1e-7, 1e-3), physical=POS),
            _p("tau_noise_std_nm", "N m", (0.003, 0.03), (1e-5, 0.3), scored=False,
               physical=POS)),
           fit="noise"),
    Effect("delay", "the command of sample n acts from (n+d) Ts",
           (_p("samples", "samples", (1, 3), (1, 5), log=False, physical_low=True,
               physical=(1, INF)),),
           fit="integer",
           always_robust=True),
    Effect("actuator_lag", "first-order lag between command and applied torque",
           (_p("time_constant_s", "s", (1.5e-3, 6e-3), (2e-4, 2e-2), detectable_from=5e-4,
               physical=POS),),
           robust_above={"time_constant_s": 1e-3}),
    Effect("transmission_compliance",
           "spring-damper between motor and link; encoder on the motor side",
           (_p("k_t", "N m/rad", (150.0, 1000.0), (30.0, 5000.0), physical=POS),),
           always_robust=True),
    Effect("interface_compliance", "compliant cuff between robot link and arm",
           (_p("k_s", "N m/rad", (100.0, 600.0), (20.0, 3000.0), physical=POS),)),
    Effect("gravity", "robot plane tilted from horizontal; gravity on the robot links",
           (_p("tilt_deg", "deg", (2.0, 10.0), (0.2, 30.0), detectable_from=1.2,
               physical=(0.0, 90.0)),)),
    Effect("inertia_mismatch", "the robot's a1, a2, a3 scaled by s",
           (_p("scale", "-", (1.1, 1.3), (0.5, 2.0), log=False, off=1.0,
               detectable_from=1.07, physical=POS),),
           sign_choice=True),
    Effect("torque_sensor_lag", "first-order low-pass of the torque sensor",
           (_p("time_constant_s", "s", (5e-4, 4e-3), (5e-5, 2e-2), detectable_from=6e-4,
               physical=POS),),
           kinds=("exoskeleton", "position")),
    # --- the limb's own effects and the position servo's apparatus (diagnosis.limb) ---
    Effect("stretch_reflex",
           "delayed velocity pathway through a 2nd-order activation, optionally half-wave "
           "rectified (parallel-cascade model, Kearney, Stein & Parameswaran 1997)",
           # realistic: up to the ~30-40 N m s/rad, ~1.7 Hz of active ankle recordings
           (_p("gain", "N m s/rad", (1.0, 40.0), (0.02, 300.0), physical=POS),
            # 5 ms: no reflex
            _p("delay_s", "s", (0.03, 0.06), (0.005, 0.15), log=False, physical=POS),
            _p("frequency_hz", "Hz", (1.0, 6.0), (0.5, 30.0), physical=POS)),
           fit="limbfit", kinds=("position",),
           # stretch_sign: which velocity stretches the reflexing muscle (acts only when
           # rectified; limb.py): both are tried, as an ankle's angle sign is the lab's
           choices={"rectified": (False, True), "stretch_sign": (1.0, -1.0)}),
    Effect("stiffness_amplitude",
           "stiffness softening with the running RMS amplitude, K (A / 0.01 rad)^-exponent",
           (_p("exponent", "-", (0.15, 0.5), (0.003, 3.0), physical=POS),), fit="limbfit",
           kinds=("position",)),
    Effect("stiffness_drift", "stiffness drifting over the trial, K (1 + rate t / 60 s)",
           (_p("rate_per_min", "1/min", (0.1, 0.4), (-3.0, 3.0), log=False,
               physical=(-INF, INF)),),
           fit="limbfit", kinds=("position",), sign_choice=True),
    # --- stiffness (and damping) varying in time or in state (diagnosis.varying_effects):
    # reported relative to K0; the linear coefficients' bounds only flag absurd values
    Effect("stiffness_saturating",
           "stiffness (and damping) drifting and settling, K0 (1 + change (1 - e^-t/T))",
           (_p("change_rel", "-", (0.3, 1.5), (-0.95, 3.0), log=False,
               physical=(-1.0, INF)),
            _p("time_constant_s", "s", (5.0, 20.0), (1.0, 200.0), physical=POS)),
           fit="limbfit", kinds=("position",)),
    Effect("stiffness_switching",
           "stiffness (and damping) switching between two levels, change points read "
           "from the data",
           (_p("level_ratio", "-", (1.5, 3.0), (0.02, 50.0), physical=POS),
            _p("n_changes", "-", (2, 20), (0, 1e6), log=False, scored=False,
               physical_low=True, physical=POS)),
           fit="limbfit", kinds=("position",)),
    Effect("stiffness_modulated",
           "stiffness (and damping) modulated slowly, K0 (1 + a sin(2 pi t / P + phi))",
           (_p("amplitude_rel", "-", (0.2, 0.6), (0.0, 20.0), log=False, physical_low=True,
               physical=POS),
            _p("period_s", "s", (5.0, 20.0), (2.5, 120.0), physical=POS)),
           fit="limbfit", kinds=("position",)),
    Effect("stiffness_angle",
           "stiffness (and damping) a function of the scheduling variable (the slow "
           "angle): K0 (1 + s (rho - rho_mid) + c (rho - rho_mid)^2)",
           (_p("slope_rel", "1/unit of rho", (1.5, 4.0), (-1e4, 1e4), log=False,
               physical=(-INF, INF)),
            _p("curvature_rel", "1/unit^2", (0.0, 10.0), (-1e6, 1e6), log=False,
               scored=False, physical=(-INF, INF))),
           fit="limbfit", kinds=("position",)),
    Effect("stiffness_torque",
           "stiffness (and damping) a function of the background torque (slow part of "
           "the measured torque): K0 (1 + s (tau_bg - mid) + c (tau_bg - mid)^2)",
           (_p("slope_rel", "1/(N m)", (0.05, 0.3), (-1e4, 1e4), log=False,
               physical=(-INF, INF)),
            _p("curvature_rel", "1/(N m)^2", (0.0, 0.1), (-1e6, 1e6), log=False,
               scored=False, physical=(-INF, INF))),
           fit="limbfit", kinds=("position",)),
    Effect("wobbling_mass", "soft-tissue inertia on a spring-damper (damping ratio 0.3)",
           (_p("mass", "kg m^2", (0.004, 0.012), (2e-4, 0.3), physical=POS),
            _p("frequency_hz", "Hz", (4.0, 10.0), (1.0, 45.0), physical=POS)),
           fit="limbfit", kinds=("position",)),
    Effect("channel_delay", "the torque channel lags (or leads) the angle channel",
           # realistic: anti-alias filters (a few ms) up to unsynchronised acquisition or
           # buffering of one channel (tens of ms); magnitudes drawn log-uniformly
           (_p("delay_s", "s", (0.002, 0.04), (-0.1, 0.1), log=False, draw_log=True,
               physical=(-INF, INF)),),
           fit="limbfit", kinds=("position",), sign_choice=True),
    Effect("servo_bandwidth",
           "the servo tracks theta_ref through a 2nd-order low-pass (damping 0.7); seen "
           "only when theta_ref is recorded",
           (_p("bandwidth_hz", "Hz", (8.0, 25.0), (1.0, 250.0), physical=POS),), fit="limbfit",
           kinds=("position",)),
)}

#: experiment kinds of the catalogue
KINDS = ("exoskeleton", "position")


def effects_for(kind: str) -> tuple[str, ...]:
    """Names of the catalogue effects that apply to experiments of ``kind``.

    Raises DiagnosisInputError for an unknown kind."""
    if kind not in KINDS:
        raise DiagnosisInputError(f"unknown experiment kind {kind!r}; known: {', '.join(KINDS)}")
    return tuple(n for n, e in CATALOGUE.items() if e.applies_to(kind))


def get_effect(name: str) -> Effect:
    """The catalogue entry ``name``; DiagnosisInputError naming it when unknown."""
    try:
        return CATALOGUE[name]
    except KeyError:
        raise DiagnosisInputError(f"unknown effect {name!r}; the catalogue has "
                                  f"{', '.join(CATALOGUE)}") from None


def expand_effect(name: str, params: dict, n_dof: int = 2) -> dict:
    """Turn primary values into the parameter dict ``simulate_trial`` takes.

    Secondary parameters are tied by the module constants; per-joint values become lists.
    """
    get_effect(name)
    per_joint = lambda v: [float(v)] * n_dof  # noqa: E731
    if name == "friction":
        fc = float(params["Fc"])
        return {"Fc": per_joint(fc), "Fs": per_joint(FRICTION_FS_OVER_FC * fc),
                "sigma2": per_joint(FRICTION_SIGMA2_OVER_FC * fc)}
    if name == "transmission_compliance":
        k = float(params["k_t"])
        return {"k_t": per_joint(k), "c_t": per_joint(TRANSMISSION_DAMPING_TIME_S * k)}
    if name == "interface_compliance":
        k = float(params["k_s"])
        return {"k_s": per_joint(k), "c_s": per_joint(INTERFACE_DAMPING_TIME_S * k)}
    if name == "delay":
        return {"samples": int(round(params["samples"]))}
    return {k: (v if isinstance(v, bool) else float(v)) for k, v in params.items()}


def below_detectability(name: str, params: dict) -> bool:
    """True when every primary parameter of ``params`` lies below its measured
    detectability floor (closer to "off" than ``detectable_from``)."""
    floors = [(p, p.detectable_from) for p in get_effect(name).parameters]
    if any(f is None or p.name not in params for p, f in floors):
        return False
    return all(abs(params[p.name] - p.off) < abs(f - p.off) for p, f in floors)


def search_bound_hits(name: str, params: dict, tol: float = BOUND_TOLERANCE,
                      searched: dict | None = None) -> list:
    """``[(param, "lower" | "upper"), ...]``: the scored primary parameters of a fit of
    ``name`` that lie on a bound of the search made (``searched``: {param: (low, high)}
    where it was widened, default the declared range); the structured form of
    :func:`at_search_bound`, formatted later with values in the file's units,
    :func:`format_flag`."""
    out = []
    for p in get_effect(name).parameters:
        if not p.scored or p.name not in params:
            continue
        side = p.search_bound_hit(float(params[p.name]), tol,
                                  (searched or {}).get(p.name))
        if side is not None:
            out.append((p.name, side))
    return out


def physical_note(p: Parameter, value: float, side: str) -> str:
    """The flag of a value outside its physical limits (``side`` ``"non-physical"``)
    or on one: ``"< 0 (unphysical)"``, ``"at its physical upper limit"``."""
    if side != "non-physical":
        return f"at its physical {side} limit"
    lo, hi = p.physical
    return f"< {lo:g} (unphysical)" if not value >= lo else f"> {hi:g} (unphysical)"


def bound_notes(name: str, params: dict, tol: float = BOUND_TOLERANCE,
                searched: dict | None = None) -> list:
    """``[(param, note), ...]``: why a fit of ``name`` is not named, per scored primary
    parameter: outside its physical limits (``"< 0 (unphysical)"``), on a physical limit
    (``"at its physical upper limit"``) or on a bound of the search made (``searched``:
    {param: (low, high)} where it was widened; ``"at upper search bound"``)."""
    out = []
    for p in get_effect(name).parameters:
        if not p.scored or p.name not in params:
            continue
        v = float(params[p.name])
        b = (searched or {}).get(p.name)
        phys = p.physical_hit(v, tol, b)
        if phys is not None:
            out.append((p.name, physical_note(p, v, phys)))
            continue
        side = p.search_bound_hit(v, tol, b)
        if side is not None:
            out.append((p.name, f"at {side} search bound"))
    return out


def format_flag(param: str, value: float, note: str) -> str:
    """``"k_s = 3000 at upper search bound"``: one flag, value shown with 4 digits."""
    return f"{param} = {float(value):.4g} {note}"


def at_search_bound(name: str, params: dict, tol: float = BOUND_TOLERANCE,
                    searched: dict | None = None) -> list[str]:
    """The scored primary parameters of a fit of ``name`` that lie on a search bound, on
    a physical limit or beyond one (:func:`bound_notes`), e.g.
    ``["k_s = 3000 at upper search bound"]``; empty when none.

    Unscored parameters (not identifiable by the experiment, e.g. the torque noise of
    ``sensor_noise``) may wander anywhere and are not checked.
    """
    return [format_flag(k, params[k], note)
            for k, note in bound_notes(name, params, tol, searched)]


def relative_parameter_error(name: str, fitted: dict, truth: dict, *,
                             scored_only: bool = False) -> dict:
    """|fitted - truth| / |truth - off| per primary parameter (the 20 % target)."""
    out = {}
    for p in get_effect(name).parameters:
        if scored_only and not p.scored:
            continue
        denom = abs(truth[p.name] - p.off)
        out[p.name] = abs(fitted[p.name] - truth[p.name]) / denom if denom > 0 else math.inf
    return out


def catalogue_table() -> list[dict]:
    """The catalogue as rows (for docs and the report)."""
    rows = []
    for e in CATALOGUE.values():
        for p in e.parameters:
            rows.append({"effect": e.name, "physics": e.physics, "parameter": p.name,
                         "unit": p.unit, "realistic": list(p.realistic),
                         "fit_bounds": list(p.bounds), "physical": list(p.physical),
                         "fit": e.fit})
    return rows
