"""Random specs for validation sets: :func:`draw` (kinds and ranges in docs/labsim.md).

Ranges, one joint (the ankle on a position servo, footplate included):

- intrinsic K 20-200 N m/rad (log-uniform; relaxed to active; Kearney & Hunter, Crit Rev
  Biomed Eng 18:55, 1990; Mirbagheri et al., Exp Brain Res 132:84, 2000), B 0.5-3 N m s/rad,
  I 0.01-0.03 kg m^2 (foot plus footplate; Kearney et al., IEEE TBME 44:493, 1997);
- perturbation: Gaussian noise flat to 30-45 Hz of RMS 0.01-0.03 rad, a PRBS of
  +-0.02-0.04 rad switching every 0.1-0.2 s (Kearney et al. 1997: 0.03 rad, 150 ms), or a
  random-phase multisine to 40 Hz, RMS 0.01-0.03 rad (each a third of draws);
- servo: PD, closed-loop 50-120 Hz, damping 0.6-1.0, motor inertia 0.01-0.05 kg m^2,
  actuator lag 0.3-1 ms;
- sensors: a 4th-order Butterworth anti-alias filter at 0.4 fs on both channels; angle
  noise 1e-5-5e-5 rad, torque noise 0.5-2 % of the perturbation torque's RMS; 16-bit
  quantisation of +-0.5 rad and +-100 N m;
- reflex (``+reflex``): gain set so that the reflex torque's fluctuation is 20-70 % of
  the intrinsic torque's RMS (Kearney et al. 1997: the reflex pathway explains up to
  about a third of the torque variance of active plantarflexors; the project's reklab
  estimates, 58 -> 88 % VAF), delay 40-50 ms (ankle stretch reflex; Kearney et al. 1997;
  Sobhani Tehrani & Kearney's 50 ms), threshold 0-0.05 rad/s,
  positive-velocity rectifier, 2nd-order activation at 1.5-3.5 Hz with damping 0.6-0.9
  (``reflex_other_damping``: 0.4-1.2 or a third-order/cascade form);
- time variations: linear drift to 0.5-2x by the end, saturating drift to 1.3-2.5x with
  tau 5-20 s, switching between 1 and 1.5-3x every 3-10 s, sinusoidal modulation of +-20-60 %
  with period 5-20 s;
- time-varying kinds with a reflex: in half the draws the reflex gain follows K's profile
  (50-100 % of its relative change);
- background torque (``torque_dependent``): 2-10 N m of either sign plus a voluntary torque
  of 20-50 % of the perturbation torque; K rises by 50-150 % (B half as much, the reflex gain
  as much) at the background plus twice the voluntary RMS (Hunter & Kearney 1982);
- moving joint: a sine through about -0.4..+0.2 rad (each end +-0.05) of period 10-20 s,
  or (30 % of draws) raised-cosine ramps of 1-3 s between 3-4 levels of that range held 2-6 s
  (Sobhani Tehrani & Kearney, IEEE TBME 69, 2022); K exponential in angle with 1.5-4 /rad
  (Weiss, Kearney & Hunter, J Biomech 19:727, 1986) or a U with its minimum near mid-range;
  with a reflex, half the draws have its gain exponential in angle, 1-3 /rad;
  ``moving_pilot``: the same, stored as the lab's pilot file is (less an unperturbed
  trial along the movement, RecordingSpec.movement_removed).

Two joints (``n_dof=2``): a planar arm on a 2-joint manipulandum (shoulder, elbow):
K diagonal 10-40 and 8-30 N m/rad with coupling 10-30 % of the geometric mean, B 0.3-2,
I 0.1-0.4 and 0.04-0.1 kg m^2 (Perreault, Kirsch & Crago, Exp Brain Res 141:312, 2001;
Gomi & Kawato, Biol Cybern 76:163, 1997), servo at 30-60 Hz, perturbation to 20 Hz.
"""

from __future__ import annotations

import copy

import numpy as np

from .spec import (Channel, Filter, Footplate, Limb, Movement, Perturbation, RecordingSpec,
                   Reflex, Sensors, Servo, Variation, Voluntary, WobblingMass)

KINDS = ("nominal", "nominal_coloured_noise", "voluntary", "footplate_friction",
         "reflex_other_damping", "wobbling_other_damping", "antialias_filter",
         "linear_drift", "saturating_drift", "switching", "modulated",
         "moving_angle_dependent", "moving_linear", "channel_delay", "rest_period",
         "stiffening_spring", "short_range_stiffness", "backlash", "contact_clipping",
         "moving_pilot", "torque_dependent")


def _u(rng, lo, hi):
    return float(rng.uniform(lo, hi))


