"""The limb's own effects and the apparatus of a position servo (docs/diagnosis.md,
section "The limb and the position-servo catalogue").

A position-controlled apparatus imposes the joint angle; a torque sensor between actuator
and limb measures the torque the device applies to the limb (``tau_h`` of log-format.md:
positive in the joint's positive direction). For the nominal intrinsic limb that torque is

    tau = I theta'' + B theta' + K theta                                    (1)

with K, B, I the (n, n) stiffness [N m/rad], viscosity [N m s/rad] and inertia [kg m^2]
matrices. :func:`limb_torque` adds the effects of ``effects`` (a dict ``{name: params}``
like the catalogue's; ``{}`` is the nominal model (1)):

``stretch_reflex`` {gain G [N m s/rad], delay_s d [s], frequency_hz f_r [Hz],
damping z_r [-] (default 0.7), rectified [bool] (default False), stretch_sign (+1/-1),
threshold_rad_s [rad/s] (default 0: the rectifier passes sign v - threshold above 0)}
    The reflex pathway of the parallel-cascade model (Kearney, Stein & Parameswaran 1997,
    IEEE TBME 44(6)): joint velocity, delayed by d, optionally half-wave rectified (only
    velocities of sign ``stretch_sign`` stretch the muscle), through the 2nd-order
    activation dynamics w^2/(s^2 + 2 z w s + w^2), w = 2 pi f_r, times G:
    without rectification tau_r / theta = G s exp(-s d) w^2 / (s^2 + 2 z w s + w^2).
    Joint j's reflex acts on joint j from its own velocity.
``stiffness_amplitude`` {exponent alpha [-], reference_rad A_ref [rad] (default 0.01),
window_s T_A [s] (default 0.5)}
    Stiffness that softens with the amplitude of the movement (muscle short-range
    stiffness, Kearney & Hunter 1982): joint j's stiffness torque is scaled by
    (A_j(t) / A_ref)^(-alpha), A_j(t) the causal running RMS of theta_j (exponential
    window of time constant T_A). K is the stiffness at the amplitude A_ref. Unlike an
    instantaneous cubic spring (stiffening with the angle itself, diagnosis/outside.py of
    the earlier validation) this depends on how large the recent movement was.
``stiffness_drift`` {rate_per_min r [1/min]}
    K(t) = K (1 + r t / 60 s), t from the first sample: stiffness drifting over the trial
    (fatigue, changing co-contraction); K is the stiffness at the start.
``wobbling_mass`` {mass m [kg m^2], frequency_hz f_w [Hz], damping z_w [-] (default 0.3)}
    Soft tissue of inertia m coupled to the bone by a spring-damper (k = m w^2,
    c = 2 z_w m w): tau_w / theta = m s^2 (2 z w s + w^2) / (s^2 + 2 z w s + w^2).
``torque_sensor_lag`` {time_constant_s T [s]}
    The torque sensor low-passes: tau_measured = tau / (T s + 1).
``channel_delay`` {delay_s d [s]} (or {samples})
    The torque channel lags the angle channel by d (d < 0: it leads): anti-alias filters,
    multiplexed conversion or buffering in one channel only.

:func:`servo_response` adds the servo: ``servo_bandwidth`` {bandwidth_hz f_s [Hz],
damping z_s (default 0.7)}: the servo's tracking theta / theta_ref =
w^2/(s^2 + 2 z w s + w^2), w = 2 pi f_s, a stiff (load-independent) servo with a finite
closed-loop bandwidth.

Discretisation (fs the sampling rate): derivatives by second-order central differences
(numpy.gradient), second-order filters by the bilinear transform pre-warped at
their characteristic frequency, the sensor's first-order low-pass by its first-order-hold
equivalent (any T >= 0), fractional delays by linear interpolation between samples.
Filters start from rest, except the sensor low-pass, which starts at the first torque.
Everything is vectorised (scipy.signal.lfilter along time): a 60 s, 1 kHz trial takes
milliseconds.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

#: effects limb_torque knows (the limb's own, then the torque-channel apparatus)
LIMB_EFFECTS = ("stretch_reflex", "stiffness_amplitude", "stiffness_drift", "wobbling_mass")
CHANNEL_EFFECTS = ("torque_sensor_lag", "channel_delay")
SERVO_EFFECTS = ("servo_bandwidth",)
ALL_EFFECTS = LIMB_EFFECTS + CHANNEL_EFFECTS + SERVO_EFFECTS

DEFAULTS = {
    "stretch_reflex": {"damping": 0.7, "rectified": False, "stretch_sign": 1.0,
                       "threshold_rad_s": 0.0},
    "stiffness_amplitude": {"reference_rad": 0.01, "window_s": 0.5},
    "wobbling_mass": {"damping": 0.3},
    "servo_bandwidth": {"damping": 0.7},
}
REQUIRED = {
    "stretch_reflex": ("gain", "delay_s", "frequency_hz"),
    "stiffness_amplitude": ("exponent",),
    "stiffness_drift": ("rate_per_min",),
    "wobbling_mass": ("mass", "frequency_hz"),
    "torque_sensor_lag": ("time_constant_s",),
    "channel_delay": (),
    "servo_bandwidth": ("bandwidth_hz",),
}
AMPLITUDE_FLOOR_RAD = 1e-5  # running RMS floor (a limb at rest has no defined amplitude)


@dataclass(frozen=True)
class LimbModel:
    """Intrinsic impedance of an n-joint limb, model (1) of the module docstring.

    Attributes
    ----------
    K : ndarray (n, n) [N m/rad]
    B : ndarray (n, n) [N m s/rad]
    I : ndarray (n, n) [kg m^2]

    Scalars and 1-D diagonals are accepted and stored as (n, n) float arrays.

    Raises
    ------
    ValueError
        Matrices of different or non-square shapes, or non-finite entries.
    """

    K: np.ndarray
    B: np.ndarray
    I: np.ndarray  # noqa: E741 (the field's name for inertia)

    def __post_init__(self):
        mats = {}
        for key in ("K", "B", "I"):
            m = np.asarray(getattr(self, key), dtype=float)
            if m.ndim == 0:
                m = m.reshape(1, 1)
            elif m.ndim == 1:
                m = np.diag(m)
            if m.ndim != 2 or m.shape[0] != m.shape[1]:
                raise ValueError(f"LimbModel {key} has shape {m.shape}; expected (n, n)")
            if not np.all(np.isfinite(m)):
                raise ValueError(f"LimbModel {key} has non-finite entries: {m.tolist()}")
            mats[key] = m
        shapes = {k: v.shape for k, v in mats.items()}
        if len(set(shapes.values())) != 1:
            raise ValueError(f"LimbModel matrices differ in shape: {shapes}")
        for k, v in mats.items():
            object.__setattr__(self, k, v)

    @property
    def n_dof(self) -> int:
        return int(self.K.shape[0])


def _as_signal(x, name: str, n: int | None = None) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2:
        raise ValueError(f"{name} has shape {a.shape}; expected (N, n)")
    if n is not None and a.shape[1] != n:
        raise ValueError(f"{name} has {a.shape[1]} joint column(s); the limb has {n}")
    if a.shape[0] < 3:
        raise ValueError(f"{name} has {a.shape[0]} samples; at least 3 are needed")
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise ValueError(f"{name} is not finite at sample {bad[0]}, joint {bad[1] + 1}")
    return a


def effect_params(name: str, params: dict) -> dict:
    """``params`` completed with the defaults of effect ``name``.

    Raises
    ------
    ValueError
        Unknown effect, missing required key, or unknown key (named).
    """
    if name not in ALL_EFFECTS:
        raise ValueError(f"unknown limb/position effect {name!r}; known: "
                         f"{', '.join(ALL_EFFECTS)}")
    p = {**DEFAULTS.get(name, {}), **(params or {})}
    missing = [k for k in REQUIRED[name] if k not in p]
    if name == "channel_delay" and not ({"delay_s", "samples"} & set(p)):
        missing = ["delay_s (or samples)"]
    if missing:
        raise ValueError(f"effect {name!r} is missing parameter(s) {', '.join(missing)}")
    known = set(REQUIRED[name]) | set(DEFAULTS.get(name, {})) | (
        {"delay_s", "samples"} if name == "channel_delay" else set())
    unknown = sorted(set(p) - known)
    if unknown:
        raise ValueError(f"effect {name!r} has unknown parameter(s) {', '.join(unknown)}; "
                         f"known: {', '.join(sorted(known))}")
    return p


def derivatives(theta: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocity [rad/s] and acceleration [rad/s^2] of theta (N, n) [rad] by second-order
    central differences (one-sided second order at the ends)."""
    ts = 1.0 / fs
    omega = np.gradient(theta, ts, axis=0, edge_order=2)
    alpha = np.gradient(omega, ts, axis=0, edge_order=2)
    return omega, alpha


