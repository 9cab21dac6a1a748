"""The scheduling variable of a trial: what the joint's impedance changes with.

A joint perturbed while it moves (or while its background torque changes) has an impedance
that varies with a *scheduling variable* (SV): the angle, the background torque, or time
(parameter-varying identification, Sobhani Tehrani & Kearney, IEEE TBME 2022). This module
finds it; it estimates nothing.

:func:`scheduling_of` resolves, in order:

1. ``requested`` (the CLI's ``--scheduling NAME``);
2. the metadata key ``scheduling`` (a name, or ``{"name": NAME, "units": UNITS}``: a CSV
   trial's JSON, an nldat sidecar; docs/spec/log-format.md);
3. an extra column named ``sv`` or described as a scheduling variable (an nldat variable
   ``sv``, or one whose channel name contains "scheduling"), with a note;
4. the default rule, with a note: the slow part of the measured angle ``theta[j]``
   (zero-phase low-pass below :data:`SLOW_CUTOFF_HZ`) when the joint *moves beyond its
   perturbation*: the 1-99 % range of the slow part exceeds :data:`MOVING_RATIO` times the
   standard deviation of the fast part (the perturbation and noise). The first joint that
   moves is taken;
5. otherwise None: a stationary recording, no scheduling.

Names: ``time`` (``trial.t`` [s]); ``angle`` (the perturbed joint, joint 1 when all or one)
and ``angle[j]`` (the slow part of ``theta[j]`` [rad]; absolute, posture added, when the
metadata declare ``"angles": "absolute"``); any extra column (``trial.extra``: a CSV
column, an nldat variable of the file). Units of an extra column: ``units`` of the
``scheduling`` key, else ``auxiliary.NAME.units`` of the metadata (the nldat reader's
``chanUnits``), else "" (not stated).

The cut-off, 0.5 Hz: a scheduled impedance is estimated from windows of a few seconds, so
only variation slower than about 0.5 Hz (periods over 2 s) can schedule it; the
perturbations that identify it have their power and fit band above about 1 Hz. On the
measured recordings: the stationary ankle recordings' slow part spans 2.3-2.5 times their
fast part's std (the perturbation's own power below 0.5 Hz), the moving pilot recording's
ankle angle 30 times: the threshold 5 lies between with a factor 2 to spare.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .errors import SchedulingError

#: cut-off [Hz] of the slow part of a signal (module docstring)
SLOW_CUTOFF_HZ = 0.5
#: order of the Butterworth low-pass, run forward and backward (zero phase, order 4)
SLOW_ORDER = 2
#: a joint moves beyond its perturbation when the slow part's 1-99 % range exceeds this
#: many standard deviations of the fast part (module docstring)
MOVING_RATIO = 5.0
#: a scheduling variable covers too narrow a range for a varying fit when its slow part's
#: 1-99 % range is below MOVING_RATIO times its fast part's std, or below this fraction of
#: its mean magnitude (a background torque of 10 +- 0.2 N m)
MIN_RANGE_FRACTION = 0.05
_ANGLE = re.compile(r"^angle(?:\[(\d+)\])?$")
#: extra-column names taken as the scheduling variable by default (case ignored)
DEFAULT_NAMES = ("sv",)


@dataclass(frozen=True)
class Scheduling:
    """The scheduling variable of one trial.

    Attributes
    ----------
    name : str
        ``"sv"``, a column name, ``"time"``, ``"angle[1]"``...
    units : str
        ``"rad"``, ``"s"``, ``"N m"`` or the file's stated units; "" when not stated.
    values : ndarray, shape (N,), float64
        One value per sample of the trial, in ``units``.
    source : str
        Where it came from: ``"nldat variable 'sv' of FILE.mat"``, ``"column 'sv'"``,
        ``"time"``, ``"slow part of theta[1] (< 0.5 Hz)"``.
    note : str or None
        One line for the output when it was chosen by default (not requested or declared).
    fs : float or None
        The trial's sample rate [Hz] (for :func:`narrow_range`).
    noise_std : float or None
        For a slow part (``angle``): the std of the fast part it was separated from (the
        perturbation and noise), in ``units``; None when the values are the signal itself.
    """

    name: str
    units: str
    values: np.ndarray
    source: str
    note: str | None = None
    fs: float | None = None
    noise_std: float | None = None

    def describe(self) -> str:
        """``sv [rad] (nldat variable 'sv' of F.mat): -0.412..0.203 rad``."""
        units = f" {self.units}" if self.units else ""
        shown = f" [{self.units}]" if self.units else " (units not stated)"
        lo, hi = float(np.min(self.values)), float(np.max(self.values))
        return f"{self.name}{shown} ({self.source}): {lo:.4g}..{hi:.4g}{units}"


def where(trial) -> str:
    """The trial as messages name it: ``trial 'io' (FILE.mat)``."""
    src = getattr(trial, "_source", None) or getattr(trial, "source_arg", None)
    text = str((trial.meta or {}).get("source", ""))
    if src is None and text.startswith("NLID nldat "):  # the nldat reader names the file
        src = text.split(";")[0][len("NLID nldat "):].split(" (")[0]
    return f"trial {trial.name or '(unnamed)'!r}" + (f" ({src})" if src else "")


def slow_part(x: np.ndarray, fs: float, cutoff_hz: float = SLOW_CUTOFF_HZ) -> np.ndarray:
    """Zero-phase Butterworth low-pass of ``x`` (N,) at ``cutoff_hz`` [Hz] (order
    :data:`SLOW_ORDER`, forward and backward: scipy.signal.sosfiltfilt). Raises ValueError
    when ``cutoff_hz`` is not below fs/2."""
    from scipy import signal
    if not 0 < cutoff_hz < fs / 2:
        raise ValueError(f"cut-off {cutoff_hz:g} Hz is not below fs/2 = {fs / 2:g} Hz")
    sos = signal.butter(SLOW_ORDER, cutoff_hz, fs=fs, output="sos")
    pad = min(len(x) - 1, int(3 * fs / cutoff_hz))
    return signal.sosfiltfilt(sos, np.asarray(x, dtype=float), padlen=max(pad, 0))


def spread(x: np.ndarray, fs: float) -> tuple[float, float]:
    """``(span, noise)``: the 1-99 % range of the slow part of ``x`` and the standard
    deviation of the rest (same units as ``x``)."""
    slow = slow_part(x, fs)
    lo, hi = np.percentile(slow, [1, 99])
    return float(hi - lo), float(np.std(x - slow))


def narrow_range(sched: Scheduling, *, noise_std: float | None = None,
                 ratio: float = MOVING_RATIO,
                 min_fraction: float = MIN_RANGE_FRACTION) -> str | None:
    """Why ``sched`` covers too narrow a range for a parameter-varying fit, or None.

    Too narrow: the 1-99 % range of its slow part is below ``ratio`` times ``noise_std``
    (default: ``sched.noise_std``, else the std of its own fast part), or below
    ``min_fraction`` of its mean magnitude. A caller may then keep the time-invariant
    answer and say why (or call :func:`check_range` to refuse).
    """
    x = np.asarray(sched.values, dtype=float)
    fs = sched.fs
    if fs is None or not SLOW_CUTOFF_HZ < fs / 2 or len(x) < 3:
        lo, hi = np.percentile(x, [1, 99])
        span, noise = float(hi - lo), 0.0
    else:
        span, noise = spread(x, fs)
    if noise_std is None and sched.noise_std is not None:
        noise_std = sched.noise_std
    noise = noise if noise_std is None else float(noise_std)
    units = f" {sched.units}" if sched.units else ""
    mean = float(np.mean(np.abs(x)))
    if span <= ratio * noise:
        return (f"its slow part spans {span:.3g}{units}, within {ratio:g} times its fast "
                f"part's std {noise:.3g}{units} (perturbation and noise)")
    if span < min_fraction * mean:
        return (f"it spans {span:.3g}{units}, less than {100 * min_fraction:g} % of its "
                f"mean magnitude {mean:.4g}{units}")
    return None


def check_range(sched: Scheduling, trial=None, **kw) -> None:
    """Raise SchedulingError when :func:`narrow_range` finds the range too narrow (the
    message names the variable, the trial and the reason); ``kw`` as narrow_range's."""
    why = narrow_range(sched, **kw)
    if why:
        at = f" of {where(trial)}" if trial is not None else ""
        raise SchedulingError(f"scheduling variable {sched.name!r}{at}: range too narrow "
                              f"for a parameter-varying fit: {why}; keep the time-invariant "
                              f"estimate, or choose another (--scheduling NAME)")