def _logu(rng, lo, hi):
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def torque_scale(K, B, I, amplitude_rad, f_hz) -> float:
    """RMS torque [N m] of a K-B-I limb under angle noise flat to ``f_hz`` of RMS
    ``amplitude_rad`` (one joint; the noise levels of the draws are set from it)."""
    f = np.linspace(0, f_hz, 400)
    w = 2 * np.pi * f
    z2 = (K - w * w * I) ** 2 + (w * B) ** 2
    return float(amplitude_rad * np.sqrt(np.mean(z2)))


def _perturbation(rng, n_dof, f_top):
    choice = rng.integers(3)
    if choice == 0:
        return Perturbation(kind="noise", amplitude_rad=_u(rng, 0.01, 0.03),
                            band_hz=[0.0, _u(rng, 0.75, 1.1) * f_top], order=8)
    if choice == 1:
        return Perturbation(kind="prbs", amplitude_rad=_u(rng, 0.02, 0.04),
                            switch_s=_u(rng, 0.1, 0.2))
    return Perturbation(kind="multisine", amplitude_rad=_u(rng, 0.01, 0.03),
                        band_hz=[0.1, f_top])


def _limb(rng, n_dof):
    if n_dof == 1:
        return Limb(K=_logu(rng, 20, 200), B=_u(rng, 0.5, 3.0), I=_u(rng, 0.01, 0.03))
    k1, k2 = _u(rng, 10, 40), _u(rng, 8, 30)
    kc = _u(rng, 0.1, 0.3) * np.sqrt(k1 * k2)
    b1, b2 = _u(rng, 0.5, 2.0), _u(rng, 0.3, 1.5)
    bc = _u(rng, 0.1, 0.3) * np.sqrt(b1 * b2)
    i1, i2 = _u(rng, 0.1, 0.4), _u(rng, 0.04, 0.1)
    ic = _u(rng, 0.2, 0.5) * np.sqrt(i1 * i2)
    return Limb(K=[[k1, kc], [kc, k2]], B=[[b1, bc], [bc, b2]], I=[[i1, ic], [ic, i2]])


def _reflex(rng, n_dof, other_damping=False):
    form, damping, tau = "second_order", _u(rng, 0.6, 0.9), 0.02
    if other_damping:
        form = ["second_order", "second_order", "triple_pole", "cascade"][rng.integers(4)]
        damping = _u(rng, 0.4, 1.2)
        tau = _u(rng, 0.01, 0.04)
    gain = 0.0 if n_dof == 1 else [_u(rng, 2, 8), _u(rng, 1, 5)]
    return Reflex(gain=gain, fraction=_u(rng, 0.2, 0.7) if n_dof == 1 else None,
                  delay_s=_u(rng, 0.040, 0.050),
                  threshold_rad_s=_u(rng, 0.0, 0.05), rectify="positive", form=form,
                  f_hz=_u(rng, 1.5, 3.5), damping=damping, tau_s=tau)


def _sensors(rng, tau_rms, coloured=False):
    theta = Channel(white_std=_logu(rng, 1e-5, 5e-5), resolution=1.0 / 2 ** 16)
    tau = Channel(white_std=_u(rng, 0.005, 0.02) * tau_rms, resolution=200.0 / 2 ** 16)
    if coloured:
        mains = float(rng.choice([50.0, 60.0]))
        for ch, scale in ((theta, theta.white_std), (tau, tau.white_std)):
            ch.pink_std = _u(rng, 1.0, 3.0) * scale
            ch.hum_std = _u(rng, 0.5, 2.0) * scale
            ch.hum_hz = mains
            ch.hum_harmonics = [1.0, _u(rng, 0.1, 0.5), _u(rng, 0.05, 0.3)]
    return Sensors(antialias=Filter(kind="butterworth", order=4), theta=theta, tau=tau,
                   torque_sign=int(rng.choice([1, -1])))


def _variation(rng, kind):
    if kind == "linear_drift":
        return Variation(time="linear", ratio=_logu(rng, 0.5, 2.0))
    if kind == "saturating_drift":
        return Variation(time="saturating", ratio=_u(rng, 1.3, 2.5), tau_s=_u(rng, 5, 20))
    if kind == "switching":
        return Variation(time="switching", ratio=_u(rng, 1.5, 3.0),
                         period_s=2 * _u(rng, 3, 10))
    if kind == "modulated":
        return Variation(time="sine", ratio=1.0 + _u(rng, 0.2, 0.6) * rng.choice([-1, 1]),
                         period_s=_u(rng, 5, 20), phase_s=_u(rng, 0, 20))
    raise ValueError(kind)