def _designed_once(design):
    """``design(*args)`` computed once per distinct arguments (a fit asks for the same
    filter on every trial of every evaluation; ``signal.bilinear`` is slow next to the
    filtering itself); the cached (b, a) are read-only."""
    @functools.lru_cache(maxsize=4096)
    def cached(*args, **kwargs):
        out = tuple(np.array(c, dtype=float) for c in design(*args, **kwargs))
        for c in out:
            c.setflags(write=False)
        return out

    @functools.wraps(design)
    def wrapper(*args, **kwargs):
        return cached(*(float(a) if isinstance(a, (int, float, np.floating, np.integer))
                        and not isinstance(a, bool) else a for a in args), **kwargs)
    wrapper.uncached = design
    return wrapper


@_designed_once
def second_order_lowpass(frequency_hz: float, damping: float, fs: float, *,
                         numerator: str = "lowpass") -> tuple[np.ndarray, np.ndarray]:
    """Digital (b, a) of w^2/(s^2+2 z w s+w^2) (``numerator="lowpass"``) or of
    (2 z w s + w^2)/(s^2+2 z w s+w^2) (``"spring_damper"``), w = 2 pi f, by the bilinear
    transform pre-warped at f (exact response at f).

    Raises ValueError for f <= 0, f >= fs/2 or damping <= 0.
    """
    if not (0 < frequency_hz < fs / 2) or not damping > 0:
        raise ValueError(f"second-order filter needs 0 < frequency_hz < fs/2 = {fs / 2:g} "
                         f"and damping > 0; got {frequency_hz!r}, {damping!r}")
    w = 2 * fs * math.tan(math.pi * frequency_hz / fs)  # pre-warped [rad/s]
    den = [1.0, 2 * damping * w, w * w]
    num = [w * w] if numerator == "lowpass" else [2 * damping * w, w * w]
    return signal.bilinear(num, den, fs)