def varying_refusal(sched: Scheduling, trial_name: str) -> str | None:
    """The one refusal of a scheduling variable for a parameter-varying fit, shared by
    ``armimp estimate`` (estimation.pvlab) and ``armimp diagnose`` (its state-varying
    effects): the notice naming the variable, the trial and why (its range too narrow,
    :func:`narrow_range`; ``time`` is never refused), or None when the variable can be
    used."""
    why = None if sched.name == "time" else narrow_range(sched)
    if not why:
        return None
    return (f"scheduling variable {sched.name!r} of {trial_name}: range too narrow for a "
            f"parameter-varying fit ({why}): the time-invariant estimate is kept; a "
            f"variable the joint's state moves through (time, angle, or one spanning more) "
            f"would work")


def usage(trial) -> dict | None:
    """What a command did with ``trial``'s scheduling variable, for its reports:
    ``{"trial", "name", "units", "source", "range": [min, max], "how": "requested" |
    "declared" | "default", "used": bool, "refusal": notice or None}``;
    None for a stationary recording (no variable). A named variable that cannot be read
    raises SchedulingError as :func:`scheduling_of`."""
    s = scheduling_of(trial)
    if s is None:
        return None
    refusal = varying_refusal(s, trial.name)
    declared = (trial.meta or {}).get("scheduling")
    how = "default" if s.note is not None else (
        "declared" if declared is not None else "requested")
    lo, hi = float(np.min(s.values)), float(np.max(s.values))
    return {"trial": trial.name, "name": s.name, "units": s.units, "source": s.source,
            "range": [lo, hi], "how": how, "used": refusal is None, "refusal": refusal}


