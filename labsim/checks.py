"""Refusals of a :class:`labsim.spec.RecordingSpec` before anything is simulated: each
message names the key (``servo.f_hz``), the value and what is allowed."""

from __future__ import annotations

import numpy as np


def _num(where: str, value, *, lo=None, hi=None, lo_open=False, hi_open=False,
         allow_none=False):
    if value is None and allow_none:
        return
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    ok = ok and np.isfinite(value)
    if ok and lo is not None:
        ok = value > lo if lo_open else value >= lo
    if ok and hi is not None:
        ok = value < hi if hi_open else value <= hi
    if not ok:
        rng = []
        if lo is not None:
            rng.append(f"{'>' if lo_open else '>='} {lo:g}")
        if hi is not None:
            rng.append(f"{'<' if hi_open else '<='} {hi:g}")
        raise ValueError(f"{where} must be a finite number{' ' + ' and '.join(rng) if rng else ''}"
                         f", got {value!r}")


def _choice(where: str, value, allowed) -> None:
    if value not in allowed:
        raise ValueError(f"{where} must be one of {', '.join(map(repr, allowed))}; got {value!r}")


def _all(where: str, value, **kw) -> None:
    for v in np.ravel(np.asarray(value, dtype=object)):
        _num(where, v, **kw)


def check_spec(spec) -> None:
    """Raise ValueError naming the first bad value of ``spec``."""
    if not isinstance(spec.n_dof, (int, np.integer)) or spec.n_dof < 1:
        raise ValueError(f"n_dof must be an integer >= 1, got {spec.n_dof!r}")
    if not isinstance(spec.oversample, (int, np.integer)) or spec.oversample < 1:
        raise ValueError(f"oversample must be an integer >= 1, got {spec.oversample!r}")
    _num("fs", spec.fs, lo=0, lo_open=True)
    _num("duration_s", spec.duration_s, lo=2.0 / spec.fs)
    _num("preroll_s", spec.preroll_s, lo=0.1)
    nyq, fine_nyq = 0.5 * spec.fs, 0.5 * spec.fs * spec.oversample
    _perturbation(spec, nyq)
    _movement(spec.movement)
    sv = spec.servo
    _choice("servo.kind", sv.kind, ("ideal", "pd"))
    _choice("servo.dac", sv.dac, ("zoh", "continuous"))
    if sv.kind == "pd":
        _num("servo.f_hz", sv.f_hz, lo=0, hi=fine_nyq / 5, lo_open=True)
        _num("servo.damping", sv.damping, lo=0, lo_open=True)
        _all("servo.motor_inertia", sv.motor_inertia, lo=0, lo_open=True)
        _num("servo.integral_hz", sv.integral_hz, lo=0)
        _num("servo.actuator_lag_s", sv.actuator_lag_s, lo=0)
    lb = spec.limb
    for k in ("K", "B", "I"):
        _all(f"limb.{k}", getattr(lb, k))
    if np.any(np.linalg.eigvalsh(_sym(lb.I, spec.n_dof)) < 0):
        raise ValueError(f"limb.I must be positive semi-definite, got {lb.I!r}")
    _num("limb.srs_limit_rad", lb.srs_limit_rad, lo=0, lo_open=True)
    for k in ("K_var", "B_var", "I_var"):
        _variation(f"limb.{k}", getattr(lb, k))
    _reflex(spec.reflex, spec.preroll_s)
    wm = spec.wobbling
    if wm is not None:
        _all("wobbling.inertia", wm.inertia, lo=0)
        _all("wobbling.f_hz", wm.f_hz, lo=0, hi=fine_nyq / 5, lo_open=True)
        _all("wobbling.damping", wm.damping, lo=0)
    fp = spec.footplate
    if fp is not None:
        _choice("footplate.friction", fp.friction, (None, "tanh", "lugre"))
        _num("footplate.v_s", fp.v_s, lo=0, lo_open=True)
        _num("footplate.Fc", fp.Fc, lo=0, allow_none=True)
        _num("footplate.Fs", fp.Fs, lo=0, allow_none=True)
        _num("footplate.friction_fraction", fp.friction_fraction, lo=0)
        _num("footplate.backlash_rad", fp.backlash_rad, lo=0)
        _num("footplate.contact_hz", fp.contact_hz, lo=0, hi=fine_nyq / 5, lo_open=True)
        _num("footplate.contact_limit_nm", fp.contact_limit_nm, lo=0, lo_open=True,
             allow_none=True)
    vol = spec.voluntary
    if vol is not None:
        _num("voluntary.band_hz", vol.band_hz, lo=0, hi=nyq, lo_open=True, hi_open=True)
        _num("voluntary.level_nm", vol.level_nm, lo=0, allow_none=True)
        _num("voluntary.fraction", vol.fraction, lo=0)
    _sensors(spec.sensors, spec, fine_nyq)


def _sym(value, n):
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        return np.eye(n) * float(a)
    if a.shape == (n,):
        return np.diag(a)
    if a.shape != (n, n):
        raise ValueError(f"limb matrix: expected a number, {n} numbers or {n}x{n}, got "
                         f"shape {a.shape}")
    return 0.5 * (a + a.T)


