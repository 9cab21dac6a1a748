"""Lab data in, results out: recordings grouped honestly, analysis set by the user.

:func:`estimation_units` splits trials into the sets that are estimated together
(log-format.md, "condition"): trials are averaged only when they share the declared set-up,
perturbation level and ``condition`` label, or when the user asks (``pool``); unlabeled
recordings of one joint are estimated one by one. :func:`analyse` estimates one set with
the user's :class:`AnalysisOptions` (method, band, Welch segment, overlap, window, each
correction separately) and returns a :class:`LabResult`: Z of every element with its
coherence, M, B, K with confidence intervals, R^2 (the fit's VAF), and warnings for a
non-physical fit, low coherence, a poor fit or a poorly determined parameter.

On top of the fit (docs/estimation.md, "One answer"): the default band comes from the
data (:func:`data_band`: where the perturbation has power and the coherence is high), the
fit is one weighted linear least squares with weights from the data (accuracy.data_weights),
:func:`sensitivity` refits over neighbouring bands and weightings and reports how far M, B,
K move, :func:`segment_fits` fits successive time segments of each recording (a warning when
they differ beyond their intervals: time-varying impedance), and :func:`convention_warnings`
names the metadata key of a likely reversed torque sign or of absolute angles.
Works for any number of joints n >= 1.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from types import SimpleNamespace

import numpy as np

from trialformat.reference import ANGLE_LIMIT_RAD, PLAUSIBLE_DEVIATION_RAD

from .accuracy import (WEIGHTINGS, corrected_impedance, fit_impedance, left_limit_delay,
                       true_impedance, vaf)
from .errors import EstimationError
from .estimator import (METHODS, band_mask, default_method, estimate_impedance,
                        perturbation_of)
from .numbers import distinct

UNITS = {"M": "kg m^2", "B": "N m s/rad", "K": "N m/rad"}
NAMES = {"M": "inertia", "B": "damping", "K": "stiffness"}


@dataclass
class AnalysisOptions:
    """What the user sets; None means "from the data" (docs/estimation.md).

    method : "auto" or one of estimation.METHODS
    band_hz : (lo, hi) [Hz] or None (0 to the declared ``perturbation.cutoff_hz``, else
        :func:`data_band`)
    weighting : accuracy.WEIGHTINGS (default ``smoothed``: relative error, 1/|Z| from the
        neighbouring bins, from the data alone, solved once)
    band_coherence_min, band_power_db : the data band: coherence at least this, the
        perturbation's PSD within this many dB of its peak
    sensitivity : refit over neighbouring bands and weightings (:func:`sensitivity`)
    segments : time segments of each recording fitted apart (0: no check; None: 4, or
        as many as the recording allows when that is 2 or 3, or none with a warning when
        it allows fewer). A number larger than a recording allows
        (:func:`max_time_segments`) is refused for it (EstimationError naming the largest)
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
    track : piecewise-constant K, B, I of one-joint trials (estimation.segmentlab):
        "auto" (where the time-variation test finds a step or switching change),
        "segments" (always), "none"
    """

    method: str = "auto"
    band_hz: tuple | None = None
    weighting: str = "smoothed"
    band_coherence_min: float = 0.9
    band_power_db: float = 40.0
    sensitivity: bool = True
    segments: int | None = None
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
    track: str = "auto"

    def check(self) -> None:
        from .segmentlab import TRACKS
        if self.track not in TRACKS:
            raise EstimationError(f"--track must be one of {', '.join(TRACKS)}, got "
                                  f"{self.track!r}")
        if self.method != "auto" and self.method not in METHODS:
            raise EstimationError(f"method must be 'auto' or one of {METHODS}, got "
                                  f"{self.method!r}")
        for name in ("sampling_correction", "leakage_correction"):
            if getattr(self, name) not in ("auto", "on", "off"):
                raise EstimationError(f"{name} must be 'auto', 'on' or 'off', got "
                                      f"{getattr(self, name)!r}")
        if self.weighting not in WEIGHTINGS:
            raise EstimationError(f"weighting must be one of {WEIGHTINGS}, got "
                                  f"{self.weighting!r}")
        if self.segments is not None and (isinstance(self.segments, bool) or not isinstance(
                self.segments, (int, np.integer)) or self.segments < 0 or self.segments == 1):
            raise EstimationError(f"--segments must be 0 (no check) or a whole number of at "
                                  f"least 2, got {self.segments!r}")
        if self.band_hz is not None and not 0 <= self.band_hz[0] < self.band_hz[1]:
            raise EstimationError(f"band must be 0 <= lo < hi [Hz], got {self.band_hz}")
        if self.window != "hann":
            from scipy import signal
            try:
                signal.get_window(self.window, 16)
            except (ValueError, TypeError) as exc:
                raise EstimationError(f"window {self.window!r}: not a window "
                                      f"scipy.signal.get_window accepts ({exc}); e.g. "
                                      f"'hann', 'hamming', 'blackman'") from None
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
    weighting: str = "smoothed"
    data_band: dict | None = None
    sensitivity: dict | None = None
    segments: list = field(default_factory=list)
    time_variation: list = field(default_factory=list)  # estimation.timevarying, per joint
    flags: list = field(default_factory=list)
    reflex: list | None = None  # estimation.reflex.ReflexResult per trial, when asked
    #: trials the reflex fit was asked for and does not apply to: {"trial", "kind", "reason"}
    reflex_not_fitted: list = field(default_factory=list)
    #: estimation.varying.VaryingResult per trial with a scheduling variable (pvlab)
    varying: list = field(default_factory=list)
    #: estimation.segmentfit.SegmentTrack per one-joint trial tracked (segmentlab)
    time_segments: list = field(default_factory=list)

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
               "weighting": self.weighting, "weighting_text": WEIGHTING_TEXT[self.weighting],
               "data_band": self.data_band, "sensitivity": self.sensitivity,
               "segments": self.segments, "time_variation": self.time_variation,
               "flags": self.flags,
               "warnings": self.warnings}
        if self.errors_pct is not None:
            out["errors_pct"] = {k: v.tolist() for k, v in self.errors_pct.items()}
        if self.reflex is not None:
            out["reflex"] = [r.to_json() for r in self.reflex]
            out["reflex_not_fitted"] = self.reflex_not_fitted
        if self.varying:
            from .pvlab import varying_json
            out["parameter_varying"] = varying_json(self.varying)
        if self.time_segments:
            from .segmentlab import segments_json
            out["time_segments"] = segments_json(self.time_segments)
        return out

    @property
    def f_max(self) -> float:
        """Top [Hz] of the FRF table and plots: the coherent range (:func:`coherent_top`),
        at least the band's top."""
        return max(self.band_hz[1], coherent_top(self.f, self.coherence, self.n_dof))

    def frf_table(self, f_max=None) -> dict:
        """Columns of the FRF table: ``f_Hz``, ``in_band`` and per element ``Z{ik}_mag``
        [N m/rad], ``Z{ik}_phase_deg``, ``Z{ik}_coherence``, ``Z{ik}_mag_lo``,
        ``Z{ik}_mag_hi`` and ``Z{ik}_phase_ci_deg`` (the confidence band of
        :func:`frf_confidence`), ``Z{ik}_fit_mag``, ``Z{ik}_fit_phase_deg``; bins
        ``0 < f <= f_max`` (default :attr:`f_max`, the whole coherent range)."""
        f_max = self.f_max if f_max is None else f_max
        sel = (self.f > 0) & (self.f <= f_max)
        cols = {"f_Hz": self.f[sel],
                "in_band": ((self.f > self.band_hz[0]) & (self.f <= self.band_hz[1]))[sel]}
        nd = effective_averages(self.n_segments, self.welch)
        for i, k in element_indices(self.n_dof):
            e = f"Z{i + 1}{k + 1}"
            z, m = self.Z[sel, i, k], self.model[sel, i, k]
            rel = frf_confidence(self.coherence[sel, i, k], nd, self.fit.confidence)
            cols[f"{e}_mag"] = np.abs(z)
            cols[f"{e}_phase_deg"] = np.degrees(np.angle(z))
            cols[f"{e}_coherence"] = self.coherence[sel, i, k]
            cols[f"{e}_mag_lo"] = np.abs(z) * np.exp(-rel)
            cols[f"{e}_mag_hi"] = np.abs(z) * np.exp(rel)
            cols[f"{e}_phase_ci_deg"] = np.degrees(rel)
            cols[f"{e}_fit_mag"] = np.abs(m)
            cols[f"{e}_fit_phase_deg"] = np.degrees(np.angle(m))
        return cols