def scheduling_of(trial, requested: str | None = None) -> Scheduling | None:
    """The scheduling variable of ``trial`` (resolution order: module docstring).

    Parameters
    ----------
    trial : trialformat.Trial
    requested : str or None
        A name (``--scheduling NAME``): ``time``, ``angle``, ``angle[j]``, an extra column.

    Returns
    -------
    Scheduling, or None for a stationary recording with nothing requested or declared.

    Raises
    ------
    SchedulingError
        A requested or declared variable that is unknown (the message lists the names
        available), of another length than the trial, constant (its value), NaN or
        infinite (the first such sample, 0-based); a malformed ``scheduling`` key. A
        variable taken by default is never refused: it is passed over with a note.
    """
    if requested is not None:
        return _named(trial, str(requested), None, "requested")
    declared = (trial.meta or {}).get("scheduling")
    if declared is not None:
        name, units = _declared(trial, declared)
        return _named(trial, name, units, "declared")
    passed = []
    for name in _default_columns(trial):
        try:
            s = _named(trial, name, None, "default")
        except SchedulingError as exc:
            passed.append(f"{name!r} passed over: {str(exc).split(': ', 1)[-1]}")
            continue
        return _with_note(s, f"scheduling variable {s.describe()}, taken by default "
                             f"(its name says so); --scheduling NAME chooses another")
    s = _moving_angle(trial)
    if s is not None:
        return _with_note(s, s.note + ("; " + "; ".join(passed) if passed else ""))
    if passed:
        import warnings
        warnings.warn(f"{where(trial)}: no scheduling variable: " + "; ".join(passed),
                      stacklevel=2)
    return None


