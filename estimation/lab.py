"""Lab data in, results out: recordings grouped honestly, analysis set by the user.

:func:`estimation_units` splits trials into the sets that are estimated together
(log-format.md, "condition"): trials are averaged only when they share the declared set-up,
perturbation level and ``condition`` label, or when the user asks (``pool``); unlabeled
recordings of one joint are estimated one by one. :func:`analyse` estimates one set with
the user's :class:`AnalysisOptions` (method, band, Welch segment, overlap, window, each
correction separately) and returns a :class:`LabResult`: Z of every element with its
coherence, M, B, K with confidence intervals, R^2 (the fit's VAF), and warnings for a
non-physical fit, low coherence, a poor fit or a poorly determined parameter.
Works for any number of joints n >= 1.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .accuracy import corrected_impedance, fit_impedance, left_limit_delay, true_impedance, vaf
from .conditions import condition_of
from .errors import EstimationError
from .estimator import (METHODS, band_mask, default_method, estimate_impedance,
                        perturbation_of)

UNITS = {"M": "kg m^2", "B": "N m s/rad", "K": "N m/rad"}
NAMES = {"M": "inertia", "B": "damping", "K": "stiffness"}


@dataclass
class AnalysisOptions:
    """What the user sets; None means "from the data" (docs/estimation.md).

    method : "auto" or one of estimation.METHODS
    band_hz : (lo, hi) [Hz] or None (0 to the declared ``perturbation.cutoff_hz``)
    nperseg, noverlap, nfft : Welch segment, overlap, FFT length [samples]
        (defaults 8192, 3/4 of nperseg, nperseg)
    window : scipy.signal window name
    sampling_correction : "auto" (only for trials declaring ``torque_sampling:
        "left_limit"``, or simulated by this project), "on", "off"
    leakage_correction : "auto" (on where the method and a Hann window allow), "on", "off"
    pool : average the spectra of every trial of a set, labelled or not
    confidence : level of the intervals
    coherence_min, r2_min, ci_max_rel : thresholds of the warnings
    reflex : also fit the intrinsic + reflex (parallel-cascade) model of each one-joint
        trial (estimation.reflex; a ReflexOptions, or True for its defaults)
    """

    method: str = "auto"
    band_hz: tuple | None = None
    nperseg: int = 8192
    noverlap: int | None = None
    nfft: int | None = None
    window: str = "hann"
    sampling_correction: str = "auto"
    leakage_correction: str = "auto"
    pool: bool = False
    confidence: float = 0.95
    coherence_min: float = 0.5
    r2_min: float = 0.9
    ci_max_rel: float = 0.25
    reflex: object = False

    def check(self) -> None:
        if self.method != "auto" and self.method not in METHODS:
            raise EstimationError(f"method must be 'auto' or one of {METHODS}, got "
                                  f"{self.method!r}")
        for name in ("sampling_correction", "leakage_correction"):
            if getattr(self, name) not in ("auto", "on", "off"):
                raise EstimationError(f"{name} must be 'auto', 'on' or 'off', got "
                                      f"{getattr(self, name)!r}")
        if self.band_hz is not None and not 0 <= self.band_hz[0] < self.band_hz[1]:
            raise EstimationError(f"band must be 0 <= lo < hi [Hz], got {self.band_hz}")
        if self.nperseg < 2:
            raise EstimationError(f"--nperseg must be at least 2 samples, got {self.nperseg}")
        if self.nfft is not None and self.nfft < self.nperseg:
            raise EstimationError(f"--nfft {self.nfft} is shorter than the Welch segment "
                                  f"(--nperseg {self.nperseg}); give --nfft >= "
                                  f"{self.nperseg} or leave it out (default: the segment)")
        overlap = self.welch()["noverlap"]
        if not 0 <= overlap < self.nperseg:
            raise EstimationError(f"overlap must be in 0..nperseg-1 = {self.nperseg - 1}, "
                                  f"got {overlap}")

    def welch(self) -> dict:
        return {"nperseg": self.nperseg,
                "noverlap": 3 * self.nperseg // 4 if self.noverlap is None else self.noverlap,
                "nfft": self.nperseg if self.nfft is None else self.nfft,
                "window": self.window}


@dataclass
class Unit:
    """Trials estimated together, and why (``reason``)."""

    label: str
    trials: list
    reason: str


@dataclass
class LabResult:
    """One estimate of one set of trials (arrays: joints i, k; ``Z[:, i, k]``).

    ``f`` [Hz] and ``Z`` [N m/rad] (raw estimate) over the whole spectrum, ``coherence``
    [-] (derived, per element), ``model`` the fitted second-order model at ``f`` (with the
    sampling delay when corrected; the window leakage is not in it), the
    fit (M [kg m^2], B [N m s/rad], K [N m/rad], CI half-widths, R^2), ``vaf`` [%] of the
    band estimate against the fit (or a truth), ``warnings``.
    """

    label: str
    trials: list
    reason: str
    method: str
    n_dof: int
    fs: float
    band_hz: tuple
    band_source: str
    welch: dict
    n_segments: int
    corrections: dict
    f: np.ndarray
    Z: np.ndarray
    coherence: np.ndarray
    model: np.ndarray
    fit: object
    vaf: np.ndarray
    coherence_band: np.ndarray
    warnings: list = field(default_factory=list)
    errors_pct: dict | None = None
    reflex: list | None = None  # estimation.reflex.ReflexResult per trial, when asked

    def parameters(self) -> dict:
        """``{"M"|"B"|"K": {"value", "ci", "unit", "name"}}`` with (n, n) nested lists."""
        return {p: {"name": NAMES[p], "unit": UNITS[p],
                    "value": getattr(self.fit, p).tolist(),
                    "ci_half_width": getattr(self.fit, f"{p}_ci").tolist(),
                    "confidence": self.fit.confidence} for p in "MBK"}

    def to_json(self) -> dict:
        out = {"label": self.label, "trials": self.trials, "grouping": self.reason,
               "method": self.method, "n_dof": self.n_dof, "fs_hz": self.fs,
               "band_hz": list(self.band_hz), "band_source": self.band_source,
               "welch": self.welch,
               "n_segments": self.n_segments, "corrections": self.corrections,
               "parameters": self.parameters(),
               "r2": self.fit.r2.tolist(), "vaf_pct": self.vaf.tolist(),
               "coherence_band_mean": self.coherence_band.tolist(),
               "warnings": self.warnings}
        if self.errors_pct is not None:
            out["errors_pct"] = {k: v.tolist() for k, v in self.errors_pct.items()}
        if self.reflex is not None:
            out["reflex"] = [r.to_json() for r in self.reflex]
        return out

    def frf_table(self, f_max=None) -> dict:
        """Columns of the FRF table: ``f_Hz``, ``in_band`` and per element ``Z{ik}_mag``
        [N m/rad], ``Z{ik}_phase_deg``, ``Z{ik}_coherence``, ``Z{ik}_fit_mag``,
        ``Z{ik}_fit_phase_deg``; bins ``0 < f <= f_max`` (default twice the band top)."""
        f_max = min(2 * self.band_hz[1], self.fs / 2) if f_max is None else f_max
        sel = (self.f > 0) & (self.f <= f_max)
        cols = {"f_Hz": self.f[sel],
                "in_band": ((self.f > self.band_hz[0]) & (self.f <= self.band_hz[1]))[sel]}
        for i, k in element_indices(self.n_dof):
            e = f"Z{i + 1}{k + 1}"
            z, m = self.Z[sel, i, k], self.model[sel, i, k]
            cols[f"{e}_mag"] = np.abs(z)
            cols[f"{e}_phase_deg"] = np.degrees(np.angle(z))
            cols[f"{e}_coherence"] = self.coherence[sel, i, k]
            cols[f"{e}_fit_mag"] = np.abs(m)
            cols[f"{e}_fit_phase_deg"] = np.degrees(np.angle(m))
        return cols


FRF_UNITS = {"f_Hz": "Hz", "in_band": "-", "mag": "N m/rad", "phase_deg": "deg",
             "coherence": "-", "fit_mag": "N m/rad", "fit_phase_deg": "deg"}


def element_indices(n) -> list:
    """(i, k) 0-based pairs of an n x n matrix, row by row."""
    return [(i, k) for i in range(n) for k in range(n)]


def element_names(n) -> list:
    """``["11", "12", ..., "nn"]`` (joints 1-based; n <= 9 keeps them two characters)."""
    return [f"{i + 1}{k + 1}" for i, k in element_indices(n)]


# ----------------------------------------------------------------------------- grouping


def _group_key(trial):
    cond = condition_of(trial)
    return (trial.n_dof, trial.fs, trial.perturbation_kind, str(cond.friction),
            str(cond.resolution), str(cond.perturbation), cond.tuning,
            str(trial.meta.get("condition") or ""))


def estimation_units(trials, *, pool=False) -> list[Unit]:
    """Split trials into the sets estimated together (log-format.md, "condition").

    Trials group by n, fs, perturbation kind, declared set-up and level, and the
    ``condition`` label. A labelled group (or any group with ``pool``) is one set. An
    unlabelled group with at most one trial per perturbed joint is one set (the
    decomposition's one trial per joint). Otherwise unlabelled recordings are separate:
    one set each when a trial suffices alone (one joint, or all joints perturbed at once);
    for several joints an EstimationError says which trials to label.
    """
    groups = {}
    for t in trials:
        groups.setdefault(_group_key(t), []).append(t)
    units = []
    for key, group in groups.items():
        label = key[-1]
        cond = condition_of(group[0])
        base = label or (cond.label if group[0].n_dof > 1 and _is_simulated(group[0])
                         else "")
        by_joint = {}
        for t in group:
            by_joint.setdefault(t.perturbed_dof, []).append(t)
        if label or pool:
            why = (f"condition label {label!r}" if label else "pooled on request") + \
                f": {len(group)} trial(s) averaged"
            units.append(Unit(base or "pooled", group, why))
        elif all(len(v) == 1 for v in by_joint.values()):
            units.append(Unit(base or _joined(group), group,
                              "one trial per perturbed joint" if len(group) > 1
                              else "single recording"))
        elif group[0].n_dof == 1 or all(k is None for k in by_joint):
            units += [Unit(t.name, [t], "unlabelled recording, estimated alone")
                      for t in group]
        else:
            dup = {k: [t.name for t in v] for k, v in by_joint.items() if len(v) > 1}
            raise EstimationError(
                f"several unlabelled recordings perturb the same joint ({dup}); they are "
                f"separate recordings and are not averaged silently: give each set of one "
                f"trial per joint its own 'condition' label in the metadata, or pool them "
                f"on purpose (--pool)")
    return sorted(units, key=lambda u: u.label)


def _joined(group) -> str:
    return group[0].name if len(group) == 1 else "+".join(t.name for t in group)


def _is_simulated(trial) -> bool:
    source = str(trial.meta.get("source", ""))
    return source.startswith(("simulated: orchestrator", "estimation.synthetic: linear"))


def left_limit_sampled(trials) -> bool:
    """True when every trial declares left-limit torque sampling (or, not declaring it,
    was simulated by this project's orchestrator, whose sensor samples that way)."""
    def one(t):
        declared = (t.meta.get("sensors") or {}).get("torque_sampling")
        if declared is not None:
            return declared == "left_limit"
        return str(t.meta.get("source", "")).startswith("simulated: orchestrator")
    return all(one(t) for t in trials)


# ----------------------------------------------------------------------------- analysis


def analyse(unit: Unit, options: AnalysisOptions | None = None, *, truth=None) -> LabResult:
    """Estimate and fit one set of trials with the user's options.

    Parameters
    ----------
    unit : Unit
    options : AnalysisOptions
    truth : (M, B, K) (n, n) arrays or None
        Known answer (simulated data): VAF against it and relative errors [%].

    Raises
    ------
    EstimationError
        Trials the method cannot use, a band outside the data, bad options.
    """
    options = options or AnalysisOptions()
    options.check()
    trials = unit.trials
    method = default_method(trials) if options.method == "auto" else options.method
    usable = _usable(trials, method)
    fs = usable[0].fs
    band, band_source = _band(usable, options, fs, method)
    welch = options.welch()
    _check_band_bins(band, band_source, welch, fs)
    est = estimate_impedance(usable, method=method, band_hz=band, detrend="constant", **welch)
    sampling = _switch(options.sampling_correction, left_limit_sampled(usable))
    leakage_ok = method != "direct" and options.window == "hann"
    leakage = _switch(options.leakage_correction, leakage_ok)
    if leakage and not leakage_ok:
        raise EstimationError(f"the leakage correction needs a perturbation-based method and "
                              f"window='hann' (got {method!r}, {options.window!r})")
    delay = left_limit_delay(fs) if sampling else 0.0
    fit = fit_impedance(est, inertia_delay_s=delay, leakage=leakage,
                        confidence=options.confidence)
    n = est.n_dof
    Zb = corrected_impedance(est, fit, leakage=leakage) if (sampling or leakage) \
        else est.Z[est.band]
    model = fit.model(est.f)
    ref_Z = true_impedance(est.f[est.band], *(truth if truth is not None else
                                              (fit.M, fit.B, fit.K)))
    result = LabResult(
        label=unit.label, trials=[t.name for t in usable], reason=unit.reason, method=method,
        n_dof=n, fs=fs, band_hz=band, band_source=band_source, welch=welch, n_segments=est.n_segments,
        corrections={"left_limit_sampling": sampling, "window_leakage": leakage,
                     "inertia_delay_s": delay},
        f=est.f, Z=est.Z, coherence=est.coherence_Z, model=model, fit=fit,
        vaf=np.atleast_2d(vaf(Zb, ref_Z)), coherence_band=est.mean_coherence())
    if truth is not None:
        result.errors_pct = {p: 100 * v for p, v in fit.relative_errors(*truth).items()}
    result.warnings = fit_warnings(result, options)
    if options.reflex:
        from .reflex import reflex_of_unit
        result.reflex = reflex_of_unit(usable, options.reflex)
    return result


def _usable(trials, method):
    single = method in ("decomposition", "full")
    if trials[0].n_dof == 1 or method == "direct":
        return list(trials)
    use = [t for t in trials if (t.perturbed_dof is not None) == single]
    if not use:
        raise EstimationError(f"method {method!r} needs "
                              f"{'one trial per joint' if single else 'all-joints trials'}; "
                              f"none among {[t.name for t in trials]}")
    return use


def _band(trials, options, fs, method):
    """The fit band [Hz] and where it came from."""
    if options.band_hz is not None:
        lo, hi = (float(v) for v in options.band_hz)
        source = "set by the user"
    else:
        declared = [(t.meta.get("perturbation") or {}).get("cutoff_hz") for t in trials
                    if "perturbation.cutoff_hz" not in t.filled_defaults]
        declared = [float(c) for c in declared if c is not None]
        if declared:
            lo, hi = 0.0, max(declared)
            source = "declared perturbation.cutoff_hz"
        else:
            lo, hi = 0.0, _excited_band(trials, options, method)
            source = "where the perturbation's spectrum is within 20 dB of its peak"
    if hi > fs / 2:
        raise EstimationError(f"band top {hi} Hz is above the Nyquist frequency {fs / 2} Hz")
    return (lo, hi), source


MIN_BAND_BINS = 3  # M, B, K: three real unknowns, two real equations per bin; CIs need more


def _check_band_bins(band, band_source, welch, fs) -> None:
    """Refuse a fit band that holds fewer than MIN_BAND_BINS frequencies of the Welch grid.

    Names the option (or metadata key) that set the band and the values that would work.
    """
    df = fs / welch["nfft"]
    lo, hi = band
    count = int(np.count_nonzero(band_mask(np.arange(welch["nfft"] // 2 + 1) * df, band)))
    if count >= MIN_BAND_BINS:
        return
    setter = (f"--band {lo:g} {hi:g}" if band_source == "set by the user"
              else f"the band {lo:g}-{hi:g} Hz ({band_source})")
    need_hi = lo + MIN_BAND_BINS * df
    need_nfft = int(np.ceil(MIN_BAND_BINS * fs / (hi - lo)))
    seg = (f"--nperseg {welch['nperseg']}" if welch["nfft"] == welch["nperseg"]
           else f"--nfft {welch['nfft']}")
    raise EstimationError(
        f"{setter} holds {count} frequencies of the Welch grid ({seg} at fs={fs:g} Hz: one "
        f"every {df:.4g} Hz); the fit needs at least {MIN_BAND_BINS}: widen the band to "
        f"--band {lo:g} {need_hi:.4g} or more, or use --nperseg (and --nfft) >= {need_nfft} "
        f"with trials at least that long")


def _excited_band(trials, options, method):
    """Highest frequency [Hz] where the perturbation's PSD is within 20 dB of its peak."""
    from scipy import signal
    welch = options.welch()
    tops = []
    for t in trials:
        x = t.theta if method == "direct" else perturbation_of(t)
        k = (t.perturbed_dof or 1) - 1
        f, p = signal.welch(x[:, k], fs=t.fs, **welch)
        tops.append(f[np.nonzero(p >= 0.01 * p[1:].max())[0].max()])
    return float(max(tops))


def _switch(value, auto):
    return auto if value == "auto" else value == "on"


def fit_warnings(result: LabResult, options: AnalysisOptions) -> list[str]:
    """Warnings a lab needs before using the numbers (docs/estimation.md)."""
    out = []
    fit, n = result.fit, result.n_dof
    for p in "MBK":
        value, ci = getattr(fit, p), getattr(fit, f"{p}_ci")
        for i in range(n):
            if value[i, i] < 0:
                out.append(f"non-physical fit: {p}{_e(i, i, n)} = {value[i, i]:.4g} "
                           f"{UNITS[p]} is negative ({NAMES[p]})")
            elif abs(ci[i, i]) > options.ci_max_rel * abs(value[i, i]):
                out.append(f"{p}{_e(i, i, n)} poorly determined: {value[i, i]:.4g} +- "
                           f"{ci[i, i]:.2g} {UNITS[p]}"
                           + (" (does the band reach where the inertia shows? set --band)"
                              if p == "M" else ""))
        if n > 1:
            sym = 0.5 * (value + value.T)
            if np.any(np.diag(value) > 0) and np.linalg.eigvalsh(sym).min() <= 0:
                out.append(f"non-physical fit: the symmetric part of {p} is not positive "
                           f"definite (eigenvalues {np.round(np.linalg.eigvalsh(sym), 5)})")
    for i, k in element_indices(n):
        c = result.coherence_band[i, k]
        if c < options.coherence_min and (i == k or n == 1):
            out.append(f"low coherence: Z{_e(i, k, n)} band mean {c:.2f} (< "
                       f"{options.coherence_min})")
        r2 = fit.r2[i, k]
        if r2 < options.r2_min and (i == k or n == 1):
            out.append(f"poor fit: Z{_e(i, k, n)} R^2 = {r2:.3f} (< {options.r2_min}); the "
                       f"second-order model may not describe this joint in this band")
    if result.method == "direct":
        out.append("direct estimate (angle to torque): biased where the subject's own torque "
                   "or sensor noise moves the angle; record the reference (theta_ref) for an "
                   "unbiased estimate")
    return out


def _e(i, k, n) -> str:
    return f"_{i + 1}{k + 1}" if n > 1 else ""


def result_rows(results) -> list[dict]:
    """One flat row per result and element, for CSV tables."""
    rows = []
    for r in results:
        for i, k in element_indices(r.n_dof):
            row = {"label": r.label, "method": r.method, "element": f"Z{i + 1}{k + 1}"}
            for p in "MBK":
                row[f"{p} [{UNITS[p]}]"] = float(getattr(r.fit, p)[i, k])
                row[f"{p}_ci [{UNITS[p]}]"] = float(getattr(r.fit, f"{p}_ci")[i, k])
            row.update({"R2": float(r.fit.r2[i, k]), "VAF [%]": float(r.vaf[i, k]),
                        "coherence": float(r.coherence_band[i, k])})
            if r.errors_pct is not None:
                row.update({f"err_{p} [%]": float(r.errors_pct[p][i, k]) for p in "MBK"})
            rows.append(row)
    return rows


def options_dict(options: AnalysisOptions) -> dict:
    return asdict(options)