FRF_UNITS = {"f_Hz": "Hz", "in_band": "-", "mag": "N m/rad", "phase_deg": "deg",
             "coherence": "-", "mag_lo": "N m/rad", "mag_hi": "N m/rad",
             "phase_ci_deg": "deg", "fit_mag": "N m/rad", "fit_phase_deg": "deg"}

WEIGHTING_TEXT = {
    "coherence": "each bin weighted by 1/std of Zhat from its coherence (Bendat & Piersol "
                 "9.52: |g| / (|Z| sqrt(1 - g^2)), |Z| and g^2 the means of the bins 3-6 "
                 "away), one linear least squares",
    "smoothed": "each bin weighted by 1/|Z| (|Z| the geometric mean of the bins 3-6 away), "
                "one linear least squares",
    "relative": "each bin weighted by 1/|Zhat| of the bin itself, one linear least squares",
    "none": "unweighted linear least squares",
    "model": "each bin weighted by 1/|Zfit| of a first fit weighted by 1/|Zhat| (two passes)"}

#: Coherence that makes a stretch of the spectrum "coherent" for the plots and the FRF
#: table (the phase is unwrapped per stretch; labreport.PHASE_MIN_COHERENCE).
COHERENT = 0.5
#: Shortest run of bins counted as a coherent stretch (isolated bins of a noise-dominated
#: spectrum reach any coherence by chance with few averages).
MIN_RUN_BINS = 5