def _perturbation(spec, nyq) -> None:
    p = spec.perturbation
    _choice("perturbation.kind", p.kind, ("noise", "prbs", "multisine"))
    _num("perturbation.amplitude_rad", p.amplitude_rad, lo=0)
    if p.kind in ("noise", "multisine"):
        if len(p.band_hz) != 2:
            raise ValueError(f"perturbation.band_hz must be [low, high], got {p.band_hz!r}")
        _num("perturbation.band_hz[0]", p.band_hz[0], lo=0)
        _num("perturbation.band_hz[1]", p.band_hz[1], lo=p.band_hz[0], hi=nyq,
             lo_open=True, hi_open=True)
    if p.kind == "noise" and (not isinstance(p.order, (int, np.integer)) or p.order < 2):
        raise ValueError(f"perturbation.order must be an integer >= 2, got {p.order!r}")
    if p.kind == "prbs":
        _num("perturbation.switch_s", p.switch_s, lo=1.0 / spec.fs)
        _num("perturbation.prefilter_hz", p.prefilter_hz, lo=0, lo_open=True, hi=nyq,
             allow_none=True)
        if spec.servo.kind == "ideal" and p.prefilter_hz is None:
            raise ValueError("an ideal servo needs a smooth reference: give the PRBS a "
                             "perturbation.prefilter_hz (its steps have no finite velocity)")
    _choice("perturbation.phases", p.phases, ("random", "schroeder"))
    _num("perturbation.taper_s", p.taper_s, lo=0)
    for i, iv in enumerate(p.rest):
        if len(iv) != 2 or not (0 <= iv[0] < iv[1] <= spec.duration_s):
            raise ValueError(f"perturbation.rest[{i}] must be [start, end] with 0 <= start "
                             f"< end <= duration_s={spec.duration_s:g}, got {iv!r}")
    for j in p.joints or [1]:
        if not isinstance(j, (int, np.integer)) or not 1 <= j <= spec.n_dof:
            raise ValueError(f"perturbation.joints: {j!r} is not a joint 1..{spec.n_dof}")


def _movement(m) -> None:
    if m is None:
        return
    _choice("movement.kind", m.kind, ("sine", "ramps"))
    if m.kind == "sine":
        _num("movement.period_s", m.period_s, lo=0, lo_open=True)
        if len(m.range_rad) != 2 or not m.range_rad[0] < m.range_rad[1]:
            raise ValueError(f"movement.range_rad must be [low, high] with low < high, got "
                             f"{m.range_rad!r}")
    else:
        if not m.levels_rad:
            raise ValueError("movement.levels_rad is empty")
        _num("movement.ramp_s", m.ramp_s, lo=0)
        _num("movement.hold_s", m.hold_s, lo=0)
        if m.ramp_s + m.hold_s <= 0:
            raise ValueError("movement.ramp_s + movement.hold_s must be positive")


def _variation(where, v) -> None:
    if v is None:
        return
    _choice(f"{where}.time", v.time, ("constant", "linear", "saturating", "switching", "sine"))
    _choice(f"{where}.angle", v.angle, ("constant", "exp", "quadratic", "linear"))
    _num(f"{where}.ratio", v.ratio)
    if v.time == "saturating":
        _num(f"{where}.tau_s", v.tau_s, lo=0, lo_open=True)
    if v.time in ("switching", "sine"):
        _num(f"{where}.period_s", v.period_s, lo=0, lo_open=True)
    _num(f"{where}.angle_coef", v.angle_coef)
    _num(f"{where}.torque_coef", v.torque_coef)


def _reflex(rx, preroll) -> None:
    if rx is None:
        return
    _choice("reflex.rectify", rx.rectify, ("positive", "negative", "none"))
    _choice("reflex.form", rx.form, ("second_order", "triple_pole", "cascade"))
    _num("reflex.delay_s", rx.delay_s, lo=0, hi=preroll)
    _num("reflex.f_hz", rx.f_hz, lo=0, lo_open=True)
    _num("reflex.damping", rx.damping, lo=0, lo_open=True)
    _num("reflex.tau_s", rx.tau_s, lo=0, lo_open=True)
    _num("reflex.threshold_rad_s", rx.threshold_rad_s, lo=0)
    _num("reflex.fraction", rx.fraction, lo=0, allow_none=True)
    _all("reflex.gain", rx.gain)
    _variation("reflex.gain_var", rx.gain_var)


def _filter(where, f, fs, fine_nyq) -> None:
    if f is None:
        return
    _choice(f"{where}.kind", f.kind, ("butterworth", "bessel", "second_order"))
    _num(f"{where}.cutoff_hz", f.cutoff_hz, lo=0, lo_open=True, hi=fine_nyq / 5,
         allow_none=True)
    if f.kind != "second_order" and (not isinstance(f.order, (int, np.integer)) or f.order < 1):
        raise ValueError(f"{where}.order must be an integer >= 1, got {f.order!r}")
    _num(f"{where}.damping", f.damping, lo=0, lo_open=True)


def _sensors(s, spec, fine_nyq) -> None:
    if s.torque_sign not in (1, -1):
        raise ValueError(f"sensors.torque_sign must be 1 or -1, got {s.torque_sign!r}")
    _filter("sensors.antialias", s.antialias, spec.fs, fine_nyq)
    for name in ("theta", "tau"):
        ch = getattr(s, name)
        where = f"sensors.{name}"
        _filter(f"{where}.filter", ch.filter, spec.fs, fine_nyq)
        _num(f"{where}.delay_s", ch.delay_s, lo=0, hi=spec.preroll_s)
        for k in ("white_std", "pink_std", "hum_std", "resolution"):
            _num(f"{where}.{k}", getattr(ch, k), lo=0)
        if ch.hum_std:
            _num(f"{where}.hum_hz", ch.hum_hz, lo=0, lo_open=True, hi=0.5 * spec.fs,
                 hi_open=True)
        _num(f"{where}.offset", ch.offset)