@_designed_once
def first_order_lowpass(time_constant_s: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Digital (b, a) of 1/(T s + 1): the exact response to an input linear between
    samples (first-order-hold equivalent, scipy.signal.cont2discrete ``"foh"``).

    With r = 1/(T fs), a = exp(-r) and g = (1 - a)/r:
    y[k] = a y[k-1] + (1 - g) x[k] + (g - a) x[k-1]. Unit DC gain; defined for every
    T > 0 (corners above the Nyquist frequency included) and continuous in T, tending to
    the identity as T -> 0; T == 0 is the identity itself, b = a = [1].

    Raises ValueError for T < 0 or a non-finite T.
    """
    if time_constant_s == 0:
        return np.array([1.0]), np.array([1.0])
    if not (time_constant_s > 0 and math.isfinite(time_constant_s)):
        raise ValueError(f"time_constant_s must be >= 0 and finite; got {time_constant_s!r}")
    r = 1.0 / (time_constant_s * fs)
    a = math.exp(-r)
    g = -math.expm1(-r) / r  # (1 - a)/r, accurate for small r
    return np.array([1.0 - g, g - a]), np.array([1.0, -a])


def fractional_delay(x: np.ndarray, delay_samples: float) -> np.ndarray:
    """x (N, n) delayed by ``delay_samples`` (any real; negative advances), linear
    interpolation between samples; the edges hold the first/last value."""
    if delay_samples == 0:
        return x.copy()
    n = x.shape[0]
    idx = np.arange(n) - float(delay_samples)
    lo = np.floor(idx)
    frac = (idx - lo)[:, None]
    i0 = lo.astype(int)
    i1 = np.clip(i0 + 1, 0, n - 1)
    np.clip(i0, 0, n - 1, out=i0)
    # (1 - frac) x[i0] + frac x[i1], the same operations with fewer temporaries (a search
    # delays the velocity at every step)
    out = (1.0 - frac) * np.take(x, i0, axis=0)
    out += frac * np.take(x, i1, axis=0)
    return out


def reflex_drive(omega: np.ndarray, fs: float, p: dict) -> np.ndarray:
    """The velocity (N, n) that drives the stretch reflex's activation: ``omega``
    delayed and, when rectified, half-wave rectified (``p``: the effect's parameters
    completed by :func:`effect_params`). A function of the delay and the rectification
    only: fits that vary the activation frequency at one delay reuse it."""
    v = fractional_delay(omega, float(p["delay_s"]) * fs)
    if p["rectified"]:
        sign = 1.0 if float(p["stretch_sign"]) >= 0 else -1.0
        v = np.maximum(sign * v - float(p["threshold_rad_s"]), 0.0) * sign
    return v


def reflex_drive_key(p: dict) -> tuple:
    """What :func:`reflex_drive` depends on in ``p`` (completed parameters)."""
    return (float(p["delay_s"]), bool(p["rectified"]), float(p["stretch_sign"]),
            float(p["threshold_rad_s"]))


def reflex_torque(omega: np.ndarray, fs: float, params: dict, *, drive=None) -> np.ndarray:
    """The reflex torque (N, n) [N m] of the stretch_reflex effect from velocity (N, n).

    ``drive``, optional: :func:`reflex_drive` of these ``omega`` and ``fs`` for the
    completed parameters (a cached one); computed here when None."""
    p = effect_params("stretch_reflex", params)
    v = reflex_drive(omega, fs, p) if drive is None else drive
    b, a = second_order_lowpass(float(p["frequency_hz"]), float(p["damping"]), fs)
    return float(p["gain"]) * signal.lfilter(b, a, v, axis=0)


def stiffness_scale(theta: np.ndarray, fs: float, effects: dict) -> np.ndarray | None:
    """Per-sample, per-joint factor (N, n) on the stiffness torque (amplitude dependence
    and drift), or None when neither effect is present."""
    scale = None
    if "stiffness_amplitude" in effects:
        p = effect_params("stiffness_amplitude", effects["stiffness_amplitude"])
        n0 = max(1, min(theta.shape[0], int(round(float(p["window_s"]) * fs))))
        lam = math.exp(-1.0 / (float(p["window_s"]) * fs))
        sq = theta * theta
        zi = lam * np.mean(sq[:n0], axis=0)  # start at the first window's mean square
        ms, _ = signal.lfilter([1 - lam], [1.0, -lam], sq, axis=0, zi=zi[None, :])
        amp = np.sqrt(np.maximum(ms, AMPLITUDE_FLOOR_RAD ** 2))
        scale = (amp / float(p["reference_rad"])) ** (-float(p["exponent"]))
    if "stiffness_drift" in effects:
        p = effect_params("stiffness_drift", effects["stiffness_drift"])
        t = np.arange(theta.shape[0]) / fs
        drift = (1.0 + float(p["rate_per_min"]) * t / 60.0)[:, None]
        scale = drift if scale is None else scale * drift
    return scale


def channel_apply(tau: np.ndarray, fs: float, effects: dict) -> np.ndarray:
    """The torque-channel apparatus effects (sensor lag, then channel delay) on tau (N, n)."""
    out = tau
    if "torque_sensor_lag" in effects:
        p = effect_params("torque_sensor_lag", effects["torque_sensor_lag"])
        b, a = first_order_lowpass(float(p["time_constant_s"]), fs)
        if len(a) > 1:  # T == 0 is the identity (lfilter_zi needs a filter state)
            zi = signal.lfilter_zi(b, a)[:, None] * out[:1]
            out, _ = signal.lfilter(b, a, out, axis=0, zi=zi)
    if "channel_delay" in effects:
        p = effect_params("channel_delay", effects["channel_delay"])
        d = float(p["samples"]) if "samples" in p else float(p["delay_s"]) * fs
        out = fractional_delay(out, d)
    return out


def limb_torque(theta, fs: float, limb: LimbModel, effects: dict | None = None,
                stiffness_factor=None) -> np.ndarray:
    """The torque the sensor measures when the angle ``theta`` is imposed.

    Parameters
    ----------
    theta : array (N, n) [rad] (or (N,) for one joint)
        Imposed (measured) joint angles, deviations from the posture, sampled at ``fs``.
    fs : float [Hz]
    limb : LimbModel
    effects : dict {name: params}
        Effects of the module docstring (limb and torque channel); {} or None: model (1).
        ``servo_bandwidth`` is ignored here (it acts on the angle: :func:`servo_response`).
    stiffness_factor : array (N,) or (N, n), optional
        A per-sample factor on the stiffness torque from outside the limb model (a
        stiffness varying in time or with the state, diagnosis.varying_effects.factor).

    Returns
    -------
    ndarray (N, n) [N m]
        Device-to-limb torque as measured.

    Raises
    ------
    ValueError
        Bad shapes, non-finite samples (sample and joint named), unknown effect or
        parameter (named).
    """
    effects = dict(effects or {})
    for name in effects:
        effect_params(name, effects[name])  # validates names and keys
    theta = _as_signal(theta, "theta", limb.n_dof)
    fs = float(fs)
    omega, alpha = derivatives(theta, fs)
    tau_k = theta @ limb.K.T
    scale = stiffness_scale(theta, fs, effects)
    if scale is not None:
        tau_k = tau_k * scale
    if stiffness_factor is not None:
        f = np.asarray(stiffness_factor, float)
        tau_k = tau_k * (f[:, None] if f.ndim == 1 else f)
    tau = tau_k + omega @ limb.B.T + alpha @ limb.I.T
    if "wobbling_mass" in effects:
        p = effect_params("wobbling_mass", effects["wobbling_mass"])
        b, a = second_order_lowpass(float(p["frequency_hz"]), float(p["damping"]), fs,
                                    numerator="spring_damper")
        tau = tau + float(p["mass"]) * signal.lfilter(b, a, alpha, axis=0)
    if "stretch_reflex" in effects:
        tau = tau + reflex_torque(omega, fs, effects["stretch_reflex"])
    return channel_apply(tau, fs, effects)


def servo_angle(theta_ref, fs: float, effects: dict | None = None) -> np.ndarray:
    """The angle (N, n) [rad] a position servo imposes when commanded ``theta_ref``:
    theta_ref itself for an ideal servo, low-passed by ``servo_bandwidth`` otherwise."""
    effects = dict(effects or {})
    theta_ref = _as_signal(theta_ref, "theta_ref")
    if "servo_bandwidth" not in effects:
        return theta_ref.copy()
    p = effect_params("servo_bandwidth", effects["servo_bandwidth"])
    b, a = second_order_lowpass(float(p["bandwidth_hz"]), float(p["damping"]), float(fs))
    zi = signal.lfilter_zi(b, a)[:, None] * theta_ref[:1]
    out, _ = signal.lfilter(b, a, theta_ref, axis=0, zi=zi)
    return out


def servo_response(theta_ref, fs: float, limb: LimbModel,
                   effects: dict | None = None,
                   stiffness_factor=None) -> tuple[np.ndarray, np.ndarray]:
    """A position servo tracks ``theta_ref`` (N, n) [rad]; returns (theta, tau), both
    (N, n): the imposed angle [rad] (:func:`servo_angle`) and the measured torque [N m]
    (:func:`limb_torque` of that angle). Errors as :func:`limb_torque`."""
    theta_ref = _as_signal(theta_ref, "theta_ref", limb.n_dof)
    theta = servo_angle(theta_ref, fs, effects)
    return theta, limb_torque(theta, fs, limb, effects, stiffness_factor)