def runs(mask) -> list[tuple[int, int]]:
    """(start, stop) index pairs of the runs of True in a 1-D boolean array."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(int))
    return list(zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]))


#: The coherent range of the plots and FRF table ends with the last stretch of
#: RANGE_BINS bins whose mean (smallest diagonal) coherence reaches RANGE_COHERENCE.
RANGE_BINS, RANGE_COHERENCE = 21, 0.75


def coherent_top(f, coherence, n_dof) -> float:
    """Top [Hz] of the coherent range: the highest bin whose centred RANGE_BINS-bin mean
    of the smallest diagonal coherence reaches RANGE_COHERENCE (0 if none). A running
    mean, because past the perturbation's power a noise-dominated coherence still
    reaches 0.5 by chance in short runs."""
    c = np.min(np.stack([coherence[:, i, i] for i in range(n_dof)]), axis=0)
    mean = np.convolve(c, np.ones(RANGE_BINS) / RANGE_BINS, mode="same")
    good = np.nonzero((mean >= RANGE_COHERENCE) & (np.asarray(f) > 0))[0]
    return float(f[good[-1]]) if len(good) else 0.0


def effective_averages(n_segments, welch) -> float:
    """Equivalent number of independent averages of a Welch estimate [-].

    ``n_segments / (1 + 2 sum_k (1 - k/n_segments) rho_k^2)``, rho_k the correlation of the
    window with itself shifted by k segment steps (Welch 1967; Percival & Walden 1993,
    eq. 292b): 75 % overlapping Hann segments count about half.
    """
    from scipy import signal
    nperseg, step = welch["nperseg"], welch["nperseg"] - welch["noverlap"]
    w = signal.get_window(welch["window"], nperseg)
    den, total, k = np.sum(w ** 2), 0.0, 1
    while k * step < nperseg and k < n_segments:
        rho = np.sum(w[:nperseg - k * step] * w[k * step:]) / den
        total += (1 - k / n_segments) * rho ** 2
        k += 1
    return n_segments / (1 + 2 * total)


def frf_confidence(coherence, n_averages, confidence=0.95) -> np.ndarray:
    """Half-width of the confidence band of an FRF estimate [-, and rad].

    Bendat & Piersol, Random Data (4th ed.), eqs. 9.52-9.53: the normalised random error
    of |H| is ``sqrt(1 - g^2) / (|g| sqrt(2 nd))`` and the standard deviation of the phase
    [rad] is the same number; times the normal quantile of ``confidence``. Used as
    ``|H| exp(+-e)`` for the magnitude and ``phase +- e`` for the phase. Shape of
    ``coherence``; inf where the coherence is 0.
    """
    from scipy import stats
    g2 = np.clip(np.asarray(coherence, dtype=float), 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.sqrt(1 - g2) / np.sqrt(g2 * 2 * n_averages)
    return stats.norm.ppf(0.5 + confidence / 2) * np.where(g2 > 0, e, np.inf)


def element_indices(n) -> list:
    """(i, k) 0-based pairs of an n x n matrix, row by row."""
    return [(i, k) for i in range(n) for k in range(n)]


def element_names(n) -> list:
    """``["11", "12", ..., "nn"]`` (joints 1-based; n <= 9 keeps them two characters)."""
    return [f"{i + 1}{k + 1}" for i, k in element_indices(n)]


# ----------------------------------------------------------------------------- grouping


def estimation_units(trials, *, pool=False) -> list[Unit]:
    """Split trials into the sets estimated together (log-format.md, "condition"): the
    sets of the one grouping rule shared with ``figures`` and ``diagnose``
    (:func:`estimation.grouping.trial_sets`), sorted by label.

    Raises
    ------
    EstimationError
        What the grouping rule refuses (a non-string label, unlabelled repeats of one joint
        of a multi-joint set-up).
    """
    from .grouping import trial_sets
    return [Unit(s.label, s.trials, s.why) for s in trial_sets(trials, pool=pool)]


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
    check_not_constant(usable, method)
    fs = usable[0].fs
    welch = options.welch()
    whole = estimate_impedance(usable, method=method, band_hz=(0.0, fs / 2),
                               detrend="constant", **welch)
    found = data_band(whole, usable, options)
    band, band_source = _band(usable, options, fs, method, found)
    _check_band_bins(band, band_source, welch, fs,
                     above=lambda: _band_above_movement(whole, usable, options, welch, fs))
    n_time, time_note = time_segments(usable, band, options)  # refused before the fits
    est = replace(whole, band_hz=band)
    sampling = _switch(options.sampling_correction, left_limit_sampled(usable))
    leakage_ok = method != "direct" and options.window == "hann"
    leakage = _switch(options.leakage_correction, leakage_ok)
    if leakage and not leakage_ok:
        raise EstimationError(f"the leakage correction needs a perturbation-based method and "
                              f"window='hann' (got {method!r}, {options.window!r})")
    delay = left_limit_delay(fs) if sampling else 0.0
    fit_kw = {"inertia_delay_s": delay, "leakage": leakage, "confidence": options.confidence}
    fit = fit_impedance(est, weighting=options.weighting, **fit_kw)
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
                     "inertia_delay_s": delay,
                     # units the files stated, converted to SI on reading (issue 22)
                     "units_read": {t.name: t.meta["units_read"] for t in usable
                                    if t.meta.get("units_read")}},
        f=est.f, Z=est.Z, coherence=est.coherence_Z, model=model, fit=fit,
        vaf=np.atleast_2d(vaf(Zb, ref_Z)), coherence_band=est.mean_coherence(),
        weighting=options.weighting, data_band=found)
    if truth is not None:
        result.errors_pct = {p: 100 * v for p, v in fit.relative_errors(*truth).items()}
    if options.sensitivity:
        result.sensitivity = sensitivity(est, fit, fit_kw, options, found)
    if n_time:
        result.segments = segment_fits(usable, method, band, replace(options, segments=n_time),
                                       fit_kw)
    result.warnings = fit_warnings(result, options) + few_segments_warning(usable, result)
    result.warnings += time_note
    conv = convention_warnings(result, usable)
    tv = []
    if options.segments != 0:  # the test diagnose shares (estimation.timevarying)
        from .timevarying import of_trials
        result.time_variation, tv = of_trials(usable)
    from .segmentlab import segments_of_trials  # piecewise-constant K, B, I
    result.time_segments, seg_notes = segments_of_trials(usable, options.track,
                                                         result.time_variation)
    sens = sensitivity_warnings(result)
    result.warnings += conv + tv + seg_notes + sens
    result.flags = list(dict.fromkeys(
        w.split(":")[0].split(" Z")[0] for w in result.warnings
        if w.startswith(("non-physical", "poor fit", "torque sign", "time-varying",
                         "band-sensitive"))))
    if not any(w.startswith("angles in degrees?") for w in result.warnings):
        # a band cannot mend an angle's unit: advice on top of the unit's would mislead
        result.warnings += band_suggestion(result, options)
    if options.reflex:
        # the K-B-I result stands whatever the reflex fit can do with these trials
        from .reflex import reflex_of_trials
        result.reflex, result.reflex_not_fitted = reflex_of_trials(usable, options.reflex)
        result.warnings += [f"reflex fit not done for {s['trial']}: "
                            f"{s['reason'].removeprefix('reflex fit: ')}"
                            for s in result.reflex_not_fitted if s["kind"] != "joints"]
    from .pvlab import varying_of_trials  # K, B, I over the scheduling variable
    result.varying, pv_notes = varying_of_trials(usable, options)
    result.warnings += pv_notes
    if not any(w.startswith("torque sign") for w in result.warnings):
        from .pvlab import sign_warnings
        signs = sign_warnings(result.varying, usable)
        result.warnings += signs
        if signs and "torque sign reversed?" not in result.flags:
            result.flags.append("torque sign reversed?")
    return result


#: A signal whose peak-to-peak range is at most this fraction of its largest magnitude
#: (or exactly 0) is constant to the estimate: after the mean is removed nothing but
#: rounding is left (0.1 + 1e-12 n over 60000 samples: 6e-7).
CONSTANT_REL = 1e-6
_SIGNAL_UNITS = {"theta": "rad", "theta_ref": "rad", "tau_h": "N m", "tau_delta": "N m"}


def check_not_constant(trials, method) -> None:
    """Refuse a set whose estimate would divide by a zero spectrum: a constant (or
    numerically constant, :data:`CONSTANT_REL`) ``theta``, ``tau_h`` or perturbation
    (``theta_ref``/``tau_delta``, not for ``direct``) of a perturbed joint (every joint
    of an all-joints trial). EstimationError ``"[NAME: ]tau_h[1] is constant (1.5 N m):
    nothing to estimate"``."""
    for t in trials:
        names = ["theta", "tau_h"]
        if method != "direct":
            names.append("theta_ref" if t.perturbation_kind == "position" else "tau_delta")
        joints = range(t.n_dof) if t.perturbed_dof is None else [t.perturbed_dof - 1]
        for name in names:
            x = getattr(t, name)
            if x is None:
                continue
            for j in joints:
                col = np.asarray(x[:, j], dtype=float)
                if not np.all(np.isfinite(col)):
                    continue
                ptp = float(np.ptp(col))
                if ptp <= CONSTANT_REL * float(np.max(np.abs(col))):
                    value = (f"{col[0]:.6g}" if ptp == 0 else
                             f"{col.mean():.6g}, range {ptp:.2g}") + f" {_SIGNAL_UNITS[name]}"
                    if name == "tau_h" and (t.meta.get("sensors") or {}).get(
                            "torque_sign", 1) == -1:
                        value += " as read, sensors.torque_sign -1 applied"
                    raise EstimationError(
                        f"{t.name}: {name}[{j + 1}] is {'constant' if ptp == 0 else 'numerically constant'} "
                        f"({value}): nothing to estimate (check the "
                        f"column holds the recorded signal)")


def few_segments_warning(trials, result) -> list[str]:
    """A warning when the Welch estimate averages fewer than MIN_AVERAGES segments: the
    coherence is biased towards 1 (exactly 1 for one segment) and the intervals too
    narrow. Names the count and a segment length that gives enough averages."""
    from .estimator import MIN_AVERAGES, nperseg_for
    from .spectral import WelchOptions

    if result.n_segments >= MIN_AVERAGES:
        return []
    w = result.welch
    hint = nperseg_for(min(t.n_samples for t in trials),
                       WelchOptions(nperseg=w["nperseg"], noverlap=w["noverlap"],
                                    nfft=w["nfft"], window=w["window"]))
    return [f"few Welch averages: {result.n_segments} segment(s) of {w['nperseg']} samples "
            f"(< {MIN_AVERAGES}): the coherence is biased towards 1 (exactly 1 with one "
            f"segment) and the intervals are too narrow; use --nperseg {hint} or longer "
            f"trials"]


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


def _band(trials, options, fs, method, found):
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
        elif found is not None:
            lo, hi = found["band_hz"]
            source = found["text"]
        else:
            lo, hi = 0.0, _excited_band(trials, options, method)
            source = (f"no stretch where the perturbation has power and coherence >= "
                      f"{options.band_coherence_min:g}: where the perturbation's spectrum "
                      f"is within 20 dB of its peak")
    if hi > fs / 2:
        raise EstimationError(f"band top {hi} Hz is above the Nyquist frequency {fs / 2} Hz")
    return (lo, hi), source


def perturbation_psd(trials, options, method):
    """Welch PSD of the perturbation (the angle for ``direct``) of the perturbed joint,
    the largest over the trials at each frequency: ``(f [Hz], psd [unit^2/Hz])``."""
    from scipy import signal
    welch = options.welch()
    out = None
    for t in trials:
        x = t.theta if method == "direct" else perturbation_of(t)
        ks = range(t.n_dof) if t.perturbed_dof is None else [t.perturbed_dof - 1]
        for k in ks:
            f, p = signal.welch(x[:, k], fs=t.fs, **welch)
            out = p if out is None else np.maximum(out, p)
    return f, out