def request(trial, name: str) -> Scheduling:
    """Declare ``name`` the scheduling variable of ``trial`` (its ``meta["scheduling"]``,
    keeping declared units of the same name) and return it; SchedulingError as
    :func:`scheduling_of`. Used by the CLIs' ``--scheduling NAME``."""
    meta = trial.meta
    old = meta.get("scheduling")
    if isinstance(old, dict) and old.get("name") == name:
        return scheduling_of(trial)
    found = scheduling_of(trial, name)  # refused as requested, before the metadata change
    meta["scheduling"] = name
    return found


# ----------------------------------------------------------------------------- helpers


def _with_note(s: Scheduling, note: str) -> Scheduling:
    return Scheduling(s.name, s.units, s.values, s.source, note, s.fs, s.noise_std)


def _declared(trial, declared) -> tuple[str, str | None]:
    if isinstance(declared, str) and declared:
        return declared, None
    if isinstance(declared, dict) and isinstance(declared.get("name"), str) and \
            declared["name"] and isinstance(declared.get("units", ""), (str, type(None))):
        return declared["name"], declared.get("units")
    raise SchedulingError(f"{where(trial)}: metadata key 'scheduling' must be a name "
                          f"(\"sv\") or {{\"name\": \"sv\", \"units\": \"rad\"}}, got "
                          f"{declared!r}")


def _default_columns(trial) -> list:
    aux = (trial.meta or {}).get("auxiliary") or {}
    out = []
    for name in trial.extra:
        desc = str((aux.get(name) or {}).get("description", "")) if isinstance(aux, dict) \
            else ""
        if name.lower() in DEFAULT_NAMES or "scheduling" in desc.lower():
            out.append(name)
    return out


def available(trial) -> list:
    """The names ``scheduling_of`` accepts for ``trial``, described."""
    aux = (trial.meta or {}).get("auxiliary") or {}
    names = []
    for name in trial.extra:
        kind = "nldat variable" if name in aux else "column"
        names.append(f"{name} ({kind})")
    names += [f"{k} (nldat variable, skipped: {v['skipped']})" for k, v in aux.items()
              if isinstance(v, dict) and "skipped" in v]
    n = trial.theta.shape[1] if trial.theta is not None else 0
    names.append("time")
    if n:
        names.append("angle" + (f", angle[1]..angle[{n}]" if n > 1 else ", angle[1]"))
    return names


def _named(trial, name: str, units: str | None, how: str) -> Scheduling:
    """The variable ``name`` of ``trial``, checked; ``how``: requested, declared, default."""
    said = {"requested": "requested (--scheduling)", "declared":
            "declared (metadata 'scheduling')", "default": "taken by default"}[how]
    if name == "time":
        return _checked(trial, Scheduling("time", "s", np.asarray(trial.t, dtype=float),
                                          "time", None, trial.fs), said)
    m = _ANGLE.match(name)
    if m:
        return _checked(trial, _angle(trial, m.group(1), said), said)
    aux = (trial.meta or {}).get("auxiliary") or {}
    info = aux.get(name) if isinstance(aux, dict) else None
    if name not in trial.extra:
        if isinstance(info, dict) and "skipped" in info:
            raise SchedulingError(f"{where(trial)}: scheduling variable {name!r} {said}: "
                                  f"{info.get('source', name)} could not be attached: "
                                  f"{info['skipped']}; it must have the recording's length "
                                  f"and rate")
        raise SchedulingError(f"{where(trial)}: scheduling variable {name!r} {said}: no "
                              f"such variable; available: {'; '.join(available(trial))}")
    if units is None and isinstance(info, dict):
        units = info.get("units")
    source = info.get("source") if isinstance(info, dict) and info.get("source") else \
        f"column '{name}'"
    values = np.asarray(trial.extra[name], dtype=float).reshape(-1)
    return _checked(trial, Scheduling(name, units or "", values, source, None, trial.fs),
                    said)


