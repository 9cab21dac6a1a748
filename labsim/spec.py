"""What a simulated recording holds: the :class:`RecordingSpec` and its parts (SI units).

Every part is a dataclass of plain numbers, strings and lists, so a spec goes to JSON and
back (:func:`spec_to_dict`, :func:`spec_from_dict`) and is written whole into the truth
file. A part left ``None`` is absent from the simulated set-up. The equations each part
stands for are in docs/labsim.md and the docstrings of :mod:`labsim.limb`,
:mod:`labsim.servo`, :mod:`labsim.signals` and :mod:`labsim.sensors`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Optional, Union

Number = Union[float, list]


@dataclass
class Variation:
    """How a parameter ``P`` (K, B, I or the reflex gain) changes: ``P = P0 f_t(t) f_a(x)
    f_tau(tau_bg)``, each factor 1 when its form is ``"constant"`` / coefficient 0.

    Time factor ``f_t`` (``time``), with ``r = ratio``:
      - ``"linear"``: ``1 + (r - 1) t / T`` (T the recording's duration): r at the end;
      - ``"saturating"``: ``1 + (r - 1)(1 - exp(-t / tau_s))`` (P0 + dP (1 - e^{-t/tau}));
      - ``"switching"``: a square wave between 1 and r, switching every ``period_s / 2``
        (first level 1), from ``phase_s`` on;
      - ``"sine"``: ``1 + (r - 1) sin(2 pi t / period_s + phase_s 2 pi / period_s)``.
    Angle factor ``f_a`` (``angle``), of the joint angle x [rad] (for K: the local slope
    dtau/dx of the elastic torque, whose integral is the torque; docs/labsim.md):
      - ``"exp"``: ``exp(angle_coef (x - angle_ref_rad))`` / ``exp(-angle_coef angle_ref_rad)``
        (stiffness rising exponentially with dorsiflexion for angle_coef > 0; Weiss,
        Kearney & Hunter, J Biomech 19:727, 1986);
      - ``"quadratic"``: ``1 + angle_coef ((x - angle_ref_rad)^2 - angle_ref_rad^2)``, a U
        with its minimum at angle_ref_rad;
      - ``"linear"``: ``1 + angle_coef x``.
    Torque factor ``f_tau = 1 + torque_coef |tau_bg|`` [1/(N m)], tau_bg the subject's
    background torque (stiffness and reflex gain grow about linearly with the tonic
    torque; Hunter & Kearney, J Biomech 15:747, 1982; Mirbagheri et al., Exp Brain Res
    132:84, 2000).
    """

    time: str = "constant"
    ratio: float = 1.0
    tau_s: float = 10.0
    period_s: float = 10.0
    phase_s: float = 0.0
    angle: str = "constant"
    angle_coef: float = 0.0
    angle_ref_rad: float = 0.0
    torque_coef: float = 0.0


@dataclass
class Perturbation:
    """The servo's perturbation reference p(t) [rad] (added to the slow movement).

    kind:
      - ``"noise"``: Gaussian white noise through an analog Butterworth filter of ``order``
        over ``band_hz`` (low-pass when band_hz[0] is 0): flat in the band;
        ``amplitude_rad`` its RMS;
      - ``"prbs"``: a maximum-length binary sequence of +-``amplitude_rad`` switching every
        ``switch_s`` (Kearney & Hunter, Crit Rev Biomed Eng 18:55, 1990), optionally
        smoothed by a 2nd-order low-pass at ``prefilter_hz`` (needed on an ideal servo);
      - ``"multisine"``: sum of sines on the grid 1/``period_s`` (None: the duration) over
        ``band_hz``, every ``every``-th line, random phases (``phases="random"``) or
        Schroeder's (``"schroeder"``); ``amplitude_rad`` its RMS. With ``period_s`` dividing
        the duration the recording holds whole periods (Pintelon & Schoukens, System
        Identification, 2012, ch. 2).
    joints : list of 1-based joints perturbed (None: joint 1); independent signals each.
    rest : list of [start_s, end_s] intervals without perturbation (recorded rest), with
        ``taper_s`` raised-cosine edges.
    """

    kind: str = "noise"
    amplitude_rad: float = 0.02
    band_hz: list = field(default_factory=lambda: [0.0, 40.0])
    order: int = 8
    switch_s: float = 0.15
    prefilter_hz: Optional[float] = None
    period_s: Optional[float] = None
    every: int = 1
    phases: str = "random"
    joints: Optional[list] = None
    rest: list = field(default_factory=list)
    taper_s: float = 0.2


@dataclass
class Movement:
    """A slow imposed movement x_s(t) [rad] on which the perturbation rides (the
    scheduling variable; Sobhani Tehrani & Kearney, IEEE TBME 69, 2022, whose pilot ankle
    moved through -0.41..+0.20 rad with a ~16 s period).

    kind ``"sine"``: between ``range_rad`` [lo, hi] with period ``period_s``, starting at
    ``phase_rad`` of its cycle (0: at the middle, rising); ``"ramps"``: raised-cosine
    ramps of ``ramp_s`` between the ``levels_rad`` in turn, each held ``hold_s``.
    ``joints``: 1-based joints that move (None: joint 1).
    """

    kind: str = "sine"
    range_rad: list = field(default_factory=lambda: [-0.4, 0.2])
    period_s: float = 16.0
    phase_rad: float = 0.0
    levels_rad: list = field(default_factory=lambda: [0.0, -0.3, 0.15])
    ramp_s: float = 2.0
    hold_s: float = 4.0
    joints: Optional[list] = None


@dataclass
class Servo:
    """The position servo that imposes the reference on the joint.

    kind ``"ideal"``: the joint follows the continuous reference exactly (no loading).
    kind ``"pd"``: a motor of inertia ``motor_inertia`` [kg m^2] (per joint) drives the
    footplate through a rigid torque sensor; its controller is
    ``u = Kp (r - x) + Ki int(r - x) - Kd x'``, with Kp, Kd set for a closed-loop natural
    frequency ``f_hz`` and damping ``damping`` on the motor plus the nominal limb inertia,
    and Ki = Kp 2 pi ``integral_hz`` (0: none); a first-order actuator (current or
    force loop) lag ``actuator_lag_s`` (0.5 ms: a 320 Hz force loop; 0: none, when the
    motor's acceleration follows the reference's fine-grid interpolation directly, an
    error of ~2e-4 in the FRF at 40 Hz). The reference reaches the servo through a DAC:
    ``"zoh"`` holds each sample (1/fs; the staircase shakes the motor at fs),
    ``"continuous"`` is the analog (reconstructed) reference. The limb's impedance
    loads the motor, so the servo's stiffness is finite (Kearney & Hunter 1990 describe
    such hydraulic and electric rigs).
    """

    kind: str = "pd"
    f_hz: float = 80.0
    damping: float = 0.8
    motor_inertia: Number = 0.03
    integral_hz: float = 0.0
    actuator_lag_s: float = 0.0005
    dac: str = "continuous"


@dataclass
class Limb:
    """Intrinsic joint mechanics on the limb side of the torque sensor (footplate
    included): ``tau = I x'' + B x' + tau_e(x) + ...`` with ``K``, ``B``, ``I`` their values
    at t = 0 and x = 0 (scalars, or n x n lists for n joints), each with a
    :class:`Variation`.

    ``k3`` [N m/rad^3]: a stiffening cubic spring added to tau_e (``k3 x^3``).
    ``srs_K`` [N m/rad], ``srs_limit_rad``: short-range stiffness, an elastic element that
    slips beyond +-srs_limit_rad (elastic-perfectly-plastic, a play operator; Rack &
    Westbury, J Physiol 240:331, 1974; Campbell & Lakie, J Physiol 510:941, 1998).
    ``background_torque_nm``: the subject's tonic torque (held against the servo; the
    torque factors of the Variations read it, plus the voluntary torque).
    """

    K: Number = 80.0
    B: Number = 1.2
    I: Number = 0.015
    K_var: Optional[Variation] = None
    B_var: Optional[Variation] = None
    I_var: Optional[Variation] = None
    k3: Number = 0.0
    srs_K: Number = 0.0
    srs_limit_rad: float = 0.01
    background_torque_nm: Number = 0.0


@dataclass
class Reflex:
    """Stretch reflex: ``tau_r = LP[G(t) N(x'(t - delay_s))]``.

    N: ``rectify`` ``"positive"`` max(v - threshold, 0), ``"negative"`` min(v + threshold,
    0), ``"none"`` v (linear). LP (unit DC gain), by ``form``:
      - ``"second_order"``: wn^2 / (s^2 + 2 damping wn s + wn^2), wn = 2 pi f_hz;
      - ``"triple_pole"``: (wc / (s + wc))^3, wc = 2 pi f_hz;
      - ``"cascade"``: 1/(tau_s s + 1) times the second order (a first-order excitation
        stage and a second-order twitch; Kearney, Stein & Parameswaran, IEEE TBME 44:493,
        1997 fit a 2nd order; Mirbagheri et al. 2000 report 3rd-order-like shapes).
    ``gain`` [N m s/rad] per joint (scalar: joint 1 only), ``gain_var`` its Variation.
    ``fraction``, when given, sets joint 1's gain instead: the reflex torque's standard
    deviation is that fraction of the nominal limb's perturbation torque RMS (for the
    reference's velocity; the resolved gain is in the recording's spec).
    """

    gain: Number = 30.0
    delay_s: float = 0.045
    threshold_rad_s: float = 0.0
    rectify: str = "positive"
    form: str = "second_order"
    f_hz: float = 2.5
    damping: float = 0.7
    tau_s: float = 0.02
    gain_var: Optional[Variation] = None
    fraction: Optional[float] = None


@dataclass
class WobblingMass:
    """Soft tissue: an inertia ``inertia`` [kg m^2] tied to the joint by a spring-damper of
    natural frequency ``f_hz`` and damping ratio ``damping`` (per joint; Gruber et al., J
    Biomech 31:439, 1998). tau_w = k (x - x_w) + b (x' - x_w'), I_w x_w'' = tau_w."""

    inertia: Number = 0.004
    f_hz: Number = 12.0
    damping: Number = 0.3


@dataclass
class Footplate:
    """Apparatus effects on the limb side of the torque sensor (they load the sensor).

    friction ``"tanh"``: ``Fc tanh(x'/v_s) + sigma2 x'``; ``"lugre"``: Canudas de Wit et
    al., IEEE TAC 40:419, 1995, z' = x' - sigma0 |x'| z / g(x'), g = Fc + (Fs - Fc)
    exp(-(x'/v_s)^2), F = sigma0 z + sigma1 z' + sigma2 x'. ``friction_fraction``, when
    ``Fc`` is None, sets Fc as that fraction of the RMS torque of the nominal limb under the
    perturbation. ``backlash_rad``: half-width of a play between the encoder and the
    footplate (the limb sees the play operator's output, smoothed by a contact of
    ``contact_hz``, damping 0.7). ``contact_limit_nm``: the largest torque the contact can
    transmit in the negative direction (beyond it the foot slips: torque clipped smoothly).
    """

    friction: Optional[str] = None
    Fc: Optional[float] = None
    friction_fraction: float = 0.05
    v_s: float = 0.05
    Fs: Optional[float] = None
    sigma0: float = 1e4
    sigma1: float = 0.3
    sigma2: float = 0.0
    backlash_rad: float = 0.0
    contact_hz: float = 150.0
    contact_limit_nm: Optional[float] = None


@dataclass
class Voluntary:
    """The subject's own torque: Gaussian noise low-passed (Butterworth ``order``) to
    ``band_hz``, RMS ``level_nm``, or ``fraction`` of the nominal limb's perturbation torque
    RMS when level_nm is None; not coherent with the perturbation (Kearney & Hunter 1990:
    subjects' torque drifts at 0-2 Hz)."""

    fraction: float = 0.2
    level_nm: Optional[float] = None
    band_hz: float = 2.0
    order: int = 4


@dataclass
class Filter:
    """An analog filter: ``kind`` ``"butterworth"`` / ``"bessel"`` of ``order`` at
    ``cutoff_hz`` (None: 0.4 fs), or ``"second_order"`` of ``cutoff_hz`` and ``damping``."""

    kind: str = "butterworth"
    order: int = 4
    cutoff_hz: Optional[float] = None
    damping: float = 0.7


@dataclass
class Channel:
    """One recorded channel (theta or tau_h), after the common anti-alias filter.

    ``filter``: the channel's own filter (e.g. a torque amplifier's 2nd-order low-pass);
    ``delay_s``: the channel lags the others by this; noise (added, then quantised):
    ``white_std``, ``pink_std`` (1/f power between 0.1 Hz and fs/2), ``hum_std`` (RMS of
    ``hum_hz`` and its harmonics with relative amplitudes ``hum_harmonics``), ``offset``;
    ``resolution``: quantisation step (0: none). Units of the channel (rad, N m).
    """

    filter: Optional[Filter] = None
    delay_s: float = 0.0
    white_std: float = 0.0
    pink_std: float = 0.0
    hum_std: float = 0.0
    hum_hz: float = 50.0
    hum_harmonics: list = field(default_factory=lambda: [1.0, 0.3, 0.1])
    offset: float = 0.0
    resolution: float = 0.0


@dataclass
class Sensors:
    """Acquisition: a common anti-alias ``antialias`` filter on every analog channel
    (None: none), the channels, the sign the file stores the torque with, whether the
    reference is recorded."""

    antialias: Optional[Filter] = field(default_factory=Filter)
    theta: Channel = field(default_factory=Channel)
    tau: Channel = field(default_factory=Channel)
    torque_sign: int = 1


@dataclass
class RecordingSpec:
    """A whole simulated recording (docs/labsim.md). ``oversample``: internal steps per
    sample; ``preroll_s``: simulated before t = 0 and dropped (start transients);
    ``kind``, ``condition``: labels (the truth's, the metadata's); ``scheduling_channel``:
    the extra column holding the commanded slow angle of a moving joint (None: none);
    ``movement_removed``: store a moving joint's recording less an unperturbed trial
    along the same movement (:func:`labsim.simulate`)."""

    duration_s: float = 60.0
    fs: float = 1000.0
    n_dof: int = 1
    seed: int = 0
    perturbation: Perturbation = field(default_factory=Perturbation)
    movement: Optional[Movement] = None
    servo: Servo = field(default_factory=Servo)
    limb: Limb = field(default_factory=Limb)
    reflex: Optional[Reflex] = None
    wobbling: Optional[WobblingMass] = None
    footplate: Optional[Footplate] = None
    voluntary: Optional[Voluntary] = None
    sensors: Sensors = field(default_factory=Sensors)
    record_reference: bool = True
    oversample: int = 10
    preroll_s: float = 3.0
    kind: str = "custom"
    condition: Optional[str] = None
    scheduling_channel: Optional[str] = "sv"
    movement_removed: bool = False


_PARTS = {
    "perturbation": Perturbation, "movement": Movement, "servo": Servo, "limb": Limb,
    "reflex": Reflex, "wobbling": WobblingMass, "footplate": Footplate,
    "voluntary": Voluntary, "sensors": Sensors,
}
_NESTED = {
    (Limb, "K_var"): Variation, (Limb, "B_var"): Variation, (Limb, "I_var"): Variation,
    (Reflex, "gain_var"): Variation, (Sensors, "antialias"): Filter,
    (Sensors, "theta"): Channel, (Sensors, "tau"): Channel, (Channel, "filter"): Filter,
}


def spec_to_dict(spec) -> dict:
    """A spec (or part) as plain JSON-ready dicts."""
    return dataclasses.asdict(spec)


def _build(cls, value, where):
    if value is None or isinstance(value, cls):
        return value
    if not isinstance(value, dict):
        raise TypeError(f"{where}: expected an object for {cls.__name__}, got {value!r}")
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(value) - names)
    if unknown:
        raise TypeError(f"{where}: unknown key(s) {unknown} for {cls.__name__}; known: "
                        f"{sorted(names)}")
    kw = {}
    for k, v in value.items():
        sub = _NESTED.get((cls, k))
        kw[k] = _build(sub, v, f"{where}.{k}") if sub else v
    return cls(**kw)


def spec_from_dict(data: dict) -> RecordingSpec:
    """The inverse of :func:`spec_to_dict`; unknown keys are refused, naming them."""
    data = dict(data)
    for k, cls in _PARTS.items():
        if k in data:
            data[k] = _build(cls, data[k], k)
    return _build(RecordingSpec, data, "spec")