def data_band(estimate, trials, options, *, above_hz: float = 0.0) -> dict | None:
    """The band the data support: where the perturbation has power and coherence is high.

    Bins qualify where the perturbation's PSD (:func:`perturbation_psd`; the angle for the
    direct method) is within ``options.band_power_db`` dB of its peak and the smallest
    diagonal coherence of Z reaches ``options.band_coherence_min``. The band runs from just
    below the first qualifying bin to the top of the last run of at least MIN_RUN_BINS
    qualifying bins before the PSD first falls out of range (a single bin at the bottom:
    a chance coherence of 0.9 needs far fewer averages than a Welch estimate has); bins
    inside with low coherence (a notch) stay in and are said (``coherent_fraction``).

    ``above_hz`` > 0: only the bins above it count (the peak and the power are those of
    the spectrum above it): the perturbation's band above a slow movement that dominates
    the angle's spectrum.

    Returns ``{"band_hz": (lo, hi), "coherent_fraction", "text", ...}`` or None when no
    run qualifies.
    """
    f = estimate.f
    n = estimate.n_dof
    fp, psd = perturbation_psd(trials, options, estimate.method)
    if len(fp) != len(f):
        return None
    c = np.min(np.stack([estimate.coherence_Z[:, i, i] for i in range(n)]), axis=0)
    first_bin = max(1, int(np.searchsorted(f, above_hz, side="right")))
    if first_bin >= len(f):
        return None
    power = psd >= psd[first_bin:].max() * 10 ** (-options.band_power_db / 10)
    power[:first_bin] = False
    # the excited range: the contiguous stretch of power around the PSD's peak
    peak = first_bin + int(np.argmax(psd[first_bin:]))
    first, stop = next((a, b) for a, b in runs(power) if a <= peak < b)
    ok = np.zeros(len(f), bool)
    ok[first:stop] = c[first:stop] >= options.band_coherence_min
    good = [(a, b) for a, b in runs(ok) if b - a >= MIN_RUN_BINS]
    if not good:
        return None
    i0, i1 = int(np.argmax(ok)), good[-1][1] - 1
    lo = float(f[i0 - 1]) if i0 > 1 else 0.0
    hi = float(f[i1])
    inside = (f > lo) & (f <= hi)
    frac = float(np.mean(c[inside] >= options.band_coherence_min))
    text = (f"from the data: perturbation within {options.band_power_db:g} dB of its peak "
            f"and coherence >= {options.band_coherence_min:g}; {100 * frac:.0f} % of its "
            f"bins coherent")
    return {"band_hz": (lo, hi), "coherent_fraction": frac, "text": text,
            "excited_top_hz": float(f[stop - 1]),
            "coherence_min": options.band_coherence_min, "power_db": options.band_power_db}


MIN_BAND_BINS = 3  # M, B, K: three real unknowns, two real equations per bin; CIs need more


def _up_to_grid(x: float, df: float) -> str:
    """``x`` [Hz] rounded up to the fewest decimals that keep it within df/4 of x: as a
    band edge it holds the grid frequency at x (bins are lo < f <= hi) and no other."""
    decimals = max(0, int(np.ceil(-np.log10(df / 4)))) if df > 0 else 6
    up = math.ceil(x * 10 ** decimals) / 10 ** decimals
    return f"{up:.{decimals}f}"