def draw(kind: str, rng: np.random.Generator, *, n_dof: int = 1, reflex: bool | None = None,
         duration_s: float = 60.0, fs: float = 1000.0) -> RecordingSpec:
    """A random spec of one kind (module docstring for the ranges).

    Parameters
    ----------
    kind : one of :data:`KINDS`, optionally suffixed ``+reflex`` (or ``-reflex``)
    rng : numpy Generator (the draws and the recording's seed come from it)
    n_dof : 1 (ankle) or 2 (planar arm)
    reflex : add a stretch reflex (None: as the suffix says; default without)
    duration_s, fs : length [s] and sampling rate [Hz]

    Raises
    ------
    ValueError
        An unknown kind (the message lists the kinds).
    """
    base, _, suffix = kind.partition("+")
    if base.endswith("-reflex"):
        base, suffix = base[:-len("-reflex")], ""
    if base not in KINDS or suffix not in ("", "reflex"):
        raise ValueError(f"unknown kind {kind!r}; kinds: {', '.join(KINDS)} (each also as "
                         f"KIND+reflex)")
    if n_dof not in (1, 2):
        raise ValueError(f"n_dof must be 1 or 2, got {n_dof!r}")
    with_reflex = (suffix == "reflex") if reflex is None else bool(reflex)
    f_top = 40.0 if n_dof == 1 else 20.0
    limb = _limb(rng, n_dof)
    pert = _perturbation(rng, n_dof, f_top)
    if n_dof == 2:
        pert.amplitude_rad *= 0.5  # the arm: 5-15 mrad (Perreault et al. 2001)
        pert.joints = [1, 2] if rng.uniform() < 0.5 else [int(rng.integers(1, 3))]
    servo = Servo(kind="pd", f_hz=_u(rng, 50, 120) if n_dof == 1 else _u(rng, 30, 60),
                  damping=_u(rng, 0.6, 1.0),
                  motor_inertia=_u(rng, 0.01, 0.05) if n_dof == 1 else _u(rng, 0.05, 0.2),
                  actuator_lag_s=_u(rng, 0.0003, 0.001), dac="continuous")
    K1, B1, I1 = (float(np.atleast_2d(getattr(limb, k))[0, 0]) for k in ("K", "B", "I"))
    amp = pert.amplitude_rad if pert.kind != "prbs" else 0.7 * pert.amplitude_rad
    tau_rms = torque_scale(K1, B1, I1, amp, f_top if pert.kind != "prbs" else 10.0)
    spec = RecordingSpec(duration_s=duration_s, fs=fs, n_dof=n_dof,
                         seed=int(rng.integers(2 ** 31)), perturbation=pert, servo=servo,
                         limb=limb, kind=kind,
                         sensors=_sensors(rng, tau_rms, base == "nominal_coloured_noise"))
    if with_reflex:
        spec.reflex = _reflex(rng, n_dof, base == "reflex_other_damping")
    _apply_kind(spec, base, rng, n_dof, I1, tau_rms)
    return spec


