"""Intrinsic and reflex pathways of one joint: the parallel-cascade model.

The structure is that of Kearney, Stein and Parameswaran (1997), "Identification of
intrinsic and reflex contributions to human ankle stiffness dynamics", IEEE Trans. Biomed.
Eng. 44(6):493-504: the joint torque is the sum of

- an **intrinsic** pathway, here the second-order impedance of the rest of this package,
  ``tq_I = K theta + B theta' + I theta''``, and
- a **reflex** pathway acting on the joint velocity: a pure delay ``d``, an (optionally
  half-wave rectified) static nonlinearity and a low-pass activation dynamics with unit
  static gain, ``tq_R = G * LP[N(theta'(t - d))]``, ``LP(s) = wn^2 / (s^2 + 2 zeta wn s +
  wn^2)``, ``wn = 2 pi f_c``, ``N(v) = max(v, 0)`` (``rectify="positive"``), ``max(-v, 0)``
  (``"negative"``) or ``v`` (``"none"``, a linear reflex pathway); signs below.

The reference implementation of the Kearney lab (``stiffnessID/PC_stiffnessID.m`` of
reklab/reklab_public) alternates a non-parametric intrinsic IRF (+-40 ms) and a
Hammerstein reflex model. This module fits the parametric form above instead (the
quantities a lab reports: K, B, I, reflex gain, delay, cutoff, damping), by separable least
squares in the time domain:

1. ``theta`` and ``tau_h`` are low-passed (zero phase, 4th-order Butterworth at
   ``lowpass_hz``) and brought to about ``work_fs`` (every q-th sample); velocity and
   acceleration are central differences of the filtered angle.
2. For fixed ``(d, f_c, zeta)`` the torque is linear in ``(K, B, I, G, c)`` (``c`` an
   offset): the residual is the projection of the torque out of the regressors
   ``[theta, theta', theta'', 1, x]``, ``x = LP[N(theta')]`` delayed by ``d``.
3. A grid over ``d`` (every working sample in ``delay_ms``), ``f_c`` (log grid in
   ``cutoff_hz``) and ``zeta`` (grid in ``damping``), for each rectification, gives the
   global minimum of the residual (the reflex column's projection for every delay at once,
   by FFT cross-correlation); Levenberg-Marquardt then refines ``(d, f_c, zeta)``
   continuously from it (the delay between samples by linear interpolation). No random
   start: the same data give the same numbers.
4. **Intervals**: delete-one-block jackknife. The usable samples are split into
   ``segments`` contiguous blocks; the fit is repeated with each block left out (refined
   from the full-data optimum, same rectification); the half-width is ``t_{(1+c)/2, m-1} * sqrt((m-1)/m * sum (p_j -
   p_mean)^2)`` (Efron and Tibshirani 1993, ch. 11). Blocks keep the serial correlation of
   the residual inside them, which the Jacobian of the least squares would ignore.
5. **VAF** [%] of the (filtered) torque, ``100 (1 - var(tq - model) / var(tq))``, for the
   intrinsic pathway alone, the reflex pathway alone and the total (as
   ``PC_stiffnessID.m`` reports them: each pathway's prediction against the measured
   torque), and of the intrinsic-only model fitted on its own (``G = 0``) for comparison.

Signs: ``theta`` and ``tau_h`` are in the project's convention (the reader applied
``sensors.torque_sign``), so a stiff joint has ``K > 0``, and a reflex that resists the
stretch has ``G > 0`` for ``rectify="positive"`` (it acts while ``theta' > 0``); for
``"negative"`` it acts while ``theta' < 0`` and resists the stretch when ``G < 0``
(``x = max(-theta', 0)`` enters with the opposite sign of the velocity). The reported
``resists_stretch`` says which.

The model is for one joint: a trial of several joints is refused.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .errors import EstimationError
from .numbers import plus_minus

PARAMS = ("K", "B", "I", "G", "delay_ms", "cutoff_hz", "damping")
UNITS = {"K": "N m/rad", "B": "N m s/rad", "I": "kg m^2", "G": "N m s/rad",
         "delay_ms": "ms", "cutoff_hz": "Hz", "damping": "-"}
NAMES = {"K": "intrinsic stiffness", "B": "intrinsic damping", "I": "intrinsic inertia",
         "G": "reflex gain (torque per velocity)", "delay_ms": "reflex delay",
         "cutoff_hz": "reflex low-pass natural frequency", "damping": "reflex low-pass damping"}
RECTIFY = ("auto", "positive", "negative", "none")

#: stretch-reflex latencies reported for the ankle and the elbow [ms] (ankle plantar
#: flexors about 40 ms: Kearney, Stein & Parameswaran 1997; 40-50 ms in the parameter-
#: varying ankle studies, Sobhani Tehrani & Kearney 2022); a fitted pure delay outside is
#: flagged: the model's activation low-pass trades lag with it
TYPICAL_DELAY_MS = (30.0, 60.0)


def activation_lag_ms(cutoff_hz: float, damping: float) -> float:
    """Low-frequency group delay [ms] of a second-order low-pass of natural frequency
    ``cutoff_hz`` [Hz] and damping ``damping``: 2 zeta / omega_n."""
    return 1e3 * 2 * damping / (2 * np.pi * cutoff_hz)


def latency_warning(delay_ms: float, cutoff_hz: float | None = None,
                    damping: float | None = None) -> str | None:
    """A warning when a fitted reflex delay [ms] lies outside :data:`TYPICAL_DELAY_MS`,
    saying what it then is (the pathway's pure delay in this model form, its activation's
    group delay beside it, 2 zeta / omega_n at low frequency), else None."""
    lo, hi = TYPICAL_DELAY_MS
    if not np.isfinite(delay_ms) or lo <= delay_ms <= hi:
        return None
    lag = ("" if not cutoff_hz or damping is None else
           f"; its activation low-pass ({cutoff_hz:.3g} Hz, damping {damping:.2g}) adds "
           f"{activation_lag_ms(cutoff_hz, damping):.0f} ms of group delay at low "
           f"frequency")
    return (f"reflex delay {delay_ms:.1f} ms lies outside the {lo:g}-{hi:g} ms of "
            f"stretch-reflex latencies reported for the ankle and elbow{lag}: read it as "
            f"this model form's pure delay, not as the reflex latency; another command's "
            f"or model form's delay on the same data may differ by as much")


class ReflexNotApplicable(EstimationError):
    """The parallel-cascade fit does not apply to this input: ``kind`` ``"short"`` (a
    recording shorter than :func:`minimum_samples`), ``"rate"`` (sampled too slowly for
    the fit's low-pass) or ``"joints"`` (a trial of several joints); the lab pipeline
    reports it as a warning or note and keeps the K-B-I result."""

    def __init__(self, message, kind="short"):
        super().__init__(message)
        self.kind = kind


@dataclass
class ReflexOptions:
    """Settings of the parallel-cascade fit (module docstring).

    rectify : "auto" (the better of "positive" and "negative"), "positive", "negative",
        "none" (a linear reflex pathway)
    delay_ms : (lo, hi) search range of the reflex delay [ms]
    cutoff_hz : (lo, hi) search range of the low-pass natural frequency [Hz]
    damping : (lo, hi) search range of the low-pass damping ratio [-]
    lowpass_hz : anti-alias / differentiation low-pass of angle and torque [Hz]
    work_fs : working sampling rate [Hz] (the data are decimated by round(fs / work_fs))
    segments : blocks of the jackknife (>= 3)
    skip_s : samples at the start left out of every fit (filter transients) [s]
    confidence : level of the intervals
    """

    rectify: str = "auto"
    delay_ms: tuple = (10.0, 120.0)
    cutoff_hz: tuple = (0.5, 20.0)
    damping: tuple = (0.3, 2.0)
    lowpass_hz: float = 40.0
    work_fs: float = 500.0
    segments: int = 8
    skip_s: float = 1.0
    confidence: float = 0.95

    def check(self) -> None:
        if self.rectify not in RECTIFY:
            raise EstimationError(f"reflex rectify must be one of {RECTIFY}, got "
                                  f"{self.rectify!r}")
        for name in ("delay_ms", "cutoff_hz", "damping"):
            lo, hi = getattr(self, name)
            if not 0 < lo < hi:
                raise EstimationError(f"reflex {name} must be a range 0 < lo < hi, got "
                                      f"{getattr(self, name)}")
        if self.segments < 3:
            raise EstimationError(f"reflex segments must be at least 3, got "
                                  f"{self.segments}")
        if not 0 < self.confidence < 1:
            raise EstimationError(f"confidence must be in (0, 1), got {self.confidence}")


@dataclass
class ReflexResult:
    """The parallel-cascade fit of one joint.

    ``values`` and ``ci`` (half-widths at ``confidence``) map each name of PARAMS to a
    float (units in UNITS); ``vaf_pct`` holds ``intrinsic``, ``reflex``, ``total`` (of the
    parallel-cascade model) and ``intrinsic_only`` (K-B-I fitted alone) [%];
    ``intrinsic_only`` the K, B, I of that fit; ``jackknife`` the leave-one-block-out
    estimates (one dict per block).
    """

    trial: str
    joint: int
    fs: float
    work_fs: float
    rectify: str
    values: dict
    ci: dict
    confidence: float
    vaf_pct: dict
    intrinsic_only: dict
    n_samples: int
    resists_stretch: bool
    options: dict
    jackknife: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    #: best linear gain of the nonlinearity on the fitted velocity, cov(N(v), v) / var(v)
    #: (Bussgang 1952; 1 for "none", about 0.5 / -0.5 for a half-wave rectifier): what the
    #: rectified pathway contributes to the frequency response
    linear_gain: float = 1.0

    def frequency_response(self, f) -> dict:
        """The fitted model as frequency responses from the angle to the torque [N m/rad]
        at ``f`` (nf,) [Hz]: ``intrinsic`` ``K + j w B - w^2 I``, ``reflex`` ``G kappa j w
        LP(j w) exp(-j w d)`` with ``kappa`` the best linear gain of the nonlinearity
        (:attr:`linear_gain`) and LP the continuous-time low-pass, and ``total`` their
        sum; complex (nf,) arrays. The rectified pathway's harmonics and offset are not in
        a frequency response: this is its best linear approximation."""
        v = self.values
        jw = 2j * np.pi * np.asarray(f, dtype=float)
        wn = 2 * np.pi * v["cutoff_hz"]
        lp = wn * wn / (jw * jw + 2 * v["damping"] * wn * jw + wn * wn)
        intrinsic = v["K"] + v["B"] * jw + v["I"] * jw * jw
        reflex = v["G"] * self.linear_gain * jw * lp * np.exp(-jw * v["delay_ms"] * 1e-3)
        return {"intrinsic": intrinsic, "reflex": reflex, "total": intrinsic + reflex}

    def to_json(self) -> dict:
        return {"trial": self.trial, "joint": self.joint, "fs_hz": self.fs,
                "work_fs_hz": self.work_fs, "rectify": self.rectify,
                "parameters": {p: {"name": NAMES[p], "unit": UNITS[p],
                                   "value": self.values[p], "ci_half_width": self.ci[p],
                                   "confidence": self.confidence} for p in PARAMS},
                "vaf_pct": self.vaf_pct, "intrinsic_only": self.intrinsic_only,
                "resists_stretch": self.resists_stretch, "n_samples": self.n_samples,
                "linear_gain": self.linear_gain,
                "interval_method": f"delete-one-block jackknife, {len(self.jackknife)} "
                                   f"blocks",
                "options": self.options, "warnings": self.warnings}

    def describe(self) -> str:
        """Printed lines: intrinsic and reflex parameters with intervals, the VAFs."""
        v, c = self.values, self.ci
        conf = int(round(100 * self.confidence))
        lines = [f"  reflex (parallel cascade, {self.trial}, joint {self.joint}, rectify "
                 f"{self.rectify}, +- {conf} % jackknife over {len(self.jackknife)} blocks):",
                 f"    intrinsic: K={v['K']:.5g}±{c['K']:.2g} {UNITS['K']}  "
                 f"B={v['B']:.4g}±{c['B']:.2g} {UNITS['B']}  "
                 f"I={v['I']:.4g}±{c['I']:.2g} {UNITS['I']}",
                 f"    reflex: G={v['G']:.4g}±{c['G']:.2g} {UNITS['G']}  "
                 f"delay={delay_text(self, compact=True)}  "
                 f"low-pass {v['cutoff_hz']:.3g}±{c['cutoff_hz']:.2g} Hz, "
                 f"damping {v['damping']:.3g}±{c['damping']:.2g}",
                 f"    VAF intrinsic {self.vaf_pct['intrinsic']:.1f} %, reflex "
                 f"{self.vaf_pct['reflex']:.1f} %, total {self.vaf_pct['total']:.1f} % "
                 f"(K-B-I alone: {self.vaf_pct['intrinsic_only']:.1f} %, K="
                 f"{self.intrinsic_only['K']:.5g} B={self.intrinsic_only['B']:.4g} "
                 f"I={self.intrinsic_only['I']:.4g})"]
        lines += [f"    warning: {w}" for w in self.warnings]
        return "\n".join(lines)


# ----------------------------------------------------------------------------- data


@dataclass
class _Work:
    """Signals at the working rate: angle, velocity, acceleration, torque (N,)."""

    fs: float
    theta: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    tq: np.ndarray
    skip: int
    rectified: dict = None  # mode -> N(velocity), rectified before the anti-alias low-pass


def _prepare(theta, tau, fs, options) -> _Work:
    from scipy import signal
    if options.lowpass_hz >= fs / 2:
        raise ReflexNotApplicable(f"reflex fit: lowpass_hz {options.lowpass_hz:g} Hz must be "
                                  f"below the Nyquist frequency {fs / 2:g} Hz of the "
                                  f"recording (sampled at {fs:g} Hz)", kind="rate")
    q = max(1, int(round(fs / options.work_fs)))
    fw = fs / q
    if options.lowpass_hz >= 0.8 * fw / 2:
        raise ReflexNotApplicable(f"reflex fit: lowpass_hz {options.lowpass_hz:g} Hz too close "
                                  f"to the working Nyquist frequency {fw / 2:g} Hz (the "
                                  f"recording is sampled at {fs:g} Hz; at least "
                                  f"{2 * options.lowpass_hz / 0.8:g} Hz needed): "
                                  + (f"record at {2 * options.lowpass_hz / 0.8:g} Hz or "
                                     f"faster" if q == 1 else
                                     f"raise ReflexOptions.work_fs (now {options.work_fs:g}"
                                     f" Hz)"), kind="rate")
    sos = signal.butter(4, options.lowpass_hz, fs=fs, output="sos")
    th_full = signal.sosfiltfilt(sos, theta)
    vel_full = derivative(th_full, fs)
    # derivatives at the recording rate, then decimated: no roll-off in the band
    th, vel, acc = th_full[::q], vel_full[::q], derivative(vel_full, fs)[::q]
    tq = signal.sosfiltfilt(sos, tau)[::q]
    rectified = _rectified(theta, fs, sos, options.lowpass_hz, q)
    skip = _skip(options, fw)
    if th.size - skip < fw * options.segments:  # at least 1 s per jackknife block
        need = minimum_samples(options, fs)
        raise ReflexNotApplicable(
            f"reflex fit: the recording has {theta.size / fs:.4g} s ({theta.size} samples), "
            f"fewer than the minimum of {need / fs:.4g} s ({need} samples at {fs:g} Hz: the "
            f"first {options.skip_s:g} s and the longest delay searched, "
            f"{options.delay_ms[1]:g} ms, left out, then {options.segments} jackknife "
            f"blocks of at least 1 s); record at least {need / fs:.4g} s")
    return _Work(fw, th, vel, acc, tq, skip, rectified)


# 8th-order central difference: gain error (w T)^8 / 630, below 1e-5 at 0.25 fs / 2 (a
# central 3-point difference, np.gradient, loses 1 - sin(w T) / (w T): 4 % at 40 Hz and
# 500 Hz, which biased K, B, I of the reflex fit by 2-10 %).
_D1 = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0.0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])


def derivative(x, fs):
    """First derivative of ``x`` (N,) sampled at ``fs`` [Hz], in units of x per second.

    A 9-point central difference (Fornberg 1988), exact to the 8th order: for a signal
    band-limited to a quarter of the sampling rate its gain error is below 1e-3 (the
    3-point difference's is 10 % there). The 4 samples at each end fall back to
    :func:`numpy.gradient`."""
    x = np.asarray(x, float)
    out = np.gradient(x, 1.0 / fs) if x.size > 1 else np.zeros_like(x)
    if x.size > _D1.size:
        out[4:-4] = np.convolve(x, _D1[::-1], mode="valid") * fs
    return out


def _skip(options, fw) -> int:
    """Working samples at the start left out of every fit (transients, longest delay)."""
    return int(np.ceil(options.skip_s * fw)) + int(np.ceil(options.delay_ms[1] * 1e-3 * fw)) + 2


def minimum_samples(options: "ReflexOptions | None", fs: float) -> int:
    """The fewest samples at ``fs`` [Hz] a recording needs for :func:`fit_reflex`: the
    first ``skip_s`` and the longest delay searched left out, then ``segments`` jackknife
    blocks of at least 1 s at the working rate (``fs / round(fs / work_fs)``)."""
    options = options or ReflexOptions()
    q = max(1, int(round(fs / options.work_fs)))
    fw = fs / q
    n_work = _skip(options, fw) + int(np.ceil(fw * options.segments - 1e-9))
    return (n_work - 1) * q + 1  # every q-th sample from the first


def _rectified(theta, fs, sos, lowpass_hz, q) -> dict:
    """The reflex input N(velocity) per rectification mode, at the working rate.

    The velocity is taken from the angle low-passed at twice ``lowpass_hz`` (or 0.45 fs),
    rectified, and only then passed through the anti-alias low-pass that the torque went
    through: the torque's reflex part is LP_aa[G h * N(v)], and N does not commute with
    LP_aa (rectifying the low-passed velocity biased the reflex gain by about 20 % with a
    perturbation that fills the band)."""
    from scipy import signal
    wide = signal.butter(4, min(2 * lowpass_hz, 0.45 * fs), fs=fs, output="sos")
    vel = derivative(signal.sosfiltfilt(wide, theta), fs)
    return {mode: signal.sosfiltfilt(sos, _nonlinearity(vel, mode))[::q]
            for mode in ("positive", "negative")}  # "none" commutes: the velocity itself


def _input(w, mode):
    """N(velocity) of ``mode`` for the work signals ``w`` (rectified before the low-pass
    where :func:`_prepare` made them, else from the working-rate velocity)."""
    if w.rectified is not None and mode in w.rectified:
        return w.rectified[mode]
    return _nonlinearity(w.vel, mode)


def _nonlinearity(vel, rectify):
    if rectify == "positive":
        return np.maximum(vel, 0.0)
    if rectify == "negative":
        return np.maximum(-vel, 0.0)
    return vel.copy()


def _lowpass(u, fc, zeta, fs):
    """Unit-DC-gain 2nd-order low-pass, Tustin with the natural frequency prewarped."""
    from scipy import signal
    c = 2 * fs
    wd = c * np.tan(np.pi * fc / fs)  # prewarped 2 pi fc
    w2, zc = wd * wd, 2 * zeta * wd * c  # s = c (1 - 1/z) / (1 + 1/z) in the analog filter
    a0 = c * c + zc + w2
    den = np.array([1.0, (2 * w2 - 2 * c * c) / a0, (c * c - zc + w2) / a0])
    return signal.lfilter(np.array([1.0, 2.0, 1.0]) * (w2 / a0), den, u)


def _delayed(x, d_samples):
    """``x`` delayed by a (fractional) number of samples, linear interpolation; zeros in."""
    k = int(np.floor(d_samples))
    a = d_samples - k
    out = np.zeros_like(x)
    if k < x.size:
        out[k:] = x[:x.size - k]
    if a > 0:
        nxt = np.zeros_like(x)
        if k + 1 < x.size:
            nxt[k + 1:] = x[:x.size - k - 1]
        out = (1 - a) * out + a * nxt
    return out


# ----------------------------------------------------------------------------- fit
# Tall products go through einsum and FFTs, not BLAS: a multi-threaded BLAS on a loaded
# machine made a (30000 x 4)^T (30000 x 56) product 100 times slower than one thread.


def _ein(spec, *ops):
    return np.einsum(spec, *ops, optimize=False)


class _Design:
    """The intrinsic regressors ``[theta, theta', theta'', 1]`` on the rows of ``mask``:
    an orthonormal basis ``Q`` (N, 4) (zero off the rows), the torque's residual ``r0``
    out of it, and what recovers K, B, I, c from a fit."""

    def __init__(self, w: _Work, mask: np.ndarray):
        self.mask = mask
        A = np.column_stack([w.theta, w.vel, w.acc, np.ones(w.theta.size)]) * mask[:, None]
        self.scale = np.sqrt(_ein("ni,ni->i", A, A))
        As = A / self.scale
        L = np.linalg.cholesky(_ein("ni,nj->ij", As, As))
        self.Linv = np.linalg.inv(L)
        self.Q = _ein("nj,ij->ni", As, self.Linv)
        self.y = w.tq * mask
        self.r0 = self.y - _ein("nk,k->n", self.Q, _ein("nk,n->k", self.Q, self.y))
        self.rows = np.nonzero(mask)[0]

    def coefficients(self, target):
        """Least-squares K, B, I, c of ``target`` (N,) on the rows."""
        c = _ein("nk,n->k", self.Q, target * self.mask)
        return (self.Linv.T @ c) / self.scale

    def project_out(self, x):
        xm = x * self.mask
        return xm - _ein("nk,k->n", self.Q, _ein("nk,n->k", self.Q, xm))


def _correlate(a_f, x_f, nfft, shifts):
    """``sum_n a[n] x[n - s]`` for each s of ``shifts`` (no wrap: nfft >= N + max s)."""
    return np.fft.irfft(a_f * np.conj(x_f), nfft)[..., shifts]


def _grid_search(w: _Work, design: _Design, rectify, options):
    """Best (rss, d_samples, fc, zeta) over the grid, by projection of the reflex column."""
    d_lo = int(np.floor(options.delay_ms[0] * 1e-3 * w.fs))
    d_hi = int(np.ceil(options.delay_ms[1] * 1e-3 * w.fs))
    shifts = np.arange(d_lo, d_hi + 1)
    n = w.theta.size
    nfft = 1 << int(np.ceil(np.log2(n + d_hi + 1)))
    stack = np.vstack([design.r0, design.Q.T, design.mask])  # (6, N)
    stack_f = np.fft.rfft(stack, nfft, axis=1)
    rr = float(_ein("n,n->", design.r0, design.r0))
    u = _input(w, rectify)
    best = (np.inf, None, None, None)
    for fc in np.geomspace(*options.cutoff_hz, 12):
        if fc >= 0.45 * w.fs:
            continue
        for zeta in np.geomspace(*options.damping, 5):
            x = _lowpass(u, fc, zeta, w.fs)
            xf = np.fft.rfft(np.vstack([x, x * x]), nfft, axis=1)
            c = _correlate(stack_f[:5], xf[0], nfft, shifts)
            e = _correlate(stack_f[5], xf[1], nfft, shifts)
            den = e - np.sum(c[1:] ** 2, axis=0)
            ok = den > 1e-12 * max(float(e.max()), 1e-300)
            gain = np.where(ok, c[0] ** 2 / np.where(ok, den, 1.0), 0.0)
            j = int(np.argmax(gain))
            rss = rr - float(gain[j])
            if rss < best[0]:
                best = (rss, float(shifts[j]), float(fc), float(zeta))
    return best


def _reflex_column(w: _Work, mode, d, fc, zeta):
    return _delayed(_lowpass(_input(w, mode), fc, zeta, w.fs), d)


def _refine(w: _Work, design: _Design, mode, p0, options):
    """Continuous (d [samples], log fc, log zeta) from p0: Levenberg-Marquardt on the
    projected residual, forward-difference Jacobian, steps clipped to the search ranges."""
    lo = np.array([options.delay_ms[0] * 1e-3 * w.fs, np.log(options.cutoff_hz[0]),
                   np.log(options.damping[0])])
    hi = np.array([options.delay_ms[1] * 1e-3 * w.fs,
                   np.log(min(options.cutoff_hz[1], 0.45 * w.fs)), np.log(options.damping[1])])
    rows = design.rows
    r0 = design.r0[rows]

    def resid(q):
        xp = design.project_out(_reflex_column(w, mode, q[0], np.exp(q[1]),
                                               np.exp(q[2])))[rows]
        xx = float(_ein("n,n->", xp, xp))
        g = float(_ein("n,n->", xp, r0)) / xx if xx > 0 else 0.0
        return r0 - g * xp

    p = np.clip(np.asarray(p0, dtype=float), lo, hi)
    f = resid(p)
    cost = float(_ein("n,n->", f, f))
    h = np.array([0.01, 1e-3, 1e-3])
    lam = 1e-3
    for _ in range(50):
        J = np.empty((f.size, 3))
        for k in range(3):
            step = np.zeros(3)
            step[k] = h[k] if p[k] + h[k] <= hi[k] else -h[k]
            J[:, k] = (resid(p + step) - f) / step[k]
        JTJ = _ein("nk,nj->kj", J, J)
        grad = _ein("nk,n->k", J, f)
        improved = False
        for _ in range(12):
            A = JTJ + lam * np.diag(np.diag(JTJ) + 1e-300)
            pn = np.clip(p - np.linalg.solve(A, grad), lo, hi)
            fn = resid(pn)
            cn = float(_ein("n,n->", fn, fn))
            if cn < cost:
                improved = True
                break
            lam *= 4.0
        if not improved:
            break
        done = cost - cn <= 1e-12 * cost and np.all(np.abs(pn - p) <= 1e-6 * np.maximum(1, np.abs(p)))
        small = np.all(np.abs(pn - p) <= np.array([1e-4, 1e-6, 1e-6]))
        p, f, cost, lam = pn, fn, cn, max(lam / 3.0, 1e-9)
        if done or small:
            break
    return p


def _values(w: _Work, design: _Design, mode, p):
    d, fc, zeta = p[0], float(np.exp(p[1])), float(np.exp(p[2]))
    x = _reflex_column(w, mode, d, fc, zeta)
    xp = design.project_out(x)
    xx = float(_ein("n,n->", xp, xp))
    g = float(_ein("n,n->", xp, design.r0)) / xx if xx > 0 else 0.0
    k, b, i, _ = design.coefficients(w.tq - g * x)
    return {"K": float(k), "B": float(b), "I": float(i), "G": g,
            "delay_ms": float(1e3 * d / w.fs), "cutoff_hz": fc, "damping": zeta}


def _fit(w: _Work, mask, rectify, options, start=None):
    """Global grid then continuous refinement (or refinement from ``start`` = (mode, p)).

    Returns (values dict of PARAMS, rectification, parameter vector).
    """
    design = _Design(w, mask)
    if start is None:
        modes = ("positive", "negative") if rectify == "auto" else (rectify,)
        found = [(_grid_search(w, design, m, options), m) for m in modes]
        (_, d0, fc0, z0), mode = min(found, key=lambda g: g[0][0])
        p0 = np.array([d0, np.log(fc0), np.log(z0)])
    else:
        mode, p0 = start
    p = _refine(w, design, mode, p0, options)
    return _values(w, design, mode, p), mode, p


def _vafs(w: _Work, mask, mode, v):
    rows = np.nonzero(mask)[0]
    x = _reflex_column(w, mode, v["delay_ms"] * 1e-3 * w.fs, v["cutoff_hz"], v["damping"])
    y = w.tq[rows] - w.tq[rows].mean()
    ti = v["K"] * w.theta[rows] + v["B"] * w.vel[rows] + v["I"] * w.acc[rows]
    tr = v["G"] * x[rows]
    ti, tr = ti - ti.mean(), tr - tr.mean()
    k, b, i, _ = _Design(w, mask).coefficients(w.tq)
    to = k * w.theta[rows] + b * w.vel[rows] + i * w.acc[rows]
    to = to - to.mean()

    def vaf(pred):
        return float(100 * (1 - np.var(y - pred) / np.var(y)))

    return ({"intrinsic": vaf(ti), "reflex": vaf(tr), "total": vaf(ti + tr),
             "intrinsic_only": vaf(to)}, {"K": float(k), "B": float(b), "I": float(i)})


def fit_reflex(theta, tau, fs, options: ReflexOptions | None = None, *, name="",
               joint=1) -> ReflexResult:
    """Fit the parallel-cascade model to one joint's angle and torque.

    Parameters
    ----------
    theta : array_like (N,) [rad]
        Measured joint angle (the project's convention).
    tau : array_like (N,) [N m]
        Measured interaction torque (the project's sign convention).
    fs : float [Hz]
        Sampling rate.
    options : ReflexOptions
    name, joint : labels of the result.

    Returns
    -------
    ReflexResult
        Values, jackknife half-widths and VAFs (module docstring).

    Raises
    ------
    EstimationError
        Bad options, non-finite or mismatched signals, too few samples.
    """
    options = options or ReflexOptions()
    options.check()
    theta = np.asarray(theta, dtype=float).ravel()
    tau = np.asarray(tau, dtype=float).ravel()
    if theta.shape != tau.shape:
        raise EstimationError(f"reflex fit: angle has {theta.size} samples, torque "
                              f"{tau.size}")
    if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(tau))):
        raise EstimationError("reflex fit: angle or torque holds non-finite values")
    w = _prepare(theta, tau, float(fs), options)
    mask = np.zeros(w.theta.size)
    mask[w.skip:] = 1.0
    values, mode, p = _fit(w, mask, options.rectify, options)
    blocks = np.array_split(np.arange(w.skip, w.theta.size), options.segments)
    jack = []
    for block in blocks:  # each leave-one-block-out fit refined from the full-data optimum
        keep = mask.copy()
        keep[block] = 0.0
        jack.append(_fit(w, keep, mode, options, start=(mode, p))[0])
    m = options.segments
    from scipy import stats
    tq = stats.t.ppf(0.5 + options.confidence / 2, m - 1)
    ci = {}
    for p in PARAMS:
        est = np.array([j[p] for j in jack])
        ci[p] = float(tq * np.sqrt((m - 1) / m * np.sum((est - est.mean()) ** 2)))
    vafs, alone = _vafs(w, mask, mode, values)
    rows = mask > 0
    v = w.vel[rows] - w.vel[rows].mean()
    u = _input(w, mode)[rows]
    kappa = float(np.dot(u - u.mean(), v) / np.dot(v, v)) if np.dot(v, v) > 0 else 0.0
    resists = bool(values["G"] > 0) if mode != "negative" else bool(values["G"] < 0)
    result = ReflexResult(
        trial=name, joint=joint, fs=float(fs), work_fs=w.fs, rectify=mode, values=values,
        ci=ci, confidence=options.confidence, vaf_pct=vafs, intrinsic_only=alone,
        n_samples=int(mask.sum()), resists_stretch=resists, options=asdict(options),
        jackknife=jack, linear_gain=kappa)
    result.warnings = reflex_warnings(result, options)
    return result


def delay_text(r: ReflexResult, *, compact=False, unit=True) -> str:
    """The fitted delay as printed: ``52.8 ± 2.7 ms``, or, at an end of its search range
    (where the jackknife interval is 0 and means nothing), ``10.0 ms (at the search bound)``
    without an interval. ``compact``: ``52.8±2.7 ms`` (the console's style)."""
    d, ci = r.values["delay_ms"], r.ci["delay_ms"]
    rng = (r.options or {}).get("delay_ms")
    ms = " ms" if unit else ""
    if rng is not None and any(np.isclose(d, b, rtol=1e-3) for b in rng):
        return f"{d:.1f}{ms} (at the search bound)"
    text = plus_minus(d, ci)
    return (text.replace(" ± ", "±") if compact else text) + ms


def reflex_warnings(r: ReflexResult, options: ReflexOptions) -> list:
    """What a lab must know before using the reflex numbers."""
    out = []
    gain = r.vaf_pct["total"] - r.vaf_pct["intrinsic_only"]
    if gain < 1.0:
        out.append(f"reflex pathway adds {gain:.2f} % VAF to the K-B-I model (< 1 %): no "
                   f"reflex detected; its delay and low-pass are not determined")
    if abs(r.ci["G"]) >= abs(r.values["G"]):
        out.append(f"reflex gain not significant: G = {r.values['G']:.3g} +- "
                   f"{r.ci['G']:.2g} {UNITS['G']}")
    for p, rng in (("delay_ms", options.delay_ms), ("cutoff_hz", options.cutoff_hz),
                   ("damping", options.damping)):
        if p == "delay_ms" and np.isclose(r.values[p], rng[0], rtol=1e-3):
            out.append(f"reflex delay at the shortest allowed, {rng[0]:g} ms: the "
                       f"'reflex' pathway is not a stretch reflex here (it takes up a part "
                       f"of the response the K-B-I model lacks, and K, B, I move with it); "
                       f"no reflex identified in {rng[0]:g}-{rng[1]:g} ms")
        elif np.isclose(r.values[p], rng[0], rtol=1e-3) or np.isclose(r.values[p], rng[1],
                                                                      rtol=1e-3):
            opt = "--reflex-" + {"delay_ms": "delay-ms", "cutoff_hz": "cutoff-hz",
                                 "damping": "damping"}[p]
            lo, hi = rng
            wider = (lo / 2, hi) if np.isclose(r.values[p], lo, rtol=1e-3) else (lo, 2 * hi)
            out.append(f"{p} = {r.values[p]:.4g} is at the edge of its search range "
                       f"{lo:g}-{hi:g}: widen the range (e.g. {opt} {wider[0]:g} "
                       f"{wider[1]:g}; ReflexOptions.{p} in the API)")
    late = latency_warning(r.values["delay_ms"], r.values.get("cutoff_hz"),
                           r.values.get("damping"))
    if late and gain >= 1.0:
        out.append(late)
    if not r.resists_stretch and gain >= 1.0:
        out.append("the reflex torque aids the stretch instead of resisting it (check the "
                   "torque sign: sensors.torque_sign)")
    if r.values["K"] < 0:
        out.append(f"intrinsic K = {r.values['K']:.4g} N m/rad is negative (torque sign "
                   f"reversed? declare sensors.torque_sign = -1)")
    return out


def fit_reflex_trial(trial, options: ReflexOptions | None = None) -> ReflexResult:
    """:func:`fit_reflex` on a one-joint trialformat.Trial (its ``theta`` and ``tau_h``).

    Raises ReflexNotApplicable for a trial of several joints (kind ``"joints"``) or a
    constant ``theta`` or ``tau_h`` (kind ``"constant"``: estimation.lab.check_not_constant).
    """
    if trial.n_dof != 1:
        raise ReflexNotApplicable(f"the reflex model is for one joint; trial {trial.name!r} "
                                  f"has {trial.n_dof} joints", kind="joints")
    from .lab import check_not_constant
    try:
        check_not_constant([trial], "direct")
    except EstimationError as exc:
        raise ReflexNotApplicable(f"reflex fit: {exc}", kind="constant") from None
    return fit_reflex(trial.theta[:, 0], trial.tau_h[:, 0], trial.fs, options,
                      name=trial.name, joint=1)


def reflex_of_unit(trials, options=True) -> list:
    """The parallel-cascade fit of every trial of a set.

    ``options`` is a ReflexOptions or True (defaults). Raises ReflexNotApplicable (an
    EstimationError) for trials of several joints or too short (:func:`reflex_of_trials`
    reports those instead).
    """
    opts = options if isinstance(options, ReflexOptions) else ReflexOptions()
    return [fit_reflex_trial(t, opts) for t in trials]


def reflex_of_trials(trials, options=True) -> tuple[list, list]:
    """The lab estimator's hook: the parallel-cascade fit of every trial of a set where it
    applies. Returns ``(results, not_fitted)``: the ReflexResult of each fitted trial and,
    for each other one, ``{"trial", "reason", "kind"}`` with ``kind`` ``"joints"`` (a
    trial of several joints: the model is for one), ``"short"`` (fewer samples than
    :func:`minimum_samples`; the reason names the minimum) or ``"rate"`` (sampled too
    slowly for the fit's low-pass), ``"constant"`` (a constant angle or torque) or
    ``"singular"`` (linearly dependent regressors: a
    constant angle). Other errors (bad options, non-finite data) raise."""
    opts = options if isinstance(options, ReflexOptions) else ReflexOptions()
    opts.check()
    fitted, skipped = [], []
    for t in trials:
        if t.n_dof != 1:
            skipped.append({"trial": t.name, "kind": "joints", "reason": (
                f"the parallel-cascade model is for one joint; {t.name!r} has "
                f"{t.n_dof} joints")})
            continue
        try:
            fitted.append(fit_reflex_trial(t, opts))
        except ReflexNotApplicable as exc:
            skipped.append({"trial": t.name, "kind": exc.kind, "reason": str(exc)})
        except np.linalg.LinAlgError as exc:  # a constant or degenerate angle or torque
            skipped.append({"trial": t.name, "kind": "singular", "reason": (
                f"reflex fit: the regressors of {t.name!r} (angle, velocity, acceleration, "
                f"delayed velocity) are linearly dependent ({exc}): is an angle or torque "
                f"column constant?")})
    return fitted, skipped


COLUMNS = ("label", "trial", "rectify") + tuple(
    c for p in PARAMS for c in (f"{p} [{UNITS[p]}]", f"{p}_ci [{UNITS[p]}]")) + (
    "VAF_intrinsic [%]", "VAF_reflex [%]", "VAF_total [%]", "VAF_KBI_alone [%]",
    "K_KBI_alone [N m/rad]", "B_KBI_alone [N m s/rad]", "I_KBI_alone [kg m^2]")


def reflex_rows(results) -> list:
    """One row per trial of every LabResult carrying ``reflex`` (columns COLUMNS)."""
    rows = []
    for res in results:
        for r in res.reflex or []:
            row = [res.label, r.trial, r.rectify]
            for p in PARAMS:
                row += [r.values[p], r.ci[p]]
            row += [r.vaf_pct[k] for k in ("intrinsic", "reflex", "total", "intrinsic_only")]
            row += [r.intrinsic_only[k] for k in ("K", "B", "I")]
            rows.append(dict(zip(COLUMNS, row)))
    return rows


def reflex_parameter_rows(results) -> list:
    """Rows of parameters.csv for the parallel-cascade fits: one per fitted trial, with the
    keys of lab.result_rows for the intrinsic K, B, I (I under M) and their intervals, the
    reflex parameters and intervals, and the three time-domain VAFs."""
    rows = []
    for res in results:
        for r in res.reflex or []:
            v, c = r.values, r.ci
            row = {"label": res.label, "method": "parallel cascade (time domain)",
                   "element": "Z11", "model": f"intrinsic + reflex: {r.trial}"}
            for p, key in (("I", "M"), ("B", "B"), ("K", "K")):
                row[f"{key} [{UNITS[p]}]"] = v[p]
                row[f"{key}_ci [{UNITS[p]}]"] = c[p]
            for p in ("G", "delay_ms", "cutoff_hz", "damping"):
                row[f"{p} [{UNITS[p]}]"] = v[p]
                row[f"{p}_ci [{UNITS[p]}]"] = c[p]
            row.update({"rectify": r.rectify,
                        "VAF_intrinsic [%]": r.vaf_pct["intrinsic"],
                        "VAF_reflex [%]": r.vaf_pct["reflex"],
                        "VAF_total [%]": r.vaf_pct["total"],
                        "VAF_KBI_alone [%]": r.vaf_pct["intrinsic_only"]})
            rows.append(row)
    return rows


def reflex_markdown(results) -> str:
    """The intrinsic + reflex table of a lab report (with each trial's warnings)."""
    conf = next((int(round(100 * r.confidence)) for res in results
                 for r in res.reflex or []), 95)
    head = ["trial", "K [N m/rad]", "B [N m s/rad]", "I [kg m^2]", "G [N m s/rad]",
            "delay [ms]", "low-pass [Hz]", "damping", "VAF I / R / total [%]",
            "K-B-I alone: K, VAF [%]"]
    lines = ["### Intrinsic and reflex pathways (parallel cascade, Kearney et al. 1997)\n",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    notes = []
    for res in results:
        for r in res.reflex or []:
            v, c = r.values, r.ci
            cells = [f"{r.trial} ({r.rectify})"] + [
                delay_text(r, unit=False) if p == "delay_ms" else plus_minus(v[p], c[p])
                for p in PARAMS] + [
                f"{r.vaf_pct['intrinsic']:.1f} / {r.vaf_pct['reflex']:.1f} / "
                f"{r.vaf_pct['total']:.1f}",
                f"{r.intrinsic_only['K']:.4g}, {r.vaf_pct['intrinsic_only']:.1f}"]
            lines.append("| " + " | ".join(cells) + " |")
            notes += [f"- {r.trial}: warning: {w}" for w in r.warnings]
    lines.append(f"\n± : {conf} % intervals, delete-one-block jackknife. VAF of the "
                 f"low-passed torque; 'K-B-I alone' is the intrinsic model fitted without "
                 f"the reflex pathway, in the time domain.\n")
    return "\n".join(lines + notes) + "\n"


def write_reflex_tables(results, folder) -> list:
    """``reflex.csv`` and ``reflex.md`` in ``folder`` (a lab report being built)."""
    import csv
    import io
    from pathlib import Path
    folder = Path(folder)
    rows = reflex_rows(results)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(COLUMNS), lineterminator="\n")
    writer.writeheader()
    writer.writerows([{k: (f"{v:.10g}" if isinstance(v, float) else v)
                       for k, v in row.items()} for row in rows])
    out = []
    for name, text in (("reflex.csv", buf.getvalue()), ("reflex.md", reflex_markdown(results))):
        (folder / name).write_text(text, encoding="utf-8")
        out.append(folder / name)
    return out