def _angle(trial, joint: str | None, said: str) -> Scheduling:
    if trial.theta is None:
        raise SchedulingError(f"{where(trial)}: scheduling variable 'angle' {said}: the "
                              f"trial carries no angle theta")
    n = trial.theta.shape[1]
    j = int(joint) if joint else (trial.perturbed_dof or 1)
    if not 1 <= j <= n:
        raise SchedulingError(f"{where(trial)}: scheduling variable 'angle[{j}]' {said}: "
                              f"the trial has {n} joint(s); available: "
                              f"{'; '.join(available(trial))}")
    x = np.asarray(trial.theta[:, j - 1], dtype=float)
    if not np.all(np.isfinite(x)):
        return Scheduling(f"angle[{j}]", "rad", x, f"theta[{j}]", None, trial.fs)
    try:
        values = slow_part(x, trial.fs)
    except ValueError as exc:
        raise SchedulingError(f"{where(trial)}: scheduling variable 'angle[{j}]' {said}: "
                              f"no slow part at fs {trial.fs:g} Hz ({exc})") from None
    noise = float(np.std(x - values))
    source = f"slow part of theta[{j}] (< {SLOW_CUTOFF_HZ:g} Hz)"
    if trial.meta.get("angles") == "absolute" and trial.meta.get("posture_deg") is not None:
        values = values + np.deg2rad(float(np.ravel(trial.meta["posture_deg"])[j - 1]))
        source += ", posture added (absolute angle)"
    return Scheduling(f"angle[{j}]", "rad", values, source, None, trial.fs, noise)


def _checked(trial, s: Scheduling, said: str) -> Scheduling:
    """Refuse another length, NaN/inf, a constant; ``s`` otherwise."""
    at = f"{where(trial)}: scheduling variable {s.name!r} ({s.source}) {said}"
    x = s.values
    if x.shape != (trial.n_samples,):
        raise SchedulingError(f"{at}: {x.size} values for the trial's {trial.n_samples} "
                              f"samples; it must have one per sample, at {trial.fs:g} Hz")
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise SchedulingError(f"{at}: {'NaN' if np.isnan(x[bad[0]]) else x[bad[0]]} at "
                              f"sample {bad[0]} (0-based; {bad.size} non-finite in all); "
                              f"give a variable with a finite value at every sample")
    if x.size and np.all(x == x[0]):
        units = f" {s.units}" if s.units else ""
        raise SchedulingError(f"{at}: constant ({x[0]:.6g}{units} at every sample): "
                              f"nothing to schedule on; omit it for a time-invariant "
                              f"estimate, or choose another (time, angle)")
    return s


def _moving_angle(trial) -> Scheduling | None:
    """The default rule: the slow part of the first joint's angle that moves beyond its
    perturbation (module docstring), or None."""
    if trial.theta is None or not SLOW_CUTOFF_HZ < trial.fs / 2:
        return None
    for j in range(1, trial.theta.shape[1] + 1):
        x = np.asarray(trial.theta[:, j - 1], dtype=float)
        if x.size < 3 or not np.all(np.isfinite(x)):
            continue
        span, noise = spread(x, trial.fs)
        if span > MOVING_RATIO * noise:
            s = _angle(trial, str(j), "taken by default")
            ratio = f"{span / noise:.3g} times" if noise > 0 else "above"
            note = (f"scheduling variable {s.describe()}, taken by default: the joint moves "
                    f"beyond its perturbation (slow part spans {span:.3g} rad, {ratio} the "
                    f"fast part's std {noise:.3g} rad; more than {MOVING_RATIO:g}); "
                    f"--scheduling NAME chooses another")
            return _with_note(s, note)
    return None