def _apply_kind(spec, base, rng, n_dof, I1, tau_rms):
    limb = spec.limb
    if base == "voluntary":
        spec.voluntary = Voluntary(fraction=_u(rng, 0.1, 0.5), band_hz=_u(rng, 1.0, 2.0))
    elif base == "footplate_friction":
        model = "tanh" if rng.uniform() < 0.5 else "lugre"
        spec.footplate = Footplate(friction=model, friction_fraction=_u(rng, 0.02, 0.1),
                                   v_s=_u(rng, 0.03, 0.1))
    elif base == "reflex_other_damping" and spec.reflex is None:
        spec.reflex = _reflex(rng, n_dof, True)
    elif base == "wobbling_other_damping":
        spec.wobbling = WobblingMass(inertia=_u(rng, 0.1, 0.3) * I1, f_hz=_u(rng, 8, 20),
                                     damping=_u(rng, 0.1, 0.6))
    elif base == "antialias_filter":
        spec.sensors.tau.filter = Filter(kind="second_order", cutoff_hz=_u(rng, 50, 200),
                                         damping=_u(rng, 0.5, 0.9))
    elif base in ("linear_drift", "saturating_drift", "switching", "modulated"):
        limb.K_var = _variation(rng, base)
        if rng.uniform() < 0.5:  # B often follows K (co-contraction)
            v = _variation(rng, base)
            v.ratio = float(1.0 + 0.5 * (limb.K_var.ratio - 1.0))
            for k in ("tau_s", "period_s", "phase_s"):
                setattr(v, k, getattr(limb.K_var, k))
            limb.B_var = v
        if spec.reflex is not None and rng.uniform() < 0.5:  # the reflex gain too
            g = copy.copy(limb.K_var)
            g.ratio = float(1.0 + _u(rng, 0.5, 1.0) * (limb.K_var.ratio - 1.0))
            spec.reflex.gain_var = g
    elif base == "torque_dependent":
        bg = _u(rng, 2.0, 10.0) * rng.choice([-1.0, 1.0])
        limb.background_torque_nm = bg if n_dof == 1 else [bg, 0.0]
        frac = _u(rng, 0.2, 0.5)
        spec.voluntary = Voluntary(fraction=frac, band_hz=_u(rng, 1.0, 2.0))
        # K rises by 50-150 % at the background torque plus twice the voluntary RMS
        top = abs(bg) + 2 * frac * tau_rms
        limb.K_var = Variation(torque_coef=_u(rng, 0.5, 1.5) / top)
        limb.B_var = Variation(torque_coef=0.5 * limb.K_var.torque_coef)
        if spec.reflex is not None:
            spec.reflex.gain_var = Variation(torque_coef=_u(rng, 0.5, 1.5) / top)
    elif base in ("moving_angle_dependent", "moving_linear", "moving_pilot"):
        lo, hi = -0.4 + _u(rng, -0.05, 0.05), 0.2 + _u(rng, -0.05, 0.05)
        if rng.uniform() < 0.7:
            spec.movement = Movement(kind="sine", range_rad=[lo, hi],
                                     period_s=_u(rng, 10, 20), phase_rad=_u(rng, 0, 2 * np.pi))
        else:  # ramps and holds through the range
            levels = list(rng.permutation(np.linspace(lo, hi, int(rng.integers(3, 5)))))
            spec.movement = Movement(kind="ramps", levels_rad=[float(v) for v in levels],
                                     ramp_s=_u(rng, 1.0, 3.0), hold_s=_u(rng, 2.0, 6.0))
        spec.perturbation.amplitude_rad *= 0.7
        spec.movement_removed = base == "moving_pilot"
        if base in ("moving_angle_dependent", "moving_pilot"):
            if rng.uniform() < 0.6:
                limb.K_var = Variation(angle="exp", angle_coef=_u(rng, 1.5, 4.0))
            else:
                mid = 0.5 * (lo + hi) + _u(rng, -0.05, 0.05)
                span = 0.5 * (hi - lo)
                limb.K_var = Variation(angle="quadratic", angle_ref_rad=mid,
                                       angle_coef=_u(rng, 1.0, 3.0) / span ** 2)
            if rng.uniform() < 0.5:
                limb.B_var = Variation(angle="linear", angle_coef=_u(rng, -1.0, 1.0))
            if spec.reflex is not None and rng.uniform() < 0.5:
                # stretch reflex gain rising with dorsiflexion (Mirbagheri et al. 2000)
                spec.reflex.gain_var = Variation(angle="exp", angle_coef=_u(rng, 1.0, 3.0))
    elif base == "channel_delay":
        spec.sensors.tau.delay_s = _u(rng, 0.0005, 0.003)
    elif base == "rest_period":
        a = _u(rng, 0.2, 0.6) * spec.duration_s
        spec.perturbation.rest = [[a, a + min(_u(rng, 5, 10), 0.3 * spec.duration_s)]]
    elif base == "stiffening_spring":
        K = float(np.atleast_2d(limb.K)[0, 0])
        amp = spec.perturbation.amplitude_rad
        # 3 k3 x^2 reaches 20-80 % of K at twice the perturbation's RMS
        limb.k3 = _u(rng, 0.2, 0.8) * K / (3 * (2 * amp) ** 2)
    elif base == "short_range_stiffness":
        K = float(np.atleast_2d(limb.K)[0, 0])
        limb.srs_K = _u(rng, 0.3, 1.0) * K
        limb.srs_limit_rad = _u(rng, 0.3, 1.0) * spec.perturbation.amplitude_rad
    elif base == "backlash":
        spec.footplate = Footplate(backlash_rad=_u(rng, 0.05, 0.2) *
                                   spec.perturbation.amplitude_rad,
                                   contact_hz=_u(rng, 100, 200))
    elif base == "contact_clipping":
        # the subject pushes (background torque) and the contact slips beyond a limit
        # reached by the larger perturbation torques of the opposite sign
        bg = _u(rng, 2.0, 8.0)
        limb.background_torque_nm = bg if n_dof == 1 else [bg, 0.0]
        spec.footplate = Footplate(contact_limit_nm=bg + _u(rng, 1.0, 2.0) * tau_rms)
