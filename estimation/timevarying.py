"""The one time-variation test of the project: does the limb's impedance change within a
recording, when, and how.

``armimp estimate`` (estimation.lab) and ``armimp diagnose`` (its "when" stage) both call
:func:`time_variation`, so the two commands cannot contradict each other.

Method (docs/estimation.md, "Time variation"):

1. **Track.** Theta and tau_h are band-passed by the same zero-phase Butterworth filter
   (a linear filter applied to both sides keeps ``tau = I theta'' + B theta' + K theta``
   true, and removes the slow voluntary torque and slow movements); in windows of
   ``window_s`` (1 s) the limb model is fitted by least squares on the filtered angle and
   its derivatives (the 9-point central difference of estimation.reflex.derivative): one
   (K, B, I) per window.
2. **Noise.** The sampling noise of a window's estimate, sigma, from the data: the
   noise is not white (coloured sensor noise, the subject's slow voluntary torque leaking
   into the band), and the spread of a window's estimate depends on its serial
   correlation, so the other windows' residuals (1 s samples of the recording's own
   noise, correlation intact) are passed through each window's least-squares estimator,
   a residual block bootstrap (Kuensch 1989); sigma = the per-window MAD scale of those
   errors (Rousseeuw & Croux 1993; robust to the residuals of windows astride a switch),
   pooled as a root mean square (:func:`window_sigma`). An earlier even/odd 0.1 s
   sub-block split missed the noise correlated over more than 0.1 s and understated
   sigma up to 4.5-fold with voluntary torque (docs/estimation.md).
3. **Change points.** Seeded binary segmentation (Kovacs, Li, Buehlmann & Munk, Biometrika
   110:249, 2023): CUSUM statistics ``C = sqrt(n_l n_r / n) (mean_l - mean_r) / sigma``
   on a deterministic set of intervals at every scale, split where the narrowest interval
   whose largest |C| passes the threshold has it, repeated. The threshold is Bonferroni's
   over every (parameter, interval, split) tested, so the chance of any false change in a
   stationary recording is at most ``alpha``.
4. **Blocks.** The change points cut the record into blocks that follow the data; each
   block's K, B, I is the mean of its windows with a 95 % interval ``1.96 sigma /
   sqrt(m)``. A change smaller than ``min_change`` of the mean is not reported.
5. **Shape.** Constant, linear, saturating (exponential), sinusoidal and piecewise-constant
   (the blocks) models of the track compared by BIC (Schwarz 1978) on ``sigma``: "linear
   drift", "saturating drift", "modulated", "step" (one change) or "switching".
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal as sps
from scipy import stats

from .reflex import derivative

PARAMS = ("K", "B", "I")
UNITS = {"K": "N m/rad", "B": "N m s/rad", "I": "kg m^2"}
#: default family-wise false-alarm rate of the test, window [s], band [Hz]
ALPHA, WINDOW_S, BAND_HZ = 1e-3, 1.0, (3.0, 30.0)
#: shortest seeded interval [windows]; changes below this fraction of the mean are not
#: reported (a true change this small matters to no lab, and slowly correlated window
#: noise can reach it)
MIN_INTERVAL, MIN_CHANGE, MIN_BLOCK = 4, 0.10, 2
#: left out at each end of the record [s]: the band-pass filter's edge transients
EDGE_S = 2.0
#: two windows whose band-passed angles correlate more than this are not used as each
#: other's noise samples (a periodic perturbation's repeats)
MAX_ALIKE = 0.3
#: residuals of at most this many windows are passed through each window's estimator
MAX_PARTNERS = 100
#: the seeded intervals' decay from one scale to the next (Kovacs et al. 2023: in [1/2, 1))
DECAY = 0.5 ** 0.5
#: windows whose band-passed angle power is below this fraction of the median are left
#: out (a PRBS resting at one level, a rest period: nothing to estimate from)
MIN_EXCITATION = 0.1


@dataclass
class Block:
    """One block of constant impedance: ``t_s`` [start, end] s; ``values`` {K, B, I};
    ``ci`` {K, B, I} half-widths (95 %), SI units."""
    t_s: tuple
    values: dict
    ci: dict

    def to_json(self) -> dict:
        return {"t_s": [round(float(x), 4) for x in self.t_s],
                **{p: [float(self.values[p]), float(self.values[p] - self.ci[p]),
                       float(self.values[p] + self.ci[p])] for p in PARAMS}}


@dataclass
class TimeVariation:
    """The result of :func:`time_variation` for one joint of one recording.

    ``time_varying``: a change found; ``parameter``: the parameter with the strongest
    evidence (K, B or I) and ``p_value`` its Bonferroni-adjusted p; ``blocks`` the
    partition (one block when nothing changed); ``shape`` one of ``"constant"``,
    ``"step"``, ``"switching"``, ``"linear drift"``, ``"saturating drift"``,
    ``"modulated"``; ``track`` the windows' ``t`` (centres, s) and K, B, I arrays;
    ``sigma`` the windows' noise per parameter; ``n_tests`` the Bonferroni count.
    """
    time_varying: bool
    parameter: str
    p_value: float
    blocks: list
    shape: str
    track: dict
    sigma: dict
    n_tests: int
    alpha: float
    changed: list = field(default_factory=list)
    name: str = ""

    def message(self, joint: str = "") -> str:
        """``time-varying: K 57.3 -> 46.2 N m/rad in 4 blocks (linear drift), p < 1e-16
        (blocks 0-15 s: 57.3+-0.4, ...)``; "" when nothing changed."""
        if not self.time_varying:
            return ""
        p = self.parameter
        b = self.blocks
        parts = ", ".join(f"{x.t_s[0]:.1f}-{x.t_s[1]:.1f} s: {x.values[p]:.4g}+-"
                          f"{x.ci[p]:.2g}" for x in b[:8]) + (" ..." if len(b) > 8 else "")
        also = [q for q in self.changed if q != p]
        return (f"time-varying: {p}{joint} {b[0].values[p]:.4g} -> {b[-1].values[p]:.4g} "
                f"{UNITS[p]} in {len(b)} blocks ({self.shape}), {format_p(self.p_value)} "
                f"(blocks {parts}" + (f"; {', '.join(also)} changed too" if also else "")
                + "): the single value is an average over a changing impedance, not one "
                "joint state")

    def to_json(self) -> dict:
        return {"time_varying": self.time_varying, "parameter": self.parameter,
                "p_value": float(self.p_value), "shape": self.shape, "alpha": self.alpha,
                "n_tests": self.n_tests, "changed": list(self.changed),
                "sigma": {p: float(v) for p, v in self.sigma.items()},
                "blocks": [b.to_json() for b in self.blocks],
                "track": {k: [round(float(x), 6) for x in v] for k, v in self.track.items()}}


def format_p(p: float) -> str:
    return "p < 1e-16" if p < 1e-16 else f"p = {p:.2g}"


# ----------------------------------------------------------------------------- the track


def track(theta, tau, fs, *, window_s=WINDOW_S, band_hz=BAND_HZ, sign=1) -> dict:
    """K, B, I per window of one joint.

    Parameters
    ----------
    theta, tau : (N,) arrays, rad and N m (the joint's angle and the subject's torque)
    fs : sampling rate [Hz]
    window_s : window length [s]
    band_hz : (lo, hi) of the band-pass applied to both [Hz] (hi capped at 0.4 fs)
    sign : +1 / -1 multiplies the torque (default +1: the torque as given, i.e. with the
        sign the trial's metadata or --torque-sign declared already applied by the reader,
        so the blocks' K has the sign of the command's estimate); None: the sign that
        makes the whole record's K positive (a caller's explicit choice only: it would
        print a positive K beside a negative estimate of the same torque)

    Returns ``{"t": (W,) window centres [s], "K", "B", "I": (W,), "window_s", "sign"}``.

    Raises ValueError for fewer than 2 * MIN_INTERVAL windows or non-finite data.
    """
    theta = np.asarray(theta, float).ravel()
    tau = np.asarray(tau, float).ravel()
    if theta.shape != tau.shape:
        raise ValueError(f"theta ({theta.size} samples) and tau_h ({tau.size}) differ in "
                         f"length")
    if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(tau))):
        raise ValueError("theta or tau_h holds NaN/inf: the time-variation track needs "
                         "finite samples")
    L = int(round(window_s * fs))
    # the filter's edge transients (about 3 / lo seconds) are left out of the windows
    edge = int(np.ceil(min(EDGE_S, 0.1 * theta.size / fs) * fs))
    W = (theta.size - 2 * edge) // L if L > 0 else 0
    if W < 2 * MIN_INTERVAL:
        raise ValueError(f"the recording ({theta.size / fs:.3g} s) is too short for the "
                         f"time-variation test: it needs {2 * MIN_INTERVAL} windows of "
                         f"{window_s:g} s")
    lo, hi = band_hz[0], min(band_hz[1], 0.4 * fs)
    sos = sps.butter(4, [lo, hi], btype="bandpass", fs=fs, output="sos")
    x = sps.sosfiltfilt(sos, theta)
    y = sps.sosfiltfilt(sos, tau)
    dx = derivative(x, fs)
    ddx = derivative(dx, fs)
    X = np.stack([x, dx, ddx], axis=1)[edge:edge + W * L].reshape(W, L, 3)
    Y = y[edge:edge + W * L].reshape(W, L)
    scale = np.sqrt(np.mean(X ** 2, axis=(0, 1))) + 1e-300  # conditioning only
    Xs = X / scale
    XtX = np.einsum("wli,wlj->wij", Xs, Xs)
    XtY = np.einsum("wli,wl->wi", Xs, Y)
    coef_s = np.linalg.solve(XtX, XtY[..., None])[..., 0]
    coef = coef_s / scale
    if sign is None:
        whole = np.linalg.lstsq(X.reshape(-1, 3), Y.ravel(), rcond=None)[0]
        sign = -1.0 if whole[0] < 0 else 1.0
    coef *= sign
    t = (edge + (np.arange(W) + 0.5) * L) / fs
    power = np.mean(X[:, :, 0] ** 2, axis=1)
    keep = power >= MIN_EXCITATION * np.median(power)
    residual = Y - np.einsum("wli,wi->wl", Xs, coef_s)
    errors = sign * _residual_swap_errors(Xs[keep], XtX[keep], residual[keep]) / scale
    return {"t": t[keep], "t0": edge / fs, "n_dropped": int(np.count_nonzero(~keep)),
            "K": coef[keep, 0], "B": coef[keep, 1], "I": coef[keep, 2],
            "errors": errors, "window_s": L / fs, "sign": float(sign)}


def _residual_swap_errors(Xs, XtX, E, max_alike=MAX_ALIKE):
    """The errors the recording's own noise makes in each window's estimate.

    Window w's least-squares error is ``(X_w' X_w)^-1 X_w' e_w``; its spread depends on the
    noise's serial correlation, not only on its power (sensor noise that is coloured, the
    slow voluntary torque leaking into the band: both correlated over tenths of a second).
    The other windows' residuals are 1 s samples of that noise with their correlation
    intact, so each is passed through window w's estimator (a residual block bootstrap
    with the windows as blocks; Kuensch 1989, Politis & Romano 1994):
    ``D[w, v] = (X_w' X_w)^-1 X_w' e_v``, v over at most ``MAX_PARTNERS`` windows spread
    over the record.

    Parameters: ``Xs`` (W, L, 3) scaled regressors, ``XtX`` (W, 3, 3), ``E`` (W, L) the
    windows' own residuals (torque units). Returns D (W, V, 3) in the scaled units, NaN
    where v = w (a residual is orthogonal to its own window's regressors) or where the two
    windows' angles are alike (|correlation| > ``max_alike``: a periodic perturbation's
    repeats, whose residuals are orthogonal to this window's regressors too).
    """
    W = len(Xs)
    v = np.unique(np.linspace(0, W - 1, min(W, MAX_PARTNERS)).round().astype(int))
    G = np.stack([Xs[:, :, i] @ E[v].T for i in range(3)], axis=-1)  # (W, V, 3)
    D = np.linalg.solve(XtX[:, None], G[..., None])[..., 0]
    a = Xs[:, :, 0] / (np.linalg.norm(Xs[:, :, 0], axis=1, keepdims=True) + 1e-300)
    alike = (np.abs(a @ a[v].T) > max_alike) | (np.arange(W)[:, None] == v[None, :])
    D[alike] = np.nan
    return D


def window_sigma(v, errors=None) -> float:
    """Sampling noise of one window's estimate [the parameter's unit].

    With ``errors`` (W, V) (:func:`_residual_swap_errors` for one parameter): per window,
    the MAD scale (Rousseeuw & Croux 1993) of the errors the other windows' residuals
    make in it (robust to the few residuals of windows astride a switch, which hold the
    change itself), pooled over the windows as a root mean square (the variance of a
    block's mean of windows). Without them (or when fewer than MIN_INTERVAL partners are
    left to a window: a perturbation repeating every window), from the track's first
    differences (scale / sqrt 2).
    """
    if errors is not None:
        e = np.asarray(errors, float)
        e = e[np.count_nonzero(np.isfinite(e), axis=1) >= MIN_INTERVAL]
        if e.size:
            med = np.nanmedian(e, axis=1, keepdims=True)
            per_window = 1.4826 * np.nanmedian(np.abs(e - med), axis=1)
            return float(np.sqrt(np.mean(per_window ** 2)))
    d = np.diff(np.asarray(v, float))
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2))


# ----------------------------------------------------------------------------- change points


def seeded_intervals(n, min_len=MIN_INTERVAL, decay=DECAY) -> list:
    """Seeded intervals [s, e) of 0..n (Kovacs et al. 2023, definition 1): at scale k,
    intervals of length n decay^(k-1), shifted by half their length, down to min_len."""
    out = {(0, n)}
    length = n * decay
    while length >= min_len:
        m = int(np.ceil(2 * n / length)) - 1
        shift = (n - length) / max(m - 1, 1)
        for i in range(m):
            s = int(np.floor(i * shift))
            out.add((s, min(n, int(np.ceil(s + length)))))
        length *= decay
    return sorted(out, key=lambda se: (se[1] - se[0], se[0]))


def cusum(x, s, e):
    """|CUSUM| statistics of x[s:e] at every split b in s+1..e-1 (x standardised: each
    N(0, 1) under no change): ``sqrt(n_l n_r / n) |mean_l - mean_r|``."""
    seg = x[s:e]
    n = seg.size
    c = np.cumsum(seg)[:-1]
    nl = np.arange(1, n)
    nr = n - nl
    ml, mr = c / nl, (seg.sum() - c) / nr
    out = np.sqrt(nl * nr / n) * np.abs(ml - mr)
    # no block shorter than MIN_BLOCK windows (a window astride a switch is not a state)
    out[:MIN_BLOCK - 1] = 0.0
    out[len(out) - MIN_BLOCK + 1:] = 0.0
    return out


def change_points(x, threshold, intervals) -> list:
    """Seeded binary segmentation, narrowest-over-threshold selection: split at the
    arg-max of the narrowest interval whose largest statistic exceeds ``threshold``,
    drop the intervals that hold the split, repeat. Returns sorted split indices (a block
    starts there)."""
    stats_ = []
    for s, e in intervals:
        c = cusum(x, s, e)
        j = int(np.argmax(c))
        stats_.append((s, e, float(c[j]), s + 1 + j))
    found = []
    live = [q for q in stats_ if q[2] > threshold]
    while live:
        s, e, _, b = min(live, key=lambda q: (q[1] - q[0], -q[2]))
        found.append(b)
        live = [q for q in live if not (q[0] < b < q[1])]
    return sorted(found)


# ----------------------------------------------------------------------------- the test


def time_variation(theta, tau, fs, *, window_s=WINDOW_S, band_hz=BAND_HZ, alpha=ALPHA,
                   min_change=MIN_CHANGE, sign=1, name="") -> TimeVariation:
    """Test one joint's recording for a changing K, B or I (module docstring).

    Parameters as :func:`track`; ``alpha`` the family-wise false-alarm rate (Bonferroni
    over parameters, intervals and splits); ``min_change`` the smallest relative change
    between adjacent blocks reported.

    Raises ValueError (from :func:`track`) for too short or non-finite data.
    """
    tr = track(theta, tau, fs, window_s=window_s, band_hz=band_hz, sign=sign)
    n = tr["t"].size
    intervals = seeded_intervals(n)
    n_tests = len(PARAMS) * sum(max(e - s - 2 * MIN_BLOCK + 1, 0) for s, e in intervals)
    threshold = float(stats.norm.isf(alpha / (2 * n_tests)))
    sigma, cuts, best = {}, {}, {}
    for p in PARAMS:
        v = tr[p]
        sigma[p] = max(window_sigma(v, tr["errors"][:, :, PARAMS.index(p)]),
                       1e-12 * max(np.abs(v).max(), 1e-300))
        z = (v - v.mean()) / sigma[p]
        cp = change_points(z, threshold, intervals)
        cp = _merge_small(v, cp, min_change)
        cuts[p] = cp
        full = cusum(z, 0, n)
        local = max((float(cusum(z, s, e).max()) for s, e in intervals), default=0.0)
        best[p] = max(local, float(full.max()))
    changed = [p for p in PARAMS if cuts[p]]
    p_of = {p: min(1.0, n_tests * 2 * float(stats.norm.sf(best[p]))) for p in PARAMS}
    lead = min(changed, key=lambda p: p_of[p]) if changed else "K"
    bounds = [0] + cuts[lead] + [n]
    L, t0 = tr["window_s"], tr["t0"]
    blocks = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        m = b - a
        blocks.append(Block(t_s=(float(tr["t"][a] - L / 2), float(tr["t"][b - 1] + L / 2)),
                            values={p: float(np.mean(tr[p][a:b])) for p in PARAMS},
                            ci={p: float(1.96 * sigma[p] / np.sqrt(m)) for p in PARAMS}))
    shape = classify(tr["t"], tr[lead], sigma[lead], cuts[lead]) if changed else "constant"
    return TimeVariation(time_varying=bool(changed), parameter=lead,
                         p_value=p_of[lead], blocks=blocks, shape=shape,
                         track={k: tr[k] for k in ("t",) + PARAMS}, sigma=sigma,
                         n_tests=n_tests, alpha=alpha, changed=changed, name=name)


def _merge_small(v, cp, min_change) -> list:
    """No change points when the blocks' means span less than ``min_change`` of the mean
    level (a change no lab would act on; slowly correlated noise can reach it)."""
    if not cp:
        return []
    level = max(abs(float(np.mean(v))), 1e-300)
    bounds = [0] + list(cp) + [v.size]
    means = [np.mean(v[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]
    return list(cp) if (max(means) - min(means)) / level >= min_change else []


# ----------------------------------------------------------------------------- shape


def _bic(rss, k, n, sigma):
    return rss / sigma ** 2 + k * np.log(n)


def classify(t, v, sigma, cuts) -> str:
    """The shape of the change: the BIC-best of linear, saturating exponential, sinusoid
    and the piecewise-constant blocks (module docstring)."""
    n = v.size
    ones = np.ones(n)
    cands = {}
    A = np.stack([ones, t], 1)
    cands["linear drift"] = (_rss(A, v), 2)
    T = t[-1] - t[0]
    best = np.inf
    for tau_s in np.geomspace(T / 60, T, 30):  # rises and falls that settle
        A = np.stack([ones, 1 - np.exp(-(t - t[0]) / tau_s)], 1)
        best = min(best, _rss(A, v))
    cands["saturating drift"] = (best, 3)
    best = np.inf
    for period in np.geomspace(2.0, T, 60):
        w = 2 * np.pi / period
        A = np.stack([ones, np.sin(w * t), np.cos(w * t)], 1)
        best = min(best, _rss(A, v))
    cands["modulated"] = (best, 4)
    bounds = [0] + list(cuts) + [n]
    rss = sum(float(np.sum((v[a:b] - v[a:b].mean()) ** 2))
              for a, b in zip(bounds[:-1], bounds[1:]))
    cands["blocks"] = (rss, 2 * len(bounds) - 3 + 1)
    shape = min(cands, key=lambda k: _bic(cands[k][0], cands[k][1], n, sigma))
    if shape != "blocks":
        return shape
    means = [v[a:b].mean() for a, b in zip(bounds[:-1], bounds[1:])]
    signs = np.sign(np.diff(means))
    if len(means) == 2:
        return "step"
    return "switching" if np.any(signs[1:] != signs[:-1]) else "steps"


def _rss(A, v) -> float:
    c, *_ = np.linalg.lstsq(A, v, rcond=None)
    return float(np.sum((v - A @ c) ** 2))


# ----------------------------------------------------------------------------- trials


def of_trial(trial, *, joint=None, **kw) -> list:
    """:func:`time_variation` of every joint of a ``trialformat.Trial`` (the perturbed
    one only when ``joint`` is given): a list of TimeVariation (name ``trial[j]``).
    Uses ``trial.theta`` and ``trial.tau_h``; raises ValueError when they are missing."""
    if trial.theta is None or trial.tau_h is None:
        raise ValueError(f"{trial.name}: the time-variation test needs theta and tau_h")
    joints = range(trial.n_dof) if joint is None else [joint]
    out = []
    for j in joints:
        out.append(time_variation(trial.theta[:, j], trial.tau_h[:, j], trial.fs,
                                  name=f"{trial.name}[{j + 1}]" if trial.n_dof > 1
                                  else trial.name, **kw))
    return out


def of_trials(trials, **kw) -> tuple[list, list]:
    """The test on every trial (every joint) of a set: ``(results as JSON dicts, warning
    lines)``. A trial the test cannot use (too short, NaN) gives a note, not an error."""
    found, lines = [], []
    for trial in trials:
        try:
            results = of_trial(trial, **kw)
        except ValueError as exc:
            lines.append(f"time-variation check not done for {trial.name}: {exc}")
            continue
        for j, r in enumerate(results):
            found.append({"trial": trial.name, "joint": j + 1, **r.to_json()})
            if r.time_varying:
                joint = f"_{j + 1}{j + 1}" if trial.n_dof > 1 else ""
                text = r.message(joint)
                if len(trials) > 1:
                    text = text.replace("time-varying: ", f"time-varying: {trial.name}: ", 1)
                lines.append(text)
    return found, lines
