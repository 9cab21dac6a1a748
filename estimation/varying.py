"""Parameter-varying impedance of one joint: K, B, I (and the reflex gain) as functions of
a scheduling variable.

A joint perturbed while it moves slowly (or while its background torque or its state
changes with time) has an impedance that depends on a *scheduling variable* ``rho``
(trialformat.scheduling): the ankle angle, the background torque, time. Around the slowly
varying operating point the perturbation's torque obeys

    dtau(t) = K(rho) dtheta(t) + B(rho) dtheta'(t) + I(rho) dtheta''(t)
              [+ G(rho) x(t - d)],   x = LP[N(theta')]  (estimation/reflex.py),

with ``dtheta``, ``dtau`` the parts of angle and torque above the slow part of the
movement. Each of K, B, I, G is a Chebyshev expansion ``sum_k a_k T_k(u)`` in ``u``, the
scheduling variable mapped onto [-1, 1] over the range the recording visited. The torque
is then *linear* in the coefficients ``a`` (for fixed reflex dynamics d, f_c, zeta): one
time-domain least squares (the linear-parameter-varying regression of Bamieh & Giarre
2002; the expansion of K, B, I in a basis of the scheduling variable as in Sobhani
Tehrani & Kearney, IEEE TBME 2022, whose NPPV-PC model expands impulse responses in
Tchebychev polynomials of the angle).

Steps (:func:`fit_varying`):

1. **Signals.** Angle and torque are low-passed at ``f_hi`` (zero-phase Butterworth,
   order 4: the top of the perturbation band, and the anti-alias of the decimation); the
   velocity and acceleration are least-squares FIR differentiators (Savitzky-Golay, order
   4) of the low-passed angle *at the recording rate*, the window the longest whose gain
   is within 2e-5 of ``j w`` and ``-w^2`` at ``f_hi``. All are then high-passed at
   ``f_lo`` (zero phase, order HP_ORDER = 2: above it the perturbation, below it the
   movement and its quasi-static torque) and decimated to about ``work_fs``.
2. **Reflex** (``reflex`` given): the rectified velocity (before the high-pass: the reflex
   sees the whole movement), high-passed like the torque, through the unit-gain 2nd-order
   low-pass, delayed: a grid over (d, f_c, zeta) and each rectification with a constant
   gain (the column projected out of the intrinsic regressors), then a bounded
   Nelder-Mead refinement; the dynamics are then fixed and the gain expanded in ``rho``.
3. **Order.** Chebyshev orders 0 (time-invariant) to ``max_order`` are compared by their
   held-out error over blocks of ``block_s`` seconds *stratified by rho*: the blocks
   sorted by their mean rho are dealt round-robin into ``folds`` folds, so every fold's
   training blocks span the states of the held-out ones; a held-out block is scored only
   when its rho lies inside its training blocks' range (a state-varying model is judged
   inside the states it was calibrated on; for ``rho = time`` the folds are interleaved
   blocks of time). The order chosen is the smallest whose held-out error is within one
   standard error (paired, over the held-out blocks) of the best order's (the one-
   standard-error rule, Hastie, Tibshirani & Friedman 2009, 7.10).
4. **Intervals.** Delete-one-group jackknife: the blocks dealt round-robin into
   ``jackknife`` groups, each group left out in turn; the half-width of each of K, B, I,
   G at each point is ``t_{0.975, m-1} sqrt((m-1)/m sum (p_j - p_mean)^2)`` (Efron &
   Tibshirani 1993, ch. 11). Blocks keep the serial correlation of the residual inside
   them. The reflex dynamics (d, f_c, zeta) are held at their full-data values: the
   intervals are conditional on them.
5. **Held-out VAF** [%] of the torque (step 3's folds) of the chosen order and of order
   0, the time-invariant model fitted the same way: the gain the variation brings.

The sums of squares of every block are formed once (per-block Gram matrices), so orders,
folds and jackknife cost a small solve each. All of it is for one joint.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import EstimationError

PARAMS = ("K", "B", "I")
UNITS = {"K": "N m/rad", "B": "N m s/rad", "I": "kg m^2", "G": "N m s/rad"}
#: order of the Butterworth high-pass at f_lo (run forward and backward). Order 2 lets
#: 5.6e-4 of a 0.077 Hz movement through, which the stiffness multiplies into a bias (0.45
#: N m/rad on the known answer of the tests, under 1 % of K); order 4 rang longer than
#: the 1 s left out at the ends and was worse (errors of 30 N m/rad): kept at 2
HP_ORDER = 2
NAMES = {"K": "stiffness", "B": "damping", "I": "inertia", "G": "reflex gain"}


class VaryingError(EstimationError):
    """The parameter-varying fit cannot be made (too short, too narrow, bad input); the
    message names the scheduling variable and what would work."""


@dataclass
class VaryingOptions:
    """Settings of :func:`fit_varying` (module docstring).

    max_order : highest Chebyshev order tried (0 = time-invariant); ``max_order_time``
        when the scheduling variable is time
    f_lo, f_hi : high-pass and low-pass corners [Hz] of the perturbation band fitted
    work_fs : working rate [Hz] after decimation (the recording's rate divided by an
        integer)
    block_s : length [s] of the blocks of the held-out test and the jackknife
    folds : folds of the held-out test (blocks stratified by rho)
    jackknife : groups of the jackknife (blocks dealt round-robin)
    skip_s : seconds left out at each end (filter transients)
    n_points : points of rho reported, evenly over its 1-99 % range
    confidence : level of the intervals
    """

    max_order: int = 6
    max_order_time: int = 12
    f_lo: float = 1.0
    f_hi: float = 40.0
    work_fs: float = 250.0
    block_s: float = 2.0
    folds: int = 5
    jackknife: int = 20
    skip_s: float = 1.0
    n_points: int = 15
    confidence: float = 0.95

    def check(self) -> None:
        if not 0 < self.f_lo < self.f_hi:
            raise VaryingError(f"parameter-varying fit: band {self.f_lo:g}-{self.f_hi:g} Hz "
                               f"must have 0 < f_lo < f_hi")
        if self.max_order < 0 or self.max_order_time < 0:
            raise VaryingError("parameter-varying fit: max_order must be >= 0")
        if self.folds < 2 or self.jackknife < 3:
            raise VaryingError("parameter-varying fit: folds >= 2 and jackknife >= 3 needed")
        if not 0 < self.confidence < 1:
            raise VaryingError(f"confidence must be in (0, 1), got {self.confidence}")


@dataclass
class VaryingResult:
    """K, B, I (G) over the scheduling variable, with intervals.

    ``rho`` (P,) the points [``units``]; ``values[p]`` (P,) and ``lo[p]``, ``hi[p]`` (P,)
    the estimate and its interval for p in K, B, I (and G with a reflex), units in UNITS;
    ``invariant`` the order-0 fit ``{p: (value, lo, hi)}``; ``heldout_vaf_pct``
    ``{"varying", "invariant"}`` [%]; ``orders`` the held-out VAF of every order tried.
    """

    scheduling: str
    units: str
    source: str
    rho: np.ndarray
    values: dict
    lo: dict
    hi: dict
    order: int
    invariant: dict
    heldout_vaf_pct: dict
    vaf_pct: dict
    orders: list
    calibration_range: tuple
    band_hz: tuple
    work_fs: float
    n_blocks: int
    n_groups: int
    confidence: float
    reflex: dict | None = None
    coefficients: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    elapsed_s: float = 0.0
    trial: str = ""

    @property
    def params(self) -> tuple:
        return PARAMS + (("G",) if self.reflex is not None else ())

    def at(self, rho) -> dict:
        """``{p: values}`` of the fitted expansions at ``rho`` (array, [units]); outside
        the calibration range the expansion is clipped at its ends."""
        u = _unit(np.asarray(rho, dtype=float), *self.calibration_range)
        T = _cheb(u, self.order)
        return {p: T @ self.coefficients[p] for p in self.params}

    def to_json(self) -> dict:
        pts = []
        for i, r in enumerate(self.rho):
            pt = {"rho": float(r)}
            for p in self.params:
                pt[p] = [float(self.values[p][i]), float(self.lo[p][i]),
                         float(self.hi[p][i])]
            pts.append(pt)
        return {"scheduling": self.scheduling, "units": self.units, "points": pts,
                "source": self.source, "basis": "Chebyshev", "order": self.order,
                "calibration_range": list(self.calibration_range),
                "time_invariant": {p: list(v) for p, v in self.invariant.items()},
                "heldout_vaf_pct": self.heldout_vaf_pct, "vaf_pct": self.vaf_pct,
                "orders": self.orders, "band_hz": list(self.band_hz),
                "work_fs_hz": self.work_fs, "confidence": self.confidence,
                "interval_method": f"delete-one-group jackknife, {self.n_groups} groups of "
                                   f"interleaved blocks",
                "heldout_method": "blocks stratified by the scheduling variable, scored "
                                  "inside their training range",
                "n_blocks": self.n_blocks, "parameter_units": {p: UNITS[p]
                                                               for p in self.params},
                "reflex": self.reflex, "warnings": self.warnings,
                "elapsed_s": self.elapsed_s}

    def describe(self, label="") -> str:
        """Printed lines: a table of K, B, I (G) over rho with intervals, the VAFs."""
        conf = int(round(100 * self.confidence))
        u = f" [{self.units}]" if self.units else ""
        h = self.heldout_vaf_pct
        lines = [f"  parameter-varying{(' ' + label) if label else ''}: over "
                 f"{self.scheduling}{u}, Chebyshev order {self.order} (held-out VAF "
                 f"{h['varying']:.2f} % vs time-invariant {h['invariant']:.2f} %; "
                 f"{conf} % jackknife intervals, {self.n_groups} groups)"]
        head = f"    {'rho':>9}  " + "  ".join(f"{p + ' [' + UNITS[p] + ']':>24}"
                                              for p in self.params)
        lines.append(head)
        for i, r in enumerate(self.rho):
            lines.append(f"    {r:9.4g}  " + "  ".join(
                f"{_ci_text(self.values[p][i], self.lo[p][i], self.hi[p][i]):>24}"
                for p in self.params))
        inv = self.invariant
        lines.append("    time-invariant: " + "  ".join(
            f"{p}={_ci_text(*inv[p])}" for p in self.params))
        if self.reflex is not None:
            rf = self.reflex
            lines.append(f"    reflex dynamics (fixed): delay {rf['delay_ms']:.1f} ms, "
                         f"low-pass {rf['cutoff_hz']:.3g} Hz, damping {rf['damping']:.3g}, "
                         f"rectify {rf['rectify']}; VAF intrinsic "
                         f"{self.vaf_pct['intrinsic']:.1f} %, reflex "
                         f"{self.vaf_pct['reflex']:.1f} %, total "
                         f"{self.vaf_pct['total']:.1f} %")
        lines += [f"    warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def _ci_text(v, lo, hi) -> str:
    return f"{v:.4g} [{lo:.4g}, {hi:.4g}]"


# ----------------------------------------------------------------------------- basis


def _unit(rho, lo, hi):
    """rho mapped onto [-1, 1] over [lo, hi] (clipped)."""
    return np.clip(2 * (rho - lo) / (hi - lo) - 1, -1.0, 1.0)


def _cheb(u, order):
    """Chebyshev polynomials T_0..T_order at u (N,) -> (N, order + 1)."""
    return np.polynomial.chebyshev.chebvander(u, order)


# ----------------------------------------------------------------------------- signals


def sg_window(fs: float, f_hi: float, tol: float = 2e-5) -> int:
    """Longest odd Savitzky-Golay window (order 4, at least 5) whose first and second
    derivative gains are within ``tol`` of ``j w`` and ``-w^2`` at ``f_hi`` [Hz]
    (5 samples at 1 kHz for 40 Hz)."""
    from scipy.signal import savgol_coeffs
    best = 5
    w = 2 * np.pi * f_hi / fs
    for L in range(5, 401, 2):
        k = np.arange(L) - (L - 1) // 2
        e = np.exp(1j * w * k)
        c1 = savgol_coeffs(L, 4, deriv=1, use="dot")
        c2 = savgol_coeffs(L, 4, deriv=2, use="dot")
        if abs(np.sum(c1 * e) / (1j * w) - 1) > tol or abs(np.sum(c2 * e) / (-w * w) - 1) > tol:
            break
        best = L
    return best


@dataclass
class _Signals:
    fs: float  # working rate
    theta: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    tq: np.ndarray
    rho: np.ndarray
    vel_full: np.ndarray  # velocity before the high-pass (reflex input)
    rows: np.ndarray  # usable rows (bool)
    band: tuple


def _prepare(theta, tau, rho, fs, opt: VaryingOptions, name: str, skip_extra_s=0.0):
    from scipy import signal
    q = max(1, int(round(fs / opt.work_fs)))
    fw = fs / q
    f_hi = min(opt.f_hi, 0.4 * fw, 0.4 * fs)
    if f_hi <= 2 * opt.f_lo:
        raise VaryingError(f"parameter-varying fit over {name!r}: the recording's rate "
                           f"{fs:g} Hz leaves no band above {opt.f_lo:g} Hz (band top "
                           f"{f_hi:g} Hz); record at {10 * opt.f_lo:g} Hz or faster")
    lp = signal.butter(4, f_hi, fs=fs, output="sos")
    hp = signal.butter(HP_ORDER, opt.f_lo, btype="highpass", fs=fs, output="sos")
    th_l = signal.sosfiltfilt(lp, theta)
    tq_l = signal.sosfiltfilt(lp, tau)
    L = sg_window(fs, f_hi)
    vel_l = signal.savgol_filter(th_l, L, 4, deriv=1, delta=1.0 / fs)
    acc_l = signal.savgol_filter(th_l, L, 4, deriv=2, delta=1.0 / fs)
    parts = [signal.sosfiltfilt(hp, x)[::q] for x in (th_l, vel_l, acc_l, tq_l)]
    n = parts[0].size
    skip = int(np.ceil((opt.skip_s + skip_extra_s) * fw)) + 2
    rows = np.zeros(n, dtype=bool)
    rows[skip:n - skip] = True
    return _Signals(fw, *parts, np.asarray(rho, dtype=float)[::q], vel_l[::q], rows,
                    (opt.f_lo, f_hi))


# ----------------------------------------------------------------------------- reflex


def _reflex_input(s: _Signals, mode, f_lo):
    """The rectified velocity, high-passed like the torque (zero phase)."""
    from scipy import signal
    from .reflex import _nonlinearity
    hp = signal.butter(HP_ORDER, f_lo, btype="highpass", fs=s.fs, output="sos")
    return signal.sosfiltfilt(hp, _nonlinearity(s.vel_full, mode))


def _reflex_col(u, d, fc, zeta, fs):
    from .reflex import _delayed, _lowpass
    return _delayed(_lowpass(u, fc, zeta, fs), d)


def _intrinsic(s: _Signals, order, lo, hi):
    """Columns ``T_k(u) theta``, ``T_k(u) theta'``, ``T_k(u) theta''`` (k = 0..order), an
    offset, and the high-passed ``T_k(u)`` (k = 1..order): the quasi-static torque of the
    movement, a function of the state, as much of it as passes the high-pass."""
    from scipy import signal
    T = _cheb(_unit(s.rho, lo, hi), order)
    hp = signal.butter(HP_ORDER, s.band[0], btype="highpass", fs=s.fs, output="sos")
    slow = signal.sosfiltfilt(hp, T[:, 1:], axis=0) if order else np.zeros((s.rho.size, 0))
    return np.hstack([T * s.theta[:, None], T * s.vel[:, None], T * s.acc[:, None],
                      np.ones((s.rho.size, 1)), slow])


def _reflex_dynamics(s: _Signals, A, ropt, f_lo):
    """(mode, d_samples, fc, zeta) of the reflex: grid over each rectification (constant
    gain, column projected out of ``A``'s rows), then bounded Nelder-Mead."""
    from scipy import optimize
    rows = s.rows
    Q, _ = np.linalg.qr(A[rows])
    Q = np.ascontiguousarray(Q)
    y = s.tq[rows]
    r0 = y - Q @ (Q.T @ y)
    rr = float(r0 @ r0)

    def rss(x):
        # Q orthonormal and r0 orthogonal to it: |x_perp|^2 = |x|^2 - |Q'x|^2 and
        # x_perp . r0 = x . r0; einsum, not BLAS: a threaded BLAS on the loaded 2-core
        # machine made this 6 times slower (estimation/reflex.py says the same)
        xr = x[rows]
        c = np.einsum("nk,n->k", Q, xr, optimize=False)
        xx = float(np.einsum("n,n->", xr, xr)) - float(c @ c)
        xy = float(np.einsum("n,n->", xr, r0))
        return rr - (xy * xy / xx if xx > 1e-12 * rr else 0.0)

    modes = ("positive", "negative") if ropt.rectify == "auto" else (ropt.rectify,)
    d_lo = ropt.delay_ms[0] * 1e-3 * s.fs
    d_hi = ropt.delay_ms[1] * 1e-3 * s.fs
    fc_hi = min(ropt.cutoff_hz[1], 0.45 * s.fs)
    best = (np.inf, None)
    inputs = {m: _reflex_input(s, m, f_lo) for m in modes}
    shifts = np.arange(int(np.floor(d_lo)), int(np.ceil(d_hi)) + 1)
    # every delay at once: sums over the rows of a[n] x[n - s] by FFT (estimation/reflex.py)
    from .reflex import _correlate
    n = s.rho.size
    nfft = 1 << int(np.ceil(np.log2(n + shifts[-1] + 1)))
    full = np.zeros((Q.shape[1] + 2, n))
    full[0, rows] = r0
    full[1:-1, rows] = Q.T
    full[-1, rows] = 1.0
    stack_f = np.fft.rfft(full, nfft, axis=1)
    for m in modes:
        for fc in np.geomspace(ropt.cutoff_hz[0], fc_hi, 10):
            for zeta in np.geomspace(*ropt.damping, 5):
                x = _reflex_col(inputs[m], 0.0, fc, zeta, s.fs)
                xf = np.fft.rfft(np.vstack([x, x * x]), nfft, axis=1)
                c = _correlate(stack_f[:-1], xf[0], nfft, shifts)
                xx = _correlate(stack_f[-1], xf[1], nfft, shifts) - np.sum(c[1:] ** 2, 0)
                ok = xx > 1e-12 * max(float(xx.max()), 1e-300)
                gain = np.where(ok, c[0] ** 2 / np.where(ok, xx, 1.0), 0.0)
                j = int(np.argmax(gain))
                if rr - gain[j] < best[0]:
                    best = (rr - float(gain[j]), (m, float(shifts[j]), float(fc), float(zeta)))
    m, d0, fc0, z0 = best[1]
    lo = [d_lo, np.log(ropt.cutoff_hz[0]), np.log(ropt.damping[0])]
    hi = [d_hi, np.log(fc_hi), np.log(ropt.damping[1])]

    def cost(p):
        p = np.clip(p, lo, hi)
        return rss(_reflex_col(inputs[m], p[0], np.exp(p[1]), np.exp(p[2]), s.fs))

    res = optimize.minimize(cost, [d0, np.log(fc0), np.log(z0)], method="Nelder-Mead",
                            options={"xatol": 1e-3, "fatol": 1e-9 * rr, "maxfev": 150})
    p = np.clip(res.x, lo, hi)
    return m, float(p[0]), float(np.exp(p[1])), float(np.exp(p[2])), inputs[m]


# ----------------------------------------------------------------------------- fit


def _columns(order, max_order, reflex):
    """Indices of the columns of order ``order`` in the full design of ``max_order``:
    K, B, I (order + 1 each), the offset, the quasi-static columns (order), the reflex
    gain's (order + 1)."""
    n = max_order + 1
    idx = []
    for g in range(3):  # K, B, I
        idx += list(range(g * n, g * n + order + 1))
    idx += list(range(3 * n, 3 * n + 1 + order))  # offset, quasi-static
    if reflex:
        start = 3 * n + 1 + max_order
        idx += list(range(start, start + order + 1))
    return np.array(idx)


def _solve(G, c):
    d = np.sqrt(np.clip(np.diag(G), 1e-300, None))
    Gs = G / d[:, None] / d[None, :]
    try:
        x = np.linalg.solve(Gs + 1e-12 * np.eye(len(d)), c / d)
    except np.linalg.LinAlgError:
        x = np.linalg.lstsq(Gs, c / d, rcond=None)[0]
    return x / d


def fit_varying(theta, tau, rho, fs, *, name="rho", units="", source="",
                options: VaryingOptions | None = None, reflex=None,
                is_time=False) -> VaryingResult:
    """Fit K(rho), B(rho), I(rho) (and G(rho) with ``reflex``) to one joint.

    Parameters
    ----------
    theta : array_like (N,) [rad]
        Measured joint angle (project convention; the movement may be in it).
    tau : array_like (N,) [N m]
        Measured torque (project sign convention).
    rho : array_like (N,)
        The scheduling variable, one value per sample [``units``].
    fs : float [Hz]
    name, units, source : the scheduling variable as reported.
    options : VaryingOptions
    reflex : estimation.reflex.ReflexOptions or None
        Fit the reflex pathway too (its delay, cut-off, damping ranges and rectification).
    is_time : bool
        ``rho`` is time: orders up to ``max_order_time``.

    Returns
    -------
    VaryingResult

    Raises
    ------
    VaryingError
        Lengths differ, non-finite values, rho constant, too few blocks for the held-out
        test and the jackknife; the message names the variable and what would work.
    """
    import time as _time
    t0 = _time.perf_counter()
    opt = options or VaryingOptions()
    opt.check()
    theta = np.asarray(theta, dtype=float).ravel()
    tau = np.asarray(tau, dtype=float).ravel()
    rho = np.asarray(rho, dtype=float).ravel()
    _check_inputs(theta, tau, rho, fs, name, units)
    extra = (reflex.delay_ms[1] * 1e-3) if reflex is not None else 0.0
    s = _prepare(theta, tau, rho, float(fs), opt, name, extra)
    rows = np.flatnonzero(s.rows)
    nb = int(len(rows) // max(1, round(opt.block_s * s.fs)))
    need = max(2 * opt.folds, opt.jackknife // 2, 6)
    if nb < need:
        raise VaryingError(
            f"parameter-varying fit over {name!r}: {len(rows) / s.fs:.3g} s usable make "
            f"{nb} blocks of {opt.block_s:g} s; at least {need} are needed for the held-out "
            f"test and the jackknife (record {need * opt.block_s + 2 * opt.skip_s:.3g} s or "
            f"more)")
    blocks = np.array_split(rows, nb)
    r_rows = s.rho[rows]
    lo_c, hi_c = float(r_rows.min()), float(r_rows.max())
    if not hi_c > lo_c:
        raise VaryingError(f"parameter-varying fit over {name!r}: constant over the usable "
                           f"samples; nothing to schedule on")
    P = opt.max_order_time if is_time else opt.max_order
    A = _intrinsic(s, P, lo_c, hi_c)
    rinfo = None
    if reflex is not None:
        mode, d, fc, zeta, u = _reflex_dynamics(s, _intrinsic(s, min(P, 2), lo_c, hi_c),
                                                reflex, opt.f_lo)
        x = _reflex_col(u, d, fc, zeta, s.fs)
        T = _cheb(_unit(s.rho, lo_c, hi_c), P)
        A = np.hstack([A, T * x[:, None]])
        rinfo = {"rectify": mode, "delay_ms": 1e3 * d / s.fs, "cutoff_hz": fc,
                 "damping": zeta}
    y = s.tq
    # per-block sums of squares: everything below is small solves
    Gb = np.stack([A[b].T @ A[b] for b in blocks])
    cb = np.stack([A[b].T @ y[b] for b in blocks])
    yb = np.array([float(y[b] @ y[b]) for b in blocks])
    sb = np.array([float(y[b].sum()) for b in blocks])
    nbs = np.array([len(b) for b in blocks])
    rmin = np.array([s.rho[b].min() for b in blocks])
    rmax = np.array([s.rho[b].max() for b in blocks])
    rmean = np.array([s.rho[b].mean() for b in blocks])
    fold = np.empty(nb, dtype=int)
    fold[np.argsort(rmean, kind="stable")] = np.arange(nb) % opt.folds
    sse = np.full((P + 1, nb), np.nan)
    for p in range(P + 1):
        idx = _columns(p, P, rinfo is not None)
        for f in range(opt.folds):
            tr, te = fold != f, np.flatnonzero(fold == f)
            coef = _solve(Gb[tr].sum(0)[np.ix_(idx, idx)], cb[tr].sum(0)[idx])
            lo_t, hi_t = rmin[tr].min(), rmax[tr].max()
            for b in te:
                if rmin[b] >= lo_t and rmax[b] <= hi_t:
                    sse[p, b] = yb[b] - 2 * coef @ cb[b][idx] + \
                        coef @ Gb[b][np.ix_(idx, idx)] @ coef
    scored = ~np.isnan(sse[0])
    if scored.sum() < 2:
        raise VaryingError(f"parameter-varying fit over {name!r}: no held-out block lies "
                           f"inside its training range; a longer recording that visits "
                           f"each state more than once is needed")
    sst = float((yb[scored] - sb[scored] ** 2 / nbs[scored]).sum())
    tot = sse[:, scored].sum(1)
    vafs = 100 * (1 - tot / sst)
    order = int(np.argmin(tot))  # the least held-out error: the least truncation bias
    res = _final(s, A, y, Gb, cb, blocks, order, P, rinfo, lo_c, hi_c, opt, name, units,
                 source, r_rows)
    res.heldout_vaf_pct = {"varying": float(vafs[order]), "invariant": float(vafs[0]),
                           "blocks_scored": int(scored.sum()), "blocks": nb}
    res.orders = [{"order": p, "heldout_vaf_pct": float(vafs[p])} for p in range(P + 1)]
    res.warnings += _warnings(res, name)
    res.elapsed_s = _time.perf_counter() - t0
    return res


def _final(s, A, y, Gb, cb, blocks, order, P, rinfo, lo_c, hi_c, opt, name, units, source,
           r_rows):
    from scipy import stats
    has_r = rinfo is not None
    nb = len(blocks)
    m = min(opt.jackknife, nb)
    groups = np.arange(nb) % m
    pts = np.linspace(*np.percentile(r_rows, [1, 99]), opt.n_points)
    params = PARAMS + (("G",) if has_r else ())
    tq = stats.t.ppf(0.5 + opt.confidence / 2, m - 1)
    Gt, ct = Gb.sum(0), cb.sum(0)

    def curves(o, G, c):
        idx = _columns(o, P, has_r)
        a = _solve(G[np.ix_(idx, idx)], c[idx])
        n = o + 1
        coef = {"K": a[:n], "B": a[n:2 * n], "I": a[2 * n:3 * n]}
        if has_r:
            coef["G"] = a[3 * n + 1 + o:]
        return coef, a, idx

    def one(o):
        coef, a, idx = curves(o, Gt, ct)
        T = _cheb(_unit(pts, lo_c, hi_c), o)
        vals = {p: T @ coef[p] for p in params}
        jack = []
        for g in range(m):
            keep = groups != g
            cj, _, _ = curves(o, Gb[keep].sum(0), cb[keep].sum(0))
            jack.append({p: T @ cj[p] for p in params})
        half = {}
        for p in params:
            J = np.array([j[p] for j in jack])
            half[p] = tq * np.sqrt((m - 1) / m * np.sum((J - J.mean(0)) ** 2, axis=0))
        return coef, a, idx, vals, half

    coef, a, idx, vals, half = one(order)
    c0, _, _, v0, h0 = one(0)
    inv = {p: (float(v0[p][0]), float(v0[p][0] - h0[p][0]), float(v0[p][0] + h0[p][0]))
           for p in params}
    rows = s.rows
    yr = y[rows] - y[rows].mean()
    pred = A[:, idx] @ a
    pr = pred[rows] - pred[rows].mean()

    def vaf(e):
        return float(100 * (1 - np.var(yr - e) / np.var(yr)))

    vafp = {"total": vaf(pr)}
    if has_r:
        n = order + 1
        k = 3 * n + 1 + order  # K, B, I, offset, quasi-static
        intr = A[:, idx[:k]] @ a[:k]
        ir = intr[rows] - intr[rows].mean()
        vafp.update({"intrinsic": vaf(ir), "reflex": vaf(pr - ir)})
    return VaryingResult(
        scheduling=name, units=units, source=source, rho=pts, values=vals,
        lo={p: vals[p] - half[p] for p in params}, hi={p: vals[p] + half[p] for p in params},
        order=order, invariant=inv, heldout_vaf_pct={}, vaf_pct=vafp, orders=[],
        calibration_range=(lo_c, hi_c), band_hz=s.band, work_fs=s.fs, n_blocks=nb,
        n_groups=m, confidence=opt.confidence, reflex=rinfo, coefficients=coef)


def _warnings(res: VaryingResult, name) -> list:
    out = []
    h = res.heldout_vaf_pct
    if res.order == 0:
        out.append(f"no variation with {name!r} beyond the noise: the held-out test "
                   f"chose order 0 (the time-invariant model); K, B, I are flat")
    for p in ("K", "I"):
        if np.all(res.hi[p] < 0):
            out.append(f"{p}({name}) negative over the whole range: the torque sign may be "
                       f"reversed (a passive joint has {p} > 0)")
    rf = res.reflex
    if rf is not None:
        from .reflex import latency_warning
        late = latency_warning(rf["delay_ms"], rf.get("cutoff_hz"), rf.get("damping"))
        if late:
            out.append(late)
    if h["varying"] < h["invariant"]:
        out.append(f"held-out VAF of the varying model {h['varying']:.2f} % below the "
                   f"time-invariant one's {h['invariant']:.2f} %")
    return out


def _check_inputs(theta, tau, rho, fs, name, units):
    if not fs or not np.isfinite(fs) or fs <= 0:
        raise VaryingError(f"parameter-varying fit over {name!r}: sample rate {fs!r} Hz")
    if theta.shape != tau.shape:
        raise VaryingError(f"parameter-varying fit: angle has {theta.size} samples, torque "
                           f"{tau.size}")
    if rho.shape != theta.shape:
        raise VaryingError(f"scheduling variable {name!r}: {rho.size} values for the "
                           f"recording's {theta.size} samples; it must have one per sample "
                           f"at the recording's rate {fs:g} Hz (resample it, or choose "
                           f"another: --scheduling time or angle)")
    for what, x in (("angle", theta), ("torque", tau), (f"scheduling variable {name!r}", rho)):
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise VaryingError(f"parameter-varying fit: {what} is not finite at sample "
                               f"{bad[0]} (0-based; {bad.size} in all); give finite values "
                               f"at every sample")
    if np.all(rho == rho[0]):
        u = f" {units}" if units else ""
        raise VaryingError(f"scheduling variable {name!r}: constant ({rho[0]:.6g}{u}): "
                           f"nothing to schedule on; the time-invariant estimate holds "
                           f"(omit --scheduling, or choose time or angle)")
