"""Exact discrete simulation of continuous-time linear systems, and scans for recursions.

The simulator's linear parts (servo loop, reflex activation, wobbling mass, shaping and
anti-alias filters) are continuous-time state-space systems ``x' = A x + B u``,
``y = C x + D u``. They are stepped exactly for an input that is linear between the
samples of a fine grid (first-order hold, FOH; Franklin, Powell & Workman, *Digital
Control of Dynamic Systems*, 3rd ed., 1998, section 6.3.2): in the modal coordinates of
``A`` each mode ``z' = lam z + w`` obeys

    z[k+1] = e^{lam h} z[k] + (g0 - g1/h) w[k] + (g1/h) w[k+1],
    g0 = (e^{lam h} - 1) / lam,   g1 = (e^{lam h} - 1 - lam h) / lam^2,

a first-order recursion run by ``scipy.signal.lfilter`` in C, one call per mode. This is
neither the project's bilinear (Tustin) filters at the sampling rate nor its central
differences: the step is exact for the interpolated input, at any rate.

Two scans solve the simulator's nonlinear recursions without a Python loop over samples
(Blelloch, "Prefix sums and their applications", 1990: an associative operator is
composed in log2(N) vectorised passes): :func:`affine_scan` for ``x[k] = c[k] x[k-1] +
d[k]`` (LuGre bristles) and :func:`play_scan` for the play (backlash) operator
``y[k] = min(max(y[k-1], x[k] - w), x[k] + w)`` (backlash, short-range stiffness).
"""

from __future__ import annotations

import numpy as np
from scipy import linalg, signal

#: eigenvalues closer than this (relative) are split (see :func:`_modes`)
_REPEATED = 1e-7


class StateSpace:
    """A continuous-time linear system ``x' = A x + B u``, ``y = C x + D u``.

    Parameters
    ----------
    A : (n, n), B : (n, m), C : (p, n), D : (p, m) array_like
        SI units of the signals they map.
    """

    def __init__(self, A, B, C, D):
        self.A = np.atleast_2d(np.asarray(A, dtype=float))
        self.B = np.asarray(B, dtype=float).reshape(self.A.shape[0], -1)
        self.C = np.asarray(C, dtype=float).reshape(-1, self.A.shape[0])
        self.D = np.asarray(D, dtype=float).reshape(self.C.shape[0], self.B.shape[1])

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @classmethod
    def from_tf(cls, num, den, derivatives: int = 0) -> "StateSpace":
        """A SISO transfer function ``num(s)/den(s)`` (proper), outputs y, y', ..., y^(k).

        ``derivatives`` k may reach the relative degree (:meth:`with_derivatives`).

        Raises
        ------
        ValueError
            An improper transfer function, or a relative degree too low for k.
        """
        num, den = np.atleast_1d(np.asarray(num, float)), np.atleast_1d(np.asarray(den, float))
        num = np.trim_zeros(num, "f")
        rel = (den.size - 1) - (num.size - 1)
        if rel < 0:
            raise ValueError(f"transfer function is improper (numerator degree "
                             f"{num.size - 1} above denominator degree {den.size - 1})")
        return cls(*signal.tf2ss(num, den)).with_derivatives(derivatives, rel)

    @classmethod
    def from_zpk(cls, z, p, k, derivatives: int = 0) -> "StateSpace":
        """As :meth:`from_tf` from zeros, poles and gain: a series of second-order
        sections (``scipy.signal.zpk2sos``, analog pairing), well conditioned at any order
        where one companion matrix of order 8 is not."""
        sos = signal.zpk2sos(z, p, k, analog=True)
        # each section scaled to one magnitude at a middle frequency (zpk2sos puts the
        # whole gain in the first section: a badly scaled state matrix)
        w_ref = float(np.exp(np.mean(np.log(np.abs(np.asarray(p)) + 1e-300))))
        total = abs(k * np.prod(1j * w_ref - np.asarray(z)) / np.prod(1j * w_ref - np.asarray(p)))
        share = total ** (1.0 / len(sos))
        sys = None
        for row in sos:
            num, den = np.trim_zeros(row[:3], "f"), np.trim_zeros(row[3:], "f")
            mag = abs(np.polyval(num, 1j * w_ref) / np.polyval(den, 1j * w_ref))
            sec = cls(*signal.tf2ss(num * share / mag, den))
            sys = sec if sys is None else series(sys, sec)
        if np.prod(np.sign([r[np.nonzero(r[:3])[0][0]] for r in sos])) * np.sign(k) < 0:
            sys.C = -sys.C
            sys.D = -sys.D
        return sys.with_derivatives(derivatives, len(p) - len(z))

    def with_derivatives(self, k: int, rel: int) -> "StateSpace":
        """The outputs y, y', ..., y^(k) of a SISO system of relative degree ``rel``.

        ``y^(i) = C A^i x`` for i < rel, and ``y^(rel) = C A^rel x + C A^(rel-1) B u``
        (Kailath, *Linear Systems*, 1980, section 2.1): k may reach the relative degree.

        Raises
        ------
        ValueError
            k above the relative degree.
        """
        if k > rel:
            raise ValueError(f"relative degree {rel} too low for {k} derivative(s)")
        rows, direct, Ci = [self.C], [self.D], self.C
        for i in range(1, k + 1):
            direct.append(Ci @ self.B if i == rel else np.zeros_like(self.D))
            Ci = Ci @ self.A
            rows.append(Ci)
        return StateSpace(self.A, self.B, np.vstack(rows), np.vstack(direct))

    def simulate(self, u, h: float, x0=None, smooth: bool = False) -> np.ndarray:
        """Outputs on the grid for the input ``u`` linear between samples (FOH), exactly.

        Parameters
        ----------
        u : (N,) or (m, N) array
            Input at the grid points ``k h`` (time last).
        h : float
            Grid step [s].
        x0 : (n,) array, optional
            Initial state (zero: at rest).
        smooth : bool
            ``u`` samples a smooth signal: pre-equalise it (:func:`equalise`) so that the
            response is that of the smooth signal to O((w h)^4), not of its piecewise
            linear interpolant (whose sinc^2 costs (w h)^2 / 12: 5e-5 at 40 Hz and
            h = 0.1 ms). Not for inputs that are piecewise linear by definition (white
            noise, held steps).

        Returns
        -------
        (p, N) array, or (N,) for one output of a vector input
        """
        return simulate(self, equalise(u) if smooth else u, h, x0)

    def dc_gain(self) -> np.ndarray:
        """Static gain ``D - C A^{-1} B``, shape (p, m)."""
        return self.D - self.C @ np.linalg.solve(self.A, self.B)

    def frequency_response(self, f_hz) -> np.ndarray:
        """``C (j w I - A)^{-1} B + D`` at ``f_hz`` [Hz], shape (len(f), p, m)."""
        out = []
        eye = np.eye(self.n_states)
        for w in 2 * np.pi * np.atleast_1d(f_hz):
            out.append(self.C @ np.linalg.solve(1j * w * eye - self.A, self.B) + self.D)
        return np.array(out)