def _check_band_bins(band, band_source, welch, fs, *, above=None) -> None:
    """Refuse a fit band that holds fewer than MIN_BAND_BINS frequencies of the Welch grid.

    Names the option (or metadata key) that set the band and values that work when
    followed: the band's top widened to its MIN_BAND_BINS-th frequency (rounded up, never
    down: :func:`_up_to_grid`), and first, when ``above`` (called only to refuse)
    returns a band (the data band above a slow movement, :func:`_band_above_movement`),
    that band.
    """
    df = fs / welch["nfft"]
    lo, hi = band
    count = int(np.count_nonzero(band_mask(np.arange(welch["nfft"] // 2 + 1) * df, band)))
    if count >= MIN_BAND_BINS:
        return
    setter = (f"--band {lo:g} {hi:g}" if band_source == "set by the user"
              else f"the band {lo:g}-{hi:g} Hz ({band_source})")
    first = int(np.floor(lo / df)) + 1  # the first grid frequency above lo
    need_hi = min((first + MIN_BAND_BINS - 1) * df, fs / 2)
    need_nfft = int(np.ceil(MIN_BAND_BINS * fs / (hi - lo))) if hi > lo else None
    seg = (f"--nperseg {welch['nperseg']}" if welch["nfft"] == welch["nperseg"]
           else f"--nfft {welch['nfft']}")
    lead = ""
    above = above() if above is not None else None
    if above is not None:
        a_lo, a_hi = above["band_hz"]
        lead = (f"the joint moves slowly beyond its perturbation ({above['moving']}): "
                f"below {above['above_hz']:g} Hz the angle's spectrum is that movement's, "
                f"not the perturbation's; the perturbation's own band above it is --band {_up_to_grid(a_lo, df)} "
                f"{_up_to_grid(a_hi, df)} ({above['text']}): use it; or ")
    longer = (f", or use --nperseg (and --nfft) >= {need_nfft} with trials at least that "
              f"long" if need_nfft else "")
    raise EstimationError(
        f"{setter} holds {count} frequencies of the Welch grid ({seg} at fs={fs:g} Hz: one "
        f"every {df:.4g} Hz); the fit needs at least {MIN_BAND_BINS}: {lead}widen the band "
        f"to --band {lo:g} {_up_to_grid(need_hi, df)} or more{longer}")


def _band_above_movement(whole, trials, options, welch, fs) -> dict | None:
    """The data band (:func:`data_band`) above the slow part of the angle
    (trialformat.scheduling.SLOW_CUTOFF_HZ) when a trial's perturbed joint moves beyond
    its perturbation (scheduling.MOVING_RATIO) and that band holds MIN_BAND_BINS
    frequencies; else None. With a ``"moving"`` text and ``"above_hz"``."""
    from trialformat.scheduling import MOVING_RATIO, SLOW_CUTOFF_HZ, spread
    if not SLOW_CUTOFF_HZ < fs / 2:
        return None
    moving = None
    for t in trials:
        if t.theta is None:
            continue
        for k in ([t.perturbed_dof - 1] if t.perturbed_dof else range(t.n_dof)):
            x = np.asarray(t.theta[:, k], dtype=float)
            if x.size < 3 or not np.all(np.isfinite(x)):
                continue
            try:
                span, noise = spread(x, fs)
            except ValueError:
                continue
            if span > MOVING_RATIO * noise:
                moving = (f"{t.name}: theta[{k + 1}]'s part below {SLOW_CUTOFF_HZ:g} Hz "
                          f"spans {span:.3g} rad, {span / noise:.3g} times the rest's std"
                          if noise > 0 else f"{t.name}: theta[{k + 1}] moves")
                break
        if moving:
            break
    if moving is None:
        return None
    found = data_band(whole, trials, options, above_hz=SLOW_CUTOFF_HZ)
    if found is None:
        return None
    df = fs / welch["nfft"]
    grid = np.arange(welch["nfft"] // 2 + 1) * df
    if np.count_nonzero(band_mask(grid, found["band_hz"])) < MIN_BAND_BINS:
        return None
    return {**found, "moving": moving, "above_hz": SLOW_CUTOFF_HZ}


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


# ----------------------------------------------------------------------------- one answer


def _variants(band, df):
    """Neighbouring bands of ``band``: its top at 3/4 and 1/2 of its width, its bottom
    raised by a tenth of its width (at least 4 bins)."""
    lo, hi = band
    width = hi - lo
    return [(lo, lo + 0.75 * width), (lo, lo + 0.5 * width),
            (lo + max(0.1 * width, 4 * df), hi)]


#: a parameter is band-sensitive only when some variant also moves it by more than this
#: fraction of its value: 1 % is below what matters in practice (repeated lab measurements
#: of joint K, B, I scatter by 10 % and more between trials and days; the reported digits
#: carry 3-4 significant figures) and above the few-per-mille moves that a statistically
#: "significant" but tiny misfit produces when the intervals are very narrow (clean or
#: long records: I = 0.015 +- 1e-6 moving over 0.014995...0.015001, 0.03 %)
BAND_MIN_SPREAD = 0.01


def sensitivity(estimate, fit, fit_kw, options, found=None) -> dict:
    """How far M, B, K move over reasonable band and weighting choices.

    Refits the same estimate (no spectra recomputed) over the band with the other data
    weightings (``coherence``, ``smoothed``, ``relative``) and over the neighbouring bands
    of :func:`_variants` (and the data band, when it differs) with the chosen weighting.
    Returns ``{"variants": [{"band_hz", "weighting", "M", "B", "K", "M_ci", ...}],
    "range": {p: [min, max] (n, n) lists}, "exceeds": {p: (n, n) bools}}``: ``exceeds``
    is True where some variant differs from the fit by more than both its own and the
    fit's confidence half-width (a systematic dependence on the choice, not noise) and
    by more than :data:`BAND_MIN_SPREAD` of the fitted value (a dependence that matters).
    """
    df = float(estimate.f[1] - estimate.f[0])
    band = estimate.band_hz
    choices = [(band, w) for w in ("coherence", "smoothed", "relative")
               if w != options.weighting]
    bands = _variants(band, df)
    if found is not None and tuple(found["band_hz"]) != tuple(band):
        bands.append(tuple(found["band_hz"]))
    choices += [(b, options.weighting) for b in bands]
    variants = []
    for b, w in choices:
        if np.count_nonzero(band_mask(estimate.f, b)) < 4 * MIN_BAND_BINS:
            continue
        v = fit_impedance(replace(estimate, band_hz=tuple(b)), weighting=w, **fit_kw)
        variants.append({"band_hz": [float(b[0]), float(b[1])], "weighting": w,
                         **{p: getattr(v, p).tolist() for p in
                            ("M", "B", "K", "M_ci", "B_ci", "K_ci", "r2")}})
    rng, exceeds = {}, {}
    for p in "MBK":
        main, ci = getattr(fit, p), getattr(fit, f"{p}_ci")
        vals = np.array([main] + [np.asarray(v[p]) for v in variants])
        rng[p] = [vals.min(axis=0).tolist(), vals.max(axis=0).tolist()]
        ex = np.zeros(main.shape, bool)
        for v in variants:
            d = np.abs(np.asarray(v[p]) - main)
            ex |= (d > np.maximum(ci, np.asarray(v[f"{p}_ci"]))) & \
                (d > BAND_MIN_SPREAD * np.abs(main))
        exceeds[p] = ex.tolist()
    return {"variants": variants, "range": rng, "exceeds": exceeds}


def sensitivity_warnings(result) -> list[str]:
    """A warning per diagonal parameter whose sensitivity range exceeds its interval."""
    s = result.sensitivity
    if not s:
        return []
    out, n = [], result.n_dof
    for p in ("K", "B", "M"):
        for i in range(n):
            if not s["exceeds"][p][i][i]:
                continue
            lo, hi = s["range"][p][0][i][i], s["range"][p][1][i][i]
            value, ci = getattr(result.fit, p)[i, i], getattr(result.fit, f"{p}_ci")[i, i]
            moved = [v for v in s["variants"]
                     if abs(v[p][i][i] - value) > max(ci, v[f"{p}_ci"][i][i])]
            # digits enough that the values that differ print differently (not 1.2...1.2)
            text = distinct([value, lo, hi] + [v[p][i][i] for v in moved[:3]])
            which = "; ".join(f"{v['band_hz'][0]:.3g}-{v['band_hz'][1]:.3g} Hz "
                              f"{v['weighting']}: {t}" for v, t in zip(moved[:3], text[3:]))
            out.append(f"band-sensitive: {symbol_of(p, n)}{_e(i, i, n)} = {text[0]} +- "
                       f"{ci:.2g} {UNITS[p]} moves over {text[1]}...{text[2]} with the band "
                       f"and weighting ({which}), beyond the statistical interval: the "
                       f"second-order model does not hold equally across the band; report "
                       f"the range")
    return out


def symbol_of(p, n) -> str:
    return "I" if p == "M" and n == 1 else p


def _slice(trial, a, b):
    arrays = {k: (None if getattr(trial, k) is None else getattr(trial, k)[a:b])
              for k in ("tau_delta", "theta", "tau_h", "tau_m", "theta_ref")}
    return replace(trial, t=trial.t[a:b] - trial.t[a], extra={}, t_stored=None,
                   name=f"{trial.name}[{a}:{b}]", **arrays)


#: the time-variation check's default number of segments, and the shortest Welch segment
#: [samples] of a time segment it fits
DEFAULT_TIME_SEGMENTS, MIN_SEGMENT_NPERSEG = 4, 256


def _segment_nperseg(n_samples, S, nperseg) -> int:
    """Welch segment of each of S time segments: the largest power of two <= a quarter of
    the time segment, at most ``nperseg``."""
    L = n_samples // S
    return min(nperseg, 2 ** int(np.floor(np.log2(max(L // 4, 1)))))


def _segments_work(n_samples, S, band, options, fs) -> bool:
    nper = _segment_nperseg(n_samples, S, options.nperseg)
    return nper >= MIN_SEGMENT_NPERSEG and np.count_nonzero(
        band_mask(np.fft.rfftfreq(nper, 1 / fs), band)) >= 4 * MIN_BAND_BINS


def max_time_segments(n_samples, band, options, fs) -> int:
    """The most time segments (:func:`segment_fits`) a recording of ``n_samples`` at ``fs``
    [Hz] allows in ``band`` [Hz]: each needs a Welch segment of at least
    MIN_SEGMENT_NPERSEG samples whose grid puts at least 4 * MIN_BAND_BINS bins in the
    band. 0 when not even 2 work. (The Welch segment shrinks as S grows, so the test is
    monotone in S.)"""
    hi = n_samples // (4 * MIN_SEGMENT_NPERSEG)
    if hi < 2 or not _segments_work(n_samples, 2, band, options, fs):
        return 0
    lo = 2
    while lo < hi:  # largest S in [lo, hi] that works
        mid = (lo + hi + 1) // 2
        if _segments_work(n_samples, mid, band, options, fs):
            lo = mid
        else:
            hi = mid - 1
    return lo


def time_segments(trials, band, options) -> tuple[int, list[str]]:
    """How many time segments the time-variation check fits, and a warning when it is not
    what was asked. ``options.segments`` 0: none; None (default): DEFAULT_TIME_SEGMENTS,
    fewer if the recordings allow fewer (said), none if they allow fewer than 2 (said); a
    number: that many, refused (EstimationError naming --segments, the value and the
    largest that works for these recordings) when more than they allow."""
    asked = options.segments
    if asked == 0:
        return 0, []
    n = min(t.n_samples for t in trials)
    fs = trials[0].fs
    top = max_time_segments(n, band, options, fs)
    names = ", ".join(t.name for t in trials)
    # the duration that limits the segments is the shortest recording's: name only those
    limiting = [t.name for t in trials if t.n_samples == n]
    shortest = ", ".join(limiting)
    allows = "allows" if len(limiting) == 1 else "allow"
    why = (f"each time segment needs a Welch segment of at least {MIN_SEGMENT_NPERSEG} "
           f"samples with {4 * MIN_BAND_BINS} frequencies in the band {band[0]:.4g}-"
           f"{band[1]:.4g} Hz")
    nper2 = _segment_nperseg(n, 2, options.nperseg)
    if top < 2 and nper2 >= MIN_SEGMENT_NPERSEG:  # long enough: the band is too narrow
        df = fs / nper2
        count = int(np.count_nonzero(band_mask(np.fft.rfftfreq(nper2, 1 / fs), band)))
        width = (4 * MIN_BAND_BINS + 1) * df  # one bin spare: grid alignment
        lo = max(0.0, min(band[0], band[1] - width))
        wider = (lo, lo + width) if lo + width > band[1] else (lo, band[1])
        cause = (f"the band {band[0]:.4g}-{band[1]:.4g} Hz is too narrow: it holds {count} "
                 f"frequencies of a time segment's Welch grid ({nper2} samples, one every "
                 f"{df:.3g} Hz), fewer than the {4 * MIN_BAND_BINS} the check needs; a band "
                 f"of at least {width:.3g} Hz works (e.g. --band {wider[0]:.4g} "
                 f"{min(wider[1], fs / 2):.4g})")
        if asked is None:
            return 0, [f"fixed time segments not fitted for {names}: {cause}"]
        if asked > top:
            raise EstimationError(f"--segments {asked}: {cause}, or give --segments 0")
    if asked is None:
        if top >= DEFAULT_TIME_SEGMENTS:
            return DEFAULT_TIME_SEGMENTS, []
        if top >= 2:
            return top, [f"{top} fixed time segments (results.json segments), not "
                         f"{DEFAULT_TIME_SEGMENTS}: {shortest} ({n / fs:.4g} s) {allows} at "
                         f"most {top} ({why})"]
        return 0, [f"fixed time segments not fitted: {shortest} ({n / fs:.4g} s) "
                   f"{'is' if len(limiting) == 1 else 'are'} too short for 2 time segments "
                   f"({why})"]
    if asked > top:
        largest = (f"the largest that works for it is --segments {top}" if top
                   else "it allows none (give --segments 0)")
        raise EstimationError(
            f"--segments {asked}: more time segments than {shortest} ({n} samples, "
            f"{n / fs:.4g} s) {allows}; {largest} ({why})")
    return asked, []


def segment_fits(trials, method, band, options, fit_kw) -> list[dict]:
    """Fit each of ``options.segments`` successive time segments of the recordings alone.

    Segment s of every trial of the set is estimated together (same method, band and
    weighting; Welch segment the largest power of two <= a quarter of the time segment,
    at most ``options.nperseg``, 3/4 overlap). Returns one dict per time segment:
    ``{"t_s": [start, end], "M", "B", "K", "M_ci", "B_ci", "K_ci"}`` ((n, n) lists);
    empty when the recordings are too short (Welch segment < 256 samples) or a segment's
    band holds too few bins.
    """
    S = options.segments
    N = min(t.n_samples for t in trials)
    L = N // S
    nper = _segment_nperseg(N, S, options.nperseg)
    fs = trials[0].fs
    if not _segments_work(N, S, band, options, fs):
        return []
    out = []
    for s in range(S):
        part = [_slice(t, s * L, (s + 1) * L) for t in trials]
        est = estimate_impedance(part, method=method, band_hz=band, detrend="constant",
                                 nperseg=nper, noverlap=3 * nper // 4, nfft=nper,
                                 window=options.window)
        v = fit_impedance(est, weighting=options.weighting, **fit_kw)
        out.append({"t_s": [s * L / fs, (s + 1) * L / fs], "nperseg": nper,
                    **{p: getattr(v, p).tolist() for p in
                       ("M", "B", "K", "M_ci", "B_ci", "K_ci")}})
    return out


#: Time-varying warning: homogeneity of the segment estimates rejected at this level
#: (Cochran's Q, chi-square with S - 1 degrees of freedom) and the segments' spread
#: larger than this fraction of their mean.
TV_P_VALUE, TV_MIN_SPREAD = 1e-3, 0.05


def time_varying_warnings(result) -> list[str]:
    """Evidence that the impedance changed over the trial (:func:`segment_fits`).

    Per diagonal parameter: the segment estimates v_s with standard errors
    ``sigma_s = ci_s / 1.96``; ``Q = sum ((v_s - vbar) / sigma_s)^2`` (vbar their
    inverse-variance mean) against chi-square(S - 1) (Cochran 1954). A warning when
    p < TV_P_VALUE and the spread exceeds TV_MIN_SPREAD of the mean.
    """
    from scipy import stats
    segs, n = result.segments, result.n_dof
    if len(segs) < 2:
        return []
    out = []
    for p in ("K", "B", "M"):
        for i in range(n):
            v = np.array([s[p][i][i] for s in segs])
            sd = np.array([s[f"{p}_ci"][i][i] for s in segs]) / 1.96
            if np.any(sd <= 0):
                continue
            w = 1 / sd ** 2
            vbar = np.sum(w * v) / np.sum(w)
            q = float(np.sum(w * (v - vbar) ** 2))
            pval = float(stats.chi2.sf(q, len(v) - 1))
            spread = (v.max() - v.min()) / max(abs(vbar), 1e-300)
            if pval < TV_P_VALUE and spread > TV_MIN_SPREAD:
                parts = ", ".join(f"{s['t_s'][0]:.0f}-{s['t_s'][1]:.0f} s: "
                                  f"{s[p][i][i]:.4g}+-{s[f'{p}_ci'][i][i]:.2g}" for s in segs)
                out.append(f"time-varying: {symbol_of(p, n)}{_e(i, i, n)} differs between "
                           f"time segments beyond their intervals ({parts} {UNITS[p]}; "
                           f"chi-square p {'< 1e-16' if pval < 1e-16 else f'= {pval:.1g}'}"
                           f"): the single value "
                           f"{getattr(result.fit, p)[i, i]:.4g} is an average over a "
                           f"changing impedance, not one joint state")
    return out


#: Low-frequency phase beyond this [deg] reads as a reversed torque sign (a spring: 0).
SIGN_PHASE_DEG = 135.0
#: Mean angle beyond this many standard deviations (and ABSOLUTE_MIN_RAD) reads as
#: absolute angles logged as deviations.
ABSOLUTE_SIGMAS, ABSOLUTE_MIN_RAD = 3.0, 0.02
#: Angles in degrees: a deviation from the mean angle beyond DEGREES_LIMIT_RAD (no joint's
#: perturbation moves it 2 rad, 115 deg) that is a plausible one (< DEGREES_PLAUSIBLE_RAD)
#: read as degrees. The rule of the diagnosis' conventions check, on the same constants
#: (trialformat.reference).
DEGREES_LIMIT_RAD, DEGREES_PLAUSIBLE_RAD = ANGLE_LIMIT_RAD, PLAUSIBLE_DEVIATION_RAD
#: Plausible impedance of a human ankle, elbow or wrist: K [N m/rad] and I [kg m^2]. A fit
#: with K and I both below these ranges while both times 180/pi (57.3) fall inside them
#: reads as an angle stored in degrees whose perturbation is too small (< 2 rad read as
#: rad) for the deviation rule above. (A relaxed wrist's K may be below 5; its I, the
#: hand's 3e-3 or more, is not below 1e-3.)
K_PLAUSIBLE, I_PLAUSIBLE = (5.0, 2000.0), (1e-3, 1.0)


def angle_channels(trials) -> list[str]:
    """The angle channels the trials have: ``theta`` and, when any has it, ``theta_ref``
    (a unit declared for theta alone leaves theta_ref read in radians)."""
    return ["theta"] + (["theta_ref"] if any(getattr(t, "theta_ref", None) is not None
                                             for t in trials) else [])


def angle_units_advice(trials):
    """``({"theta": "deg", "theta_ref": "deg"}, headers)``: the metadata ``units`` value
    naming every angle channel the trials have, and ``headers(j)`` the CSV headers of
    joint j (`` theta[1] (deg)`` and `` theta_ref[1] (deg)``)."""
    names = angle_channels(trials)
    key = "{" + ", ".join(f'"{c}": "deg"' for c in names) + "}"
    return key, lambda j: ("s " if len(names) > 1 else " ") + " and ".join(
        f"{c}[{j + 1}] (deg)" for c in names)


#: A recording's angle scale this many times the other recordings' (180/pi = 57.3,
#: within a factor DEGREE_SCALE_TOLERANCE) reads as a recording stored in degrees.
DEGREE_SCALE_TOLERANCE = 2.0


def _angle_scale(t) -> float:
    """A recording's angle scale [as stored]: the largest joint's theta std (its
    theta_ref's when theta is missing)."""
    x = t.theta if t.theta is not None else getattr(t, "theta_ref", None)
    return float(np.max(np.std(np.asarray(x, dtype=float), axis=0))) if x is not None \
        else float("nan")


def degree_outliers(unit: Unit) -> list[tuple]:
    """Recordings of a set whose angles look like degrees beside the others in radians:
    an angle scale (:func:`_angle_scale`) 180/pi times the median of the others' (within
    DEGREE_SCALE_TOLERANCE). Checked per recording before the set is pooled (a pooled
    spectrum mixes both scales). ``[(trial, message)]``; the message names the trial
    and the metadata declaring every angle channel it has."""
    trials = unit.trials
    if len(trials) < 2:
        return []
    scales = [_angle_scale(t) for t in trials]
    c, out = 180 / np.pi, []
    for i, t in enumerate(trials):
        others = [s for k, s in enumerate(scales) if k != i and np.isfinite(s) and s > 0]
        if not others or not np.isfinite(scales[i]) or scales[i] <= 0:
            continue
        ratio = scales[i] / float(np.median(others))
        if not c / DEGREE_SCALE_TOLERANCE <= ratio <= c * DEGREE_SCALE_TOLERANCE:
            continue
        key, _ = angle_units_advice([t])
        out.append((t, f"{t.name}: its angles look like degrees (theta std "
                       f"{scales[i]:.3g} as stored, {ratio:.3g} times the "
                       f"{float(np.median(others)):.3g} rad of the other recordings; "
                       f"180/pi = 57.3), the other recordings of {unit.label!r} are in "
                       f"radians; declare \"units\": {key} in {t.name}.json; refused alone, "
                       f"the others are estimated"))
    return out


def convention_warnings(result, trials) -> list[str]:
    """Conventions found in the data, not guessed: the metadata key to declare.

    - ``torque sign reversed?``: every diagonal K, B, M negative, or the estimate's phase
      beyond SIGN_PHASE_DEG over the lowest coherent bins of the band (median of the
      first five with coherence >= 0.5) that lie below half the fit's natural frequency
      sqrt(|K/M|)/(2 pi) (above it a passive joint's inertia gives 180 deg: the moving
      pilot ankle's band starts at 13.5 Hz, above its 4 Hz): a passive joint has K, B, I > 0 and a phase near
      0 deg at low frequency. Key: ``sensors.torque_sign``.
    - ``absolute angles?``: a joint's mean angle beyond ABSOLUTE_SIGMAS standard
      deviations and ABSOLUTE_MIN_RAD while the file declares deviations. Key: ``angles``.
    - ``angles in degrees?``: a joint's largest deviation from its mean angle beyond
      DEGREES_LIMIT_RAD (2 rad) while the same number read as degrees is below
      DEGREES_PLAUSIBLE_RAD (0.5 rad). Units are declared by the metadata key ``units``
      or a header ``theta[1] (deg)`` (log-format.md); K, B, I scale by 180/pi once it is.
    - ``angles in degrees? ... K implausibly small``: a small perturbation in degrees (no
      deviation beyond 2 rad): K and I both below K_PLAUSIBLE, I_PLAUSIBLE while both
      times 180/pi lie inside them, the file stating no unit for theta.
    """
    out, n = [], result.n_dof
    fit = result.fit
    band = band_mask(result.f, result.band_hz)
    signs = sorted({int((t.meta.get("sensors") or {}).get("torque_sign", 1)) for t in trials})
    for i in range(n):
        evidence = []
        if all(getattr(fit, p)[i, i] < 0 for p in "MBK"):
            evidence.append(f"K, B, {symbol_of('M', n)} all negative")
        idx = np.nonzero(band & (result.coherence[:, i, i] >= COHERENT))[0][:5]
        # a spring's phase 0 holds below the natural frequency only: above it the
        # inertia's 180 deg is expected (a band that starts above it says nothing here)
        f_n = np.sqrt(abs(fit.K[i, i]) / max(abs(fit.M[i, i]), 1e-300)) / (2 * np.pi)
        idx = idx[result.f[idx] < f_n / 2]
        if len(idx):
            phase = float(np.degrees(np.median(np.abs(np.angle(result.Z[idx, i, i])))))
            if phase > SIGN_PHASE_DEG:
                evidence.append(f"phase {phase:.0f} deg at {result.f[idx[0]]:.2g}-"
                                f"{result.f[idx[-1]]:.2g} Hz (a spring gives 0)")
        if evidence:
            now = signs[0] if len(signs) == 1 else signs
            want = -signs[0] if len(signs) == 1 else "the opposite"
            out.append(f"torque sign reversed? Z{_e(i, i, n)}: {'; '.join(evidence)}. If the "
                       f"torque sensor's sign is opposite to the angle's, declare "
                       f"\"sensors\": {{\"torque_sign\": {want}}} in the metadata or "
                       f"the .mat's sidecar NAME.json (now {now}), or give --torque-sign "
                       f"{want if len(signs) == 1 else -1}; the reader then negates tau_h")
    units_key, headers = angle_units_advice(trials)
    degrees = set()
    for t in trials:
        if t.theta is None:
            continue
        dev = np.max(np.abs(t.theta - t.theta.mean(axis=0)), axis=0)
        for j in range(t.n_dof):
            if DEGREES_LIMIT_RAD < dev[j] and np.radians(dev[j]) < DEGREES_PLAUSIBLE_RAD:
                degrees.add((t.name, j))
                k = fit.K[j, j] * 180 / np.pi
                out.append(f"angles in degrees? {t.name}: theta[{j + 1}] deviates up to "
                           f"{dev[j]:.4g} rad from its mean (std {t.theta[:, j].std():.3g} "
                           f"rad), beyond the {DEGREES_LIMIT_RAD:g} rad a joint's "
                           f"perturbation can move it; read as degrees it is "
                           f"{np.radians(dev[j]):.3g} rad. If theta is in degrees, "
                           f"declare it (metadata \"units\": {units_key} or the "
                           f"CSV header{headers(j)}, log-format.md) or store "
                           f"them * pi/180; K, B, {symbol_of('M', n)} are then "
                           f"180/pi = 57.3 times these (K{_e(j, j, n)} about {k:.4g} "
                           f"{UNITS['K']})")
    c = 180 / np.pi
    for j in range(n):
        k, inertia = fit.K[j, j], fit.M[j, j]
        stated = [t.name for t in trials if f"theta[{j + 1}]" in (t.meta.get("units_read") or {})]
        if (any(jj == j for _, jj in degrees) or stated or not 0 < k < K_PLAUSIBLE[0]
                or not 0 < inertia < I_PLAUSIBLE[0]
                or not K_PLAUSIBLE[0] <= k * c <= K_PLAUSIBLE[1]
                or not I_PLAUSIBLE[0] <= inertia * c <= I_PLAUSIBLE[1]):
            continue
        names = ", ".join(t.name for t in trials)
        sd = max(float(t.theta[:, j].std()) for t in trials if t.theta is not None)
        out.append(f"angles in degrees? {names}: theta[{j + 1}] gives K{_e(j, j, n)} = "
                   f"{k:.4g} {UNITS['K']} and {symbol_of('M', n)} = {inertia:.3g} {UNITS['M']}, "
                   f"both implausibly small for a human joint (plausible "
                   f"K {K_PLAUSIBLE[0]:g}-{K_PLAUSIBLE[1]:g} {UNITS['K']}, "
                   f"{symbol_of('M', n)} {I_PLAUSIBLE[0]:g}-{I_PLAUSIBLE[1]:g} "
                   f"{UNITS['M']}); times 180/pi = 57.3 both are plausible "
                   f"(K about {k * c:.4g} {UNITS['K']}, {symbol_of('M', n)} about "
                   f"{inertia * c:.3g} {UNITS['M']}), as when theta[{j + 1}] (std {sd:.3g}) "
                   f"is stored in degrees. If it is, declare it: metadata \"units\": "
                   f"{units_key} or the CSV header{headers(j)} (log-format.md)")
    for t in trials:
        if t.meta.get("angles") == "absolute" or t.theta is None:
            continue
        m, sd = t.theta.mean(axis=0), t.theta.std(axis=0)
        for j in range(t.n_dof):
            if (t.name, j) not in degrees and abs(m[j]) > max(ABSOLUTE_SIGMAS * sd[j],
                                                              ABSOLUTE_MIN_RAD):
                out.append(f"absolute angles? {t.name}: theta[{j + 1}] has mean "
                           f"{m[j]:.4g} rad ({np.degrees(m[j]):.3g} deg), "
                           f"{abs(m[j]) / sd[j]:.1f} times its standard deviation, while "
                           f"the file declares deviations from posture_deg. If it logs "
                           f"absolute joint angles, declare \"angles\": \"absolute\" with "
                           f"the posture in posture_deg (K, B, I do not change: the mean is "
                           f"removed per Welch segment)")
    return out


def _good_fit(fit, options, n) -> bool:
    diag = [getattr(fit, p)[i, i] for p in "MBK" for i in range(n)]
    cis = [getattr(fit, f"{p}_ci")[i, i] for p in "MBK" for i in range(n)]
    return (min(diag) > 0 and all(c <= options.ci_max_rel * v for v, c in zip(diag, cis))
            and float(np.min(np.diag(np.atleast_2d(fit.r2)))) >= options.r2_min)


def band_suggestion(result, options) -> list[str]:
    """When the fit is non-physical, poor, poorly determined or of low coherence, a band
    that works: the data band or a neighbouring band (:func:`sensitivity`) whose fit is
    physical, well determined and R^2 >= r2_min."""
    flagged = [w for w in result.warnings
               if w.startswith(("non-physical", "poor fit", "low coherence"))
               or "poorly determined" in w]
    if not flagged:  # band-sensitive alone: another band would not mend the model
        return []
    n = result.n_dof
    cands = []
    if result.data_band is not None:
        cands.append(tuple(result.data_band["band_hz"]))
    for v in (result.sensitivity or {}).get("variants", []):
        if v["weighting"] == result.weighting:
            cands.append(tuple(v["band_hz"]))
    for b in cands:
        if np.allclose(b, result.band_hz):
            continue
        v = next((v for v in (result.sensitivity or {}).get("variants", [])
                  if np.allclose(v["band_hz"], b) and v["weighting"] == result.weighting),
                 None)
        if v is None:
            continue
        f = SimpleNamespace(**{key: np.asarray(v[key]) for key in
                               ("M", "B", "K", "M_ci", "B_ci", "K_ci", "r2")})
        if _good_fit(f, options, n):
            return [f"suggested band: --band {b[0]:.3g} {b[1]:.3g} (K, B, "
                    f"{symbol_of('M', n)} positive and well determined, R^2 >= "
                    f"{options.r2_min:g} there"
                    + (f"; {result.data_band['text']}" if result.data_band is not None
                       and np.allclose(b, result.data_band["band_hz"]) else "") + ")"]
    where = (f"the data band {result.data_band['band_hz'][0]:.3g}-"
             f"{result.data_band['band_hz'][1]:.3g} Hz" if result.data_band else "")
    return [f"no band tried ({where + ', ' if where else ''}the band at 1/2 and 3/4 of "
            f"its width, its bottom raised) gives a physical, well determined fit with R^2 "
            f">= {options.r2_min:g}: the second-order model may not describe this joint "
            f"(a reflex pathway, a time-varying state?)"]


def fit_warnings(result: LabResult, options: AnalysisOptions) -> list[str]:
    """Warnings a lab needs before using the numbers (docs/estimation.md)."""
    out = []
    fit, n = result.fit, result.n_dof
    for p in "KBM":
        value, ci = getattr(fit, p), getattr(fit, f"{p}_ci")
        for i in range(n):
            sym = symbol_of(p, n)  # one joint: I, as in the printed line
            if value[i, i] < 0:
                out.append(f"non-physical fit: {sym}{_e(i, i, n)} = {value[i, i]:.4g} "
                           f"{UNITS[p]} is negative ({NAMES[p]})")
            elif abs(ci[i, i]) > options.ci_max_rel * abs(value[i, i]):
                out.append(f"{sym}{_e(i, i, n)} poorly determined: {value[i, i]:.4g} +- "
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
        if r2 < options.r2_min:
            what = "this joint" if i == k else f"the coupling of joints {i + 1} and {k + 1}"
            out.append(f"poor fit: Z{_e(i, k, n)} R^2 = {r2:.3f} (< {options.r2_min}); the "
                       f"second-order model may not describe {what} in this band")
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
            if r.sensitivity:
                for p in "MBK":
                    row[f"{p}_range_min [{UNITS[p]}]"] = r.sensitivity["range"][p][0][i][k]
                    row[f"{p}_range_max [{UNITS[p]}]"] = r.sensitivity["range"][p][1][i][k]
            row.update({"R2": float(r.fit.r2[i, k]), "VAF [%]": float(r.vaf[i, k]),
                        "coherence": float(r.coherence_band[i, k]),
                        "band_lo [Hz]": float(r.band_hz[0]), "band_hi [Hz]": float(r.band_hz[1]),
                        "weighting": r.weighting})
            if r.errors_pct is not None:
                row.update({f"err_{p} [%]": float(r.errors_pct[p][i, k]) for p in "MBK"})
            rows.append(row)
    return rows


def options_dict(options: AnalysisOptions) -> dict:
    return asdict(options)
