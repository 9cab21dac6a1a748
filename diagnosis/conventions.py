"""Conventions and set-up mismatches of measured trials: findings, not model errors.

A lab's file may follow another convention than log-format.md without declaring it: angles
logged as absolute joint angles where deviations from the posture are expected, the
interaction torque with the opposite sign, angles in degrees, ``t`` printed with finitely
many decimals. Such a mismatch would otherwise show up as a huge, "unexplained" gap. Each
is checked here from the data and the declared set-up alone (physical arguments, no
simulation), reported by name, and corrected before the diagnosis proper:

- declared conventions (log-format.md, "Conventions a lab states in the metadata"):
  ``"angles": "absolute"`` and ``"sensors": {"torque_sign": -1}`` are applied;
- **absolute angles**: the mean angle of every joint equals its posture (within 0.05 rad
  and a fifth of the posture) while deviations are declared;
- **angles in degrees**: a deviation beyond the master's angle limit (2 rad), which no
  trial of this set-up can have, that becomes a plausible one (< 0.5 rad) in radians;
- **torque sign reversed**: the arm impedance estimated from the trials has a negative
  stiffness on every joint (a passive limb's is positive), and a positive one with -tau_h;
- **t rounded** (a storage note, never a verdict): ``t`` is n / fs stored at its precision
  (float32, printed decimals); **t off the grid**: ``t`` differs from n / fs beyond its
  storage precision. Either way the trial is read on the uniform grid n / fs.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

# deviations are at most ANGLE_LIMIT_RAD in any trial the master runs; one read as degrees
# is plausible below PLAUSIBLE_DEVIATION_RAD
from trialformat.reference import ANGLE_LIMIT_RAD, PLAUSIBLE_DEVIATION_RAD

from .storage import detect_storage

ABSOLUTE_TOLERANCE_RAD = 0.05


@dataclasses.dataclass
class Finding:
    """A convention or set-up mismatch found in the measured trials.

    Attributes
    ----------
    name : str
        ``angles absolute``, ``angles in degrees``, ``torque sign reversed``,
        ``t rounded`` (or ``declared: ...`` for a declared convention applied).
    where : str
        Signal and trials concerned.
    evidence : str
        The numbers that show it.
    corrected : bool
        The diagnosis corrected the data and went on.
    note : bool
        A storage note, not a mismatch: the file stores the expected values at its
        precision (``t`` = n/fs in float32 or printed decimals). It never changes the
        verdict.
    storage : bool
        A finding on how ``t`` was stored or clocked (``t rounded``, ``t off the grid``):
        corrected by reading the trial on n / fs, it is reported beside the verdict on
        the gap and never replaces it (issue 21, item 7).
    """

    name: str
    where: str
    evidence: str
    corrected: bool = True
    note: bool = False
    storage: bool = False

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def text(self) -> str:
        return f"{self.name} ({self.where}): {self.evidence}" + (
            "; corrected" if self.corrected else "")


def merged_texts(findings) -> list[str]:
    """The findings' texts with repeats said once (README: a repeated note is said once
    with its count), in first order: the same finding on several trials (``declared:
    torque_sign -1`` on each of 10 files) reads ``name (10 trials: a, b, c, ...):
    evidence``; an identical text repeated reads ``text (x N)``."""
    groups: dict = {}
    for f in findings:
        key = (f.name, f.evidence, f.corrected)
        groups.setdefault(key, []).append(f.where)
    out = []
    for (name, evidence, corrected), places in groups.items():
        distinct = list(dict.fromkeys(places))
        if len(distinct) == 1:
            where = distinct[0]
        else:
            shown = ", ".join(distinct[:3]) + (", ..." if len(distinct) > 3 else "")
            where = f"{len(distinct)} trials: {shown}"
        text = Finding(name, where, evidence, corrected).text()
        repeats = len(places) // len(distinct)
        out.append(text + (f" (x {repeats})" if repeats > 1 else ""))
    return out


def _replace(trial, scale=None, offset=None, **arrays):
    """A corrected copy; its storage context is the raw trial's, seen through the
    correction corrected = raw * scale - offset (per signal), so that simulations are
    still stored as the raw numbers were."""
    from .evaluation import storage_context
    raw = storage_context(trial)
    out = dataclasses.replace(trial, **arrays)
    out._storage_context = raw.converted(scale or {}, offset or {})
    return out


def apply_declared(trials) -> tuple[list, list]:
    """Findings for the conventions the metadata declare; returns (trials, findings).

    The trial reader (trialformat.finish_trial) already returns declared conventions
    converted, so the trials are returned as they are: never converted twice."""
    findings = []
    for t in trials:
        if str(t.meta.get("angles", "")).lower() == "absolute":
            findings.append(Finding("declared: angles absolute", t.name,
                                    "posture subtracted by the reader"))
        if (t.meta.get("sensors") or {}).get("torque_sign", 1) == -1:
            findings.append(Finding("declared: torque_sign -1", t.name,
                                    "tau_h negated by the reader"))
    return list(trials), findings


def check_angles(trials) -> tuple[list, list]:
    """Absolute angles and angles in degrees (see module docstring)."""
    findings = []
    # a set-up without a declared posture (a position servo's) has deviations only
    posture = np.radians(np.asarray(trials[0].meta.get("posture_deg")
                                    or [0.0] * trials[0].n_dof, dtype=float))
    theta = np.vstack([t.theta for t in trials])
    mean = theta.mean(axis=0)
    spread = np.max(np.abs(theta - mean), axis=0)
    degrees = bool(np.any(spread > ANGLE_LIMIT_RAD)
                   and np.all(np.radians(spread) < PLAUSIBLE_DEVIATION_RAD))
    scale = math.pi / 180.0 if degrees else 1.0
    if degrees:
        findings.append(Finding(
            "angles in degrees", "theta, all trials",
            f"largest deviation {np.round(spread, 3).tolist()} beyond the {ANGLE_LIMIT_RAD} "
            f"rad any trial of this set-up can have; {np.round(np.radians(spread), 4).tolist()}"
            f" rad in degrees"))
    mean_rad = mean * scale
    near = np.abs(mean_rad - posture) < np.minimum(ABSOLUTE_TOLERANCE_RAD,
                                                    0.2 * np.abs(posture))
    absolute = bool(np.all(near) and np.all(np.abs(posture) > ABSOLUTE_TOLERANCE_RAD))
    if absolute:
        findings.append(Finding(
            "angles absolute", "theta, all trials",
            f"mean angle {np.round(mean_rad, 4).tolist()} rad equals the posture "
            f"{np.round(posture, 4).tolist()} rad while deviations are declared"))
    ref_scale = _theta_ref_scale(trials, scale, findings)
    if not findings:
        return trials, findings
    offset = posture if absolute else 0.0
    out = []
    for t in trials:
        scales, offsets = {"theta": scale}, {"theta": offset}
        arrays = {"theta": t.theta * scale - offset}
        if t.theta_ref is not None:  # the reference is an angle stored like theta
            scales["theta_ref"], offsets["theta_ref"] = ref_scale, offset
            arrays["theta_ref"] = t.theta_ref * ref_scale - offset
        out.append(_replace(t, scale=scales, offset=offsets, **arrays))
    return out, findings


def _theta_ref_scale(trials, theta_scale: float, findings: list) -> float:
    """Scale [rad per stored unit] of the trials' ``theta_ref``: that of ``theta``, unless
    the reference alone is in degrees (its deviation beyond :data:`ANGLE_LIMIT_RAD` while
    theta's is within it), which is a finding of its own (issue 22)."""
    refs = [t.theta_ref for t in trials if t.theta_ref is not None]
    if not refs:
        return theta_scale
    ref = np.vstack(refs)
    spread = np.max(np.abs(ref - ref.mean(axis=0)), axis=0)
    if theta_scale == 1.0 and np.any(spread > ANGLE_LIMIT_RAD) and \
            np.all(np.radians(spread) < PLAUSIBLE_DEVIATION_RAD):
        findings.append(Finding(
            "theta_ref in degrees", "theta_ref, all trials",
            f"largest deviation of the reference {np.round(spread, 3).tolist()} beyond the "
            f"{ANGLE_LIMIT_RAD} rad any trial can have while theta's is within it: the "
            f"reference is in degrees beside theta in radians; converted"))
        return math.pi / 180.0
    return theta_scale


def check_time(trials) -> list:
    """``t`` stored other than n / fs: the diagnosis uses n / fs either way.

    Judged against the storage precision of ``t`` (storage.detect_storage): a stored ``t``
    within half a storage step of n / fs at every sample (float32, printed decimals or
    digits) is n / fs stored at that precision, a storage note ("t rounded", ``note``
    True) that never changes the verdict; beyond, ``t`` itself is off the grid ("t off
    the grid": a clock that is not n / fs), a finding. The stored values are
    ``Trial.t_stored`` when the reader kept them (it returns ``t`` as the exact grid),
    else ``Trial.t``."""
    findings = []
    for t in trials:
        stored = t.t if getattr(t, "t_stored", None) is None else t.t_stored
        exact = np.arange(t.n_samples) / t.fs
        err = np.abs(stored - exact)
        off = np.max(err)
        if off > 0 and off > 4 * np.finfo(float).eps * exact[-1]:
            storage = detect_storage(stored)
            half = storage.max_error(exact) + 4 * np.spacing(np.abs(exact))
            if np.all(err <= half * (1 + 1e-6)):
                findings.append(Finding(
                    "t rounded", t.name,
                    f"t stored as {storage.describe()}, up to {off:.3g} s from n/fs: "
                    f"within its storage precision (half a step, up to "
                    f"{float(np.max(half)):.3g} s); read as uniform at fs = {t.fs:g} Hz",
                    note=True, storage=True))
            else:
                row = int(np.argmax(err > half * (1 + 1e-6)))
                findings.append(Finding(
                    "t off the grid", t.name,
                    f"t stored as {storage.describe()} is up to {off:.3g} s from n/fs, "
                    f"beyond its storage precision (at sample {row}: {err[row]:.3g} s, half "
                    f"a step {half[row]:.3g} s); read as uniform at fs = {t.fs:g} Hz",
                    storage=True))
    return findings


def check_torque_sign(trials, arm, estimate, k_scale: float = 1.0) -> tuple[list, object, list]:
    """A negative arm stiffness on every joint that turns positive with -tau_h means the
    torque was logged with the opposite sign. ``estimate(trials) -> ArmModel``;
    ``k_scale``: the factor from the trials' stiffness to the file's units, for the
    finding's text (rescaled trials, :func:`normalise_units`; 1 otherwise)."""
    if not np.all(np.diag(arm.K) < 0):
        return trials, arm, []
    if not _low_frequency_opposed(arm):
        # the fitted K is negative, but at the lowest frequencies torque follows the angle:
        # the band's upper part pulled K down (a reflex's notch does so), not the sign
        return trials, arm, []
    flipped = [_replace(t, scale={"tau_h": -1.0}, tau_h=-t.tau_h) for t in trials]
    arm_f = estimate(flipped)
    if not np.all(np.diag(arm_f.K) > 0):
        return trials, arm, []
    return flipped, arm_f, [Finding(
        "torque sign reversed", "tau_h, all trials",
        f"arm stiffness estimated {_shown(np.diag(arm.K) * k_scale)} N m/rad (a "
        f"passive limb's is positive); {_shown(np.diag(arm_f.K) * k_scale)} with -tau_h")]


def _shown(values) -> list:
    """Values with 5 significant digits (any units: a rounding to 3 decimals showed
    a stiffness of 1e-7 as 0)."""
    return [float(f"{v:.5g}") for v in np.asarray(values, float)]


#: the lowest frequencies [Hz] where a passive joint's impedance is stiffness-like (phase
#: near 0; a reversed torque sign puts it near 180 deg)
LOW_FREQUENCY_HZ = 1.5


def _low_frequency_opposed(arm) -> bool:
    """True when, below LOW_FREQUENCY_HZ, every diagonal Z_kk has its phase beyond 90 deg
    (median cosine < 0); True also when the arm carries no FRF to look at."""
    if getattr(arm, "Z", None) is None or getattr(arm, "f", None) is None:
        return True
    f, Z = np.asarray(arm.f), np.asarray(arm.Z)
    sel = (f > 0) & (f <= LOW_FREQUENCY_HZ)
    if not sel.any() or Z.ndim != 3:
        return True
    for k in range(Z.shape[1]):
        z = Z[sel, k, k]
        z = z[np.abs(z) > 0]
        if z.size and np.median(z.real / np.abs(z)) >= 0:
            return False
    return True



# ----------------------------------------------------------------------------- units
#: typical magnitudes (RMS of the deviation) the diagnosis's fixed constants are set for
TYPICAL_RMS = {"theta": 0.01, "tau_h": 1.0}     # [rad], [N m]
UNITS_UNIT = {"theta": "rad", "tau_h": "N m"}
#: within this factor of the typical RMS the numbers are used as they are
UNITS_TOLERANCE = 2.0 ** 8
#: an RMS below this (subnormal territory of float64) cannot be rescaled exactly
UNITS_SMALLEST = 2.0 ** -960


def _rms(x) -> float:
    """RMS of the deviation of x from its mean, without overflow or underflow: computed
    on x / max|x| (every float64 number, 1e-300 to 1e300, gives a finite result)."""
    x = np.asarray(x, dtype=float)
    m = float(np.max(np.abs(x))) if x.size else 0.0
    if m == 0 or not math.isfinite(m):
        return m
    y = x / m
    return m * float(np.sqrt(np.mean((y - y.mean(axis=0)) ** 2)))


def normalise_units(trials, source_of=None) -> tuple[list, dict | None, list]:
    """Angles and torques far from the magnitudes the diagnosis's constants are set for
    (``TYPICAL_RMS``, beyond a factor ``UNITS_TOLERANCE``): the trials are divided by
    a power of two per signal (exact in floating point), so that their RMS is near the
    typical one, and diagnosed in those units; the report gives its values back in the
    file's units (pipeline.report). Data of every float64 magnitude then give the
    verdict they give at the typical magnitude (a squared 1e80 N m overflows; a
    1e-6 rad angle's spectra underflow the fixed floors).

    Returns (trials, units, findings): ``units`` {signal: divisor} (theta_ref shares
    theta's) or None when nothing was rescaled; the finding is a storage-like note that
    never changes the verdict.

    Raises
    ------
    DiagnosisInputError
        An RMS below ``UNITS_SMALLEST`` (subnormal numbers: no exact rescaling), naming
        the trial (its file when ``source_of`` gives it), the signal and the value.
    """
    from .errors import DiagnosisInputError
    units, evidence = {}, []
    for s, typical in TYPICAL_RMS.items():
        per = {t.name: _rms(t.signal(s)) for t in trials}
        worst = min(per, key=per.get)
        if 0 < per[worst] < UNITS_SMALLEST:
            where = source_of(worst) if source_of else worst
            raise DiagnosisInputError(
                f"{where}: {s} has an RMS of {per[worst]:.3g} {UNITS_UNIT[s]}, below "
                f"{UNITS_SMALLEST:.3g}: too small for float64 to rescale exactly; store it "
                f"in larger units")
        rms = float(np.exp(np.mean(np.log([v for v in per.values() if v > 0] or [typical]))))
        ratio = rms / typical
        if 1.0 / UNITS_TOLERANCE <= ratio <= UNITS_TOLERANCE:
            continue
        units[s] = 2.0 ** round(math.log2(ratio))
        evidence.append(f"{s} RMS {rms:.3g} {UNITS_UNIT[s]} (typical {typical:g}): "
                        f"diagnosed in {s} / 2^{round(math.log2(ratio))}")
    if not units:
        return list(trials), None, []
    a, b = 1.0 / units.get("theta", 1.0), 1.0 / units.get("tau_h", 1.0)
    out = []
    for t in trials:
        scale, arrays = {"theta": a, "tau_h": b}, {"theta": t.theta * a, "tau_h": t.tau_h * b}
        if getattr(t, "theta_ref", None) is not None:
            scale["theta_ref"], arrays["theta_ref"] = a, t.theta_ref * a
        out.append(_replace(t, scale=scale, **arrays))
    finding = Finding("units rescaled", "all trials",
                      "; ".join(evidence) + " (a power of two: exact); values reported in "
                      "the file's units, figures in the rescaled ones", note=True)
    units.setdefault("theta", 1.0)
    units.setdefault("tau_h", 1.0)
    return out, units, [finding]
