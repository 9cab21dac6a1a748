"""Piecewise-constant K, B, I of one joint whose impedance switches: a segment-wise fit on
the change points of the project's time-variation test, the change times refined on the
samples.

A square-wave stiffness (a subject switching between relaxed and co-contracted, the
"most extreme case of time-varying behaviour" of van de Ruit et al., Annu Rev Control
52:91, 2021) is what neither smooth tracker of the project follows: a Chebyshev
expansion in time (estimation/varying.py) rings and is chosen flat by its held-out test
when the switches are many, and a windowed estimate (estimation/timevarying.py, track)
averages the two levels in every window astride a switch. Here (:func:`segment_track`):

1. **Change points.** :func:`estimation.timevarying.time_variation` on short windows
   (``window_s``, 0.25 s by default: a level must last 2 windows, MIN_BLOCK, to be seen;
   the Bonferroni-controlled seeded binary segmentation keeps the false-alarm rate at
   ``alpha`` on a stationary record).
2. **Refinement.** Each change time is moved, one at a time, to the split (on a grid of
   ``step_s``, within ``search_s`` of it and between its neighbours) that minimises the
   summed squared error of the K-B-I least-squares fits of the two segments either side
   (angle, its derivatives and torque band-passed as in the track, but over the wider
   ``refine_band_hz``, 1-60 Hz; sums of squares cumulated once, so every split costs a
   3x3 solve). Change points that end up closer than ``min_segment_s`` (MIN_BLOCK
   windows) are merged, and the sweep repeated. Then change points are pruned one at a
   time while the weakest one's removal raises the squared error less than a split
   without a change would (:func:`_prune`): two change points either side of one switch
   (a window astride it, seen as an intermediate level) become one.
3. **Values.** K, B, I of each segment by least squares over the segment less ``guard_s``
   at each end (the zero-phase band-pass smears a switch over its impulse response; the
   smear is symmetric, so the split is unbiased but the samples next to it are mixed);
   95 % half-widths by batch means (:func:`_batch_half_widths`): the segment's fitted
   span cut into m contiguous sub-blocks of about ``window_s``, each fitted alone,
   ``t_{0.975, m-1} sd / sqrt(m)`` of their spread; where m < 3 (a short end segment)
   the window noise of step 1 (3-30 Hz fits), ``1.96 sigma sqrt(window_s / L)``
   (``ci_window``, kept beside). On the square-wave bench (``bench/bench_square_wave.py
   --coverage``, 40 runs, 15 dB, 840 segments) the window-noise half-widths covered the
   truth 98.9 % (K), 99.9 % (B), 100 % (I) of the time, too wide: their sigma is of
   3-30 Hz fits, the segments' of 1-60 Hz; the batch means 95.6, 96.6, 95.8 %.

The result is a step function of time: its rise time is zero, and its error at a switch
is the error of the change time (``SegmentTrack.change_s``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal as sps

from .timevarying import ALPHA, BAND_HZ, EDGE_S, MIN_BLOCK, PARAMS, time_variation

#: defaults: window of the change-point test [s], grid and reach of the refinement [s],
#: samples left out of each segment's fit at its ends [s]; the shortest segment kept is
#: MIN_BLOCK windows (the shortest level the window test can see)
WINDOW_S, STEP_S, SEARCH_S, GUARD_S = 0.25, 0.005, 0.5, 0.1
#: band [Hz] of the refinement and the segment fits (top capped at 0.4 fs): wider than
#: the window test's 3-30 Hz, since a split is placed by the torque's fast detail. On
#: the square-wave bench's recording (noise perturbation to 40 Hz, 15 dB SNR, 3 noise
#: draws) the RMS change-time error was 22.6-25.2 ms with 3-30 Hz, 9.6-11.3 ms with
#: 1-40 Hz, 6.5-10.1 ms with 1-60 Hz, 6.3-9.8 ms with 1-100 Hz (VAF of K(t) 95.9-96.3,
#: 98.4-98.5, 98.7-99.1, 98.9-99.2 %)
REFINE_BAND_HZ = (1.0, 60.0)


@dataclass
class SegmentTrack:
    """Piecewise-constant K, B, I of one joint (SI units).

    ``edges_s`` (S + 1,) the segments' bounds [s] (the first and last the usable span,
    EDGE_S inside the record); ``values[p]`` (S,) and ``ci[p]`` (S,) the segment values
    and 95 % half-widths for p in K, B, I (``ci_batch``, from the spread of the
    segment's sub-block fits, where it has 3 sub-blocks or more, else ``ci_window``, from
    the window test's noise: module docstring, step 3); ``change_s`` (S - 1,) the refined change
    times [s]; ``initial_change_s`` those of the window test before refinement."""

    edges_s: np.ndarray
    values: dict
    ci: dict
    change_s: np.ndarray
    initial_change_s: np.ndarray
    window_s: float
    sign: float
    warnings: list = field(default_factory=list)
    ci_window: dict = field(default_factory=dict)
    ci_batch: dict = field(default_factory=dict)

    def at(self, t) -> dict:
        """``{p: (M,)}`` the step functions at times ``t`` (M,) [s]; outside the usable
        span the first / last segment's value."""
        t = np.asarray(t, dtype=float)
        k = np.clip(np.searchsorted(self.edges_s, t, side="right") - 1, 0,
                    len(self.edges_s) - 2)
        return {p: self.values[p][k] for p in PARAMS}

    def to_json(self) -> dict:
        return {"edges_s": [float(x) for x in self.edges_s],
                "change_s": [float(x) for x in self.change_s],
                "initial_change_s": [float(x) for x in self.initial_change_s],
                "values": {p: [float(v) for v in self.values[p]] for p in PARAMS},
                "ci95": {p: [float(v) for v in self.ci[p]] for p in PARAMS},
                "ci95_window": {p: [float(v) for v in self.ci_window.get(p, [])]
                                for p in PARAMS},
                "ci95_batch": {p: [float(v) for v in self.ci_batch.get(p, [])]
                               for p in PARAMS},
                "window_s": self.window_s, "warnings": list(self.warnings)}


def _design(theta, tau, fs, band_hz):
    """Band-passed angle, velocity, acceleration (N, 3) and torque (N,): the same
    zero-phase Butterworth band-pass on both sides (as estimation.timevarying.track),
    the derivatives by Savitzky-Golay filters (order 4) whose gains are within 2e-5 of
    j w and -w^2 up to the band's top (estimation.varying.sg_window). Central
    differences, as the track uses, fall 4.7 % short in the acceleration at 60 Hz and
    1 kHz, which put a +2.4 N m/rad bias on K at a 1-60 Hz band."""
    from .varying import sg_window
    lo, hi = band_hz[0], min(band_hz[1], 0.4 * fs)
    sos = sps.butter(4, [lo, hi], btype="bandpass", fs=fs, output="sos")
    x = sps.sosfiltfilt(sos, theta)
    y = sps.sosfiltfilt(sos, tau)
    L = sg_window(fs, hi)
    X = np.stack([x, sps.savgol_filter(x, L, 4, deriv=1, delta=1.0 / fs),
                  sps.savgol_filter(x, L, 4, deriv=2, delta=1.0 / fs)], axis=1)
    return X, y


class _Sums:
    """Cumulative sums of X'X, X'y, y'y: the least-squares fit of any span [a, b) of
    samples in O(1) (a 3x3 solve)."""

    def __init__(self, X, y):
        self.scale = np.sqrt(np.mean(X ** 2, axis=0)) + 1e-300  # conditioning only
        Xs = X / self.scale
        n = X.shape[0]
        self.xx = np.zeros((n + 1, 3, 3))
        self.xy = np.zeros((n + 1, 3))
        self.yy = np.zeros(n + 1)
        np.cumsum(Xs[:, :, None] * Xs[:, None, :], axis=0, out=self.xx[1:])
        np.cumsum(Xs * y[:, None], axis=0, out=self.xy[1:])
        np.cumsum(y * y, out=self.yy[1:])

    def rss(self, a, b):
        """Residual sums of squares of the fits on [a, b) (arrays of sample indices)."""
        a, b = np.asarray(a), np.asarray(b)
        A = self.xx[b] - self.xx[a]
        c = self.xy[b] - self.xy[a]
        sol = np.linalg.solve(A + 1e-12 * np.eye(3), c[..., None])[..., 0]
        return self.yy[b] - self.yy[a] - np.einsum("...i,...i->...", sol, c)

    def coef(self, a, b):
        """(K, B, I) of the fit on [a, b)."""
        A = self.xx[b] - self.xx[a]
        c = self.xy[b] - self.xy[a]
        return np.linalg.solve(A, c) / self.scale


def segment_track(theta, tau, fs, *, window_s=WINDOW_S, band_hz=BAND_HZ, alpha=ALPHA,
                  refine_band_hz=REFINE_BAND_HZ,
                  step_s=STEP_S, search_s=SEARCH_S, min_segment_s=None,
                  guard_s=GUARD_S, sign=1, passes=2) -> SegmentTrack:
    """Piecewise-constant K, B, I of one joint (module docstring).

    Parameters
    ----------
    theta, tau : (N,) arrays [rad], [N m]: the joint's angle and the subject's torque
    fs : sampling rate [Hz]
    window_s, band_hz, alpha : the change-point test's window [s], band [Hz] and
        family-wise false-alarm rate (estimation.timevarying.time_variation)
    refine_band_hz : band [Hz] of the refinement and the segments' fits
    step_s, search_s : grid and reach [s] of the change-time refinement
    min_segment_s : change points closer than this [s] are merged (None: MIN_BLOCK
        windows, the shortest level the window test sees)
    guard_s : samples left out of each segment's fit next to a change [s]
    sign : +1 / -1 on the torque (default +1: the torque as given, the declared sign
        already applied, as estimation.timevarying.track); None: the sign that makes the
        whole record's K positive
    passes : sweeps of the one-at-a-time refinement

    Returns
    -------
    SegmentTrack

    Raises
    ------
    ValueError
        Too short or non-finite data (from the time-variation test).
    """
    theta = np.asarray(theta, float).ravel()
    tau = np.asarray(tau, float).ravel()
    if min_segment_s is None:
        min_segment_s = MIN_BLOCK * window_s
    tv = time_variation(theta, tau, fs, window_s=window_s, band_hz=band_hz, alpha=alpha,
                        sign=sign)
    sgn = float(sign) if sign is not None else _sign_of(tv, theta, tau, fs, band_hz)
    X, y = _design(theta, tau * sgn, fs, refine_band_hz)
    sums = _Sums(X, y)
    edge = int(np.ceil(min(EDGE_S, 0.1 * theta.size / fs) * fs))
    lo_i, hi_i = edge, theta.size - edge
    init = sorted(int(round(b.t_s[0] * fs)) for b in tv.blocks[1:])
    cps = [c for c in init if lo_i < c < hi_i]
    step = max(1, int(round(step_s * fs)))
    reach = int(round(search_s * fs))
    gap = int(round(min_segment_s * fs))
    end_gap = int(round(guard_s * fs)) + 1  # the first and last levels may be cut short
    cps = _merge_close(cps, lo_i, hi_i, gap, end_gap)
    for _ in range(passes):
        cps = _refine(sums, cps, lo_i, hi_i, step, reach, gap, end_gap)
        cps = _merge_close(cps, lo_i, hi_i, gap, end_gap)
    cps, null_scale = _prune(sums, cps, lo_i, hi_i, step, reach, gap, end_gap, alpha)
    bounds = [lo_i] + cps + [hi_i]
    guard = int(round(guard_s * fs))
    vals = {p: [] for p in PARAMS}
    ci = {p: [] for p in PARAMS}
    ci_window = {p: [] for p in PARAMS}
    ci_batch = {p: [] for p in PARAMS}
    sub = max(3, int(round(window_s * fs)))
    for j, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        ga = a + (guard if j else 0)
        gb = b - (guard if j + 1 < len(bounds) - 1 else 0)
        if gb - ga < gap // 2:
            ga, gb = a, b
        c = sums.coef(ga, gb)
        hb = _batch_half_widths(sums, ga, gb, sub)
        for k, p in enumerate(PARAMS):
            vals[p].append(float(c[k]))
            hw = float(1.96 * tv.sigma[p] * np.sqrt(window_s * fs / (gb - ga)))
            ci_window[p].append(hw)
            ci_batch[p].append(float(hb[k]))
            ci[p].append(float(hb[k]) if np.isfinite(hb[k]) else hw)
    warnings = [f"segment {a / fs:.2f}-{b / fs:.2f} s is shorter than {min_segment_s:g} s "
                f"(cut by the record's usable span): its K, B, I are uncertain"
                for a, b in zip(bounds[:-1], bounds[1:]) if b - a < gap]
    return SegmentTrack(edges_s=np.array(bounds) / fs,
                        values={p: np.array(v) for p, v in vals.items()},
                        ci={p: np.array(v) for p, v in ci.items()},
                        change_s=np.array(cps, dtype=float) / fs,
                        initial_change_s=np.array(init, dtype=float) / fs,
                        window_s=window_s, sign=sgn, warnings=warnings,
                        ci_window={p: np.array(v) for p, v in ci_window.items()},
                        ci_batch={p: np.array(v) for p, v in ci_batch.items()})


def _batch_half_widths(sums, a, b, sub, level=0.95) -> np.ndarray:
    """(3,) batch-means 95 % half-widths of the K, B, I fit on [a, b): the span cut into
    m contiguous sub-blocks of about ``sub`` samples, each fitted alone; half-width
    ``t_{m-1} sd / sqrt(m)`` of their spread (the residual spread the data show, whatever
    the noise's colour). NaN where fewer than 3 sub-blocks fit."""
    from scipy import stats
    m = (b - a) // sub
    if m < 3:
        return np.full(3, np.nan)
    cuts = np.linspace(a, b, m + 1).round().astype(int)
    est = np.array([sums.coef(x, y) for x, y in zip(cuts[:-1], cuts[1:])])
    sd = est.std(axis=0, ddof=1)
    return stats.t.ppf(0.5 + level / 2, m - 1) * sd / np.sqrt(m)


def _sign_of(tv, theta, tau, fs, band_hz) -> float:
    """The torque sign that makes the whole record's K positive (as track does)."""
    X, y = _design(theta, tau, fs, band_hz)
    k = np.linalg.lstsq(X, y, rcond=None)[0][0]
    return -1.0 if k < 0 else 1.0


def _merge_close(cps, lo, hi, gap, end_gap) -> list:
    """Sorted change points, each at least ``gap`` samples from its neighbours and
    ``end_gap`` from the ends (the later of two close ones dropped)."""
    out = []
    for c in sorted(cps):
        if (c - out[-1] >= gap if out else c - lo >= end_gap) and hi - c >= end_gap:
            out.append(int(c))
    return out


def _refine(sums, cps, lo, hi, step, reach, gap, end_gap) -> list:
    """One sweep: each change point moved to the split of least summed squared error of
    the fits either side (grid ``step``, within ``reach``, its neighbours fixed)."""
    cps = list(cps)
    for i in range(len(cps)):
        left = cps[i - 1] + gap if i else lo + end_gap
        right = cps[i + 1] - gap if i + 1 < len(cps) else hi - end_gap
        a = cps[i - 1] if i else lo
        b = cps[i + 1] if i + 1 < len(cps) else hi
        cand = np.arange(max(left, cps[i] - reach), min(right, cps[i] + reach) + 1, step)
        if cand.size == 0:
            continue
        cost = sums.rss(np.full(cand.size, a), cand) + sums.rss(cand, np.full(cand.size, b))
        cps[i] = int(cand[int(np.argmin(cost))])
    return cps


def _gain(sums, a, c, b):
    """Drop of the squared error when [a, b) is split at c (arrays)."""
    return sums.rss(a, b) - sums.rss(a, c) - sums.rss(c, b)


def _total(sums, cps, lo, hi) -> float:
    bounds = np.array([lo] + list(cps) + [hi])
    return float(np.sum(sums.rss(bounds[:-1], bounds[1:])))


def _prune(sums, cps, lo, hi, step, reach, gap, end_gap, alpha):
    """Remove, one at a time, the change point whose removal (its neighbours refined
    again) raises the squared error least, while that rise is below the level a split of
    a segment *without* a change reaches. The null scale is the median gain of splitting
    every segment at its middle (mostly no change there: chi^2_3 times the noise's scale,
    median 2.37 times); the threshold is chi^2_3's quantile at ``alpha`` over the change
    points, doubled for the refinement's search over positions. Two change points either
    side of one switch (a window astride it seen as an intermediate level) become one
    here. Returns (change points, null scale)."""
    from scipy import stats
    cps = list(cps)
    scale = None
    while cps:
        bounds = np.array([lo] + cps + [hi])
        a, b = bounds[:-1], bounds[1:]
        scale = max(float(np.median(_gain(sums, a, (a + b) // 2, b))) / stats.chi2.median(3),
                    1e-300)
        here = _total(sums, cps, lo, hi)
        best = (np.inf, None)
        for k in range(len(cps)):
            trial = _refine(sums, cps[:k] + cps[k + 1:], lo, hi, step, reach, gap, end_gap)
            rise = (_total(sums, trial, lo, hi) - here) / scale
            if rise < best[0]:
                best = (rise, trial)
        if best[0] >= 2 * stats.chi2.isf(alpha / len(cps), 3):
            break
        cps = best[1]
    return cps, scale