def series(first: StateSpace, second: StateSpace) -> StateSpace:
    """``second`` driven by the outputs of ``first`` (exact, one state space)."""
    n1, n2 = first.n_states, second.n_states
    A = np.block([[first.A, np.zeros((n1, n2))], [second.B @ first.C, second.A]])
    B = np.vstack([first.B, second.B @ first.D])
    C = np.hstack([second.D @ first.C, second.C])
    return StateSpace(A, B, C, second.D @ first.D)


def _modes(A: np.ndarray):
    """Eigenvalues and eigenvectors of ``A``; a repeated eigenvalue (a critically damped
    pair, a Jordan block) is split by a relative 1e-7, an error of that order in the
    response, so that the eigenvector matrix is invertible."""
    lam, V = linalg.eig(A)
    n = lam.size
    scale = max(np.max(np.abs(lam)), 1e-300)
    close = n > 1 and np.min(np.abs(lam[:, None] - lam[None, :]) + np.eye(n) * scale) \
        < _REPEATED * scale
    if close or np.linalg.cond(V) > 1e10:
        shift = np.diag(np.linspace(-1.0, 1.0, n)) * _REPEATED * scale
        lam, V = linalg.eig(A + shift)
        if np.linalg.cond(V) > 1e12:
            raise ValueError("state matrix too close to defective to diagonalise")
    return lam, V


def foh_coefficients(lam: np.ndarray, h: float):
    """Pole ``e^{lam h}`` and the FOH weights (of ``w[k]``, of ``w[k+1]``) of each mode."""
    z = lam * h
    a = np.exp(z)
    small = np.abs(z) < 1e-3
    zs = np.where(small, 1.0, z)
    g0 = np.where(small, h * (1 + z / 2 + z ** 2 / 6 + z ** 3 / 24),
                  np.expm1(zs) / np.where(small, 1.0, lam))
    g1 = np.where(small, h * h * (0.5 + z / 6 + z ** 2 / 24 + z ** 3 / 120),
                  (np.expm1(zs) - zs) / np.where(small, 1.0, lam) ** 2)
    return a, g0 - g1 / h, g1 / h


def equalise(u) -> np.ndarray:
    """``u`` through the 3-tap FIR (-1, 14, -1)/12 along its last axis (end samples
    kept): the inverse, to O((w h)^4), of the first-order hold's sinc^2(w h / 2) =
    1 - (w h)^2/12 + ..., whose response is (14 - 2 cos(w h))/12 = 1 + (w h)^2/12 - ..."""
    u = np.asarray(u, dtype=float)
    out = u.copy()
    out[..., 1:-1] += (2 * u[..., 1:-1] - u[..., :-2] - u[..., 2:]) / 12.0
    return out


def simulate(sys: StateSpace, u, h: float, x0=None) -> np.ndarray:
    """:meth:`StateSpace.simulate` (module docstring: exact FOH step per mode).

    Signals are time-last: ``u`` (N,) or (m, N), the result (p, N), or (N,) for a
    single-input single-output system given a vector.
    """
    u = np.asarray(u, dtype=float)
    flat = u.ndim == 1
    u = u.reshape(-1, u.shape[-1])
    if u.shape[0] != sys.B.shape[1]:
        raise ValueError(f"input has {u.shape[0]} row(s), the system {sys.B.shape[1]} input(s)")
    y = sys.D @ u
    if sys.n_states == 0:
        return y[0] if flat and y.shape[0] == 1 else y
    lam, V = _modes(sys.A)
    Vinv = np.linalg.inv(V)
    z0 = np.zeros(lam.size, complex) if x0 is None else Vinv @ np.asarray(x0, float)
    a, b0, b1 = foh_coefficients(lam, h)
    # a conjugate pair contributes twice the real part of one of its modes
    keep, weight = [], []
    for i in range(lam.size):
        if lam[i].imag != 0 and any(
                abs(lam[j] - np.conj(lam[i])) <= 1e-12 * abs(lam[i]) for j in keep):
            continue
        keep.append(i)
        weight.append(2.0 if lam[i].imag != 0 else 1.0)
    W = (Vinv[keep] @ sys.B) @ u  # modal inputs (k, N), complex
    Z = np.empty(W.shape, complex)
    for row, i in enumerate(keep):
        zi = np.array([z0[i] - b1[i] * W[row, 0]])
        Z[row], _ = signal.lfilter([b1[i], b0[i]], [1.0, -a[i]], W[row], zi=zi)
    CV = (sys.C @ V[:, keep]) * np.asarray(weight)
    y += (CV @ Z).real
    return y[0] if flat and y.shape[0] == 1 else y


def affine_scan(c: np.ndarray, d: np.ndarray, x0: float = 0.0) -> np.ndarray:
    """``x[k] = c[k] x[k-1] + d[k]`` for k = 0..N-1 with ``x[-1] = x0``, vectorised.

    |c| <= 1 keeps every partial product bounded (no overflow). Shapes (N,) or (N, n).
    """
    C = np.array(c, dtype=float, copy=True)
    D = np.array(d, dtype=float, copy=True)
    s = 1
    while s < C.shape[0]:
        D[s:] = C[s:] * D[:-s] + D[s:]
        C[s:] = C[s:] * C[:-s]
        s *= 2
    return C * x0 + D


def play_scan(x: np.ndarray, width, y0=0.0) -> np.ndarray:
    """The play operator ``y[k] = min(max(y[k-1], x[k] - w), x[k] + w)``, ``y[-1] = y0``.

    Each step is the clamp map ``y -> min(max(y, lo), hi)``; clamps compose into clamps
    (lo, hi of g after f: g(lo_f), g(hi_f)), so the recursion is a scan. Shapes (N,) or
    (N, n); ``width`` >= 0 (scalar or per column).
    """
    x = np.asarray(x, dtype=float)
    w = np.asarray(width, dtype=float)
    lo, hi = x - w, x + w
    s = 1
    while s < x.shape[0]:
        # map k after map k-s: (lo, hi)[k] applied to (lo, hi)[k-s]
        new_lo = np.minimum(np.maximum(lo[:-s], lo[s:]), hi[s:])
        new_hi = np.minimum(np.maximum(hi[:-s], lo[s:]), hi[s:])
        lo[s:], hi[s:] = new_lo, new_hi
        s *= 2
    return np.minimum(np.maximum(y0, lo), hi)
