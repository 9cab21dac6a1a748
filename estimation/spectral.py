"""Welch cross-spectra, frequency responses and coherences (reference.md section 8).

One helper, :func:`cross_spectrum`, computes every spectral density; transfer functions and
coherences are built on it. Conventions follow ``scipy.signal.csd(x, y)``:
``G_xy(f) = E[conj(X(f)) Y(f)]``, one-sided, density scaling [unit_x unit_y / Hz]. With that
convention the H1 estimate of the response from x to y is ``G_xy / G_xx``.

Defaults are the paper's Table IV: Hann window of 8192 samples, 6144 overlap, NFFT 8192,
mean removed per segment. ``fs`` is always required.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from .errors import EstimationError

NPERSEG = 8192
NOVERLAP = 6144
NFFT = 8192
WINDOW = "hann"
DETREND = "constant"


@dataclass(frozen=True)
class WelchOptions:
    """Welch parameters (Table IV by default)."""

    nperseg: int = NPERSEG
    noverlap: int = NOVERLAP
    nfft: int = NFFT
    window: str = WINDOW
    detrend: str = DETREND

    def n_segments(self, n_samples: int) -> int:
        """Number of Welch segments a record of ``n_samples`` gives."""
        return (n_samples - self.noverlap) // (self.nperseg - self.noverlap)


def cross_spectrum(x, y, *, fs, nperseg=NPERSEG, noverlap=NOVERLAP, nfft=NFFT,
                   window=WINDOW, detrend=DETREND):
    """Welch cross-spectral density matrix between the columns of x and of y.

    Parameters
    ----------
    x : array_like, shape (N,) or (N, p)
        First signal(s), conjugated [unit_x].
    y : array_like, shape (N,) or (N, q)
        Second signal(s) [unit_y].
    fs : float
        Sampling frequency [Hz].
    nperseg, noverlap, nfft : int, keyword-only
        Welch segment length, overlap and FFT length [samples].
    window, detrend : str, keyword-only
        As in ``scipy.signal.csd``.

    Returns
    -------
    f : ndarray [Hz], shape (nf,)
    G : ndarray [unit_x unit_y / Hz], complex
        Shape (nf,) for 1-D x and y, else (nf, p, q) with ``G[:, a, b] = G_{x_a y_b}``.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x.shape[0] != y.shape[0]:
        raise EstimationError(f"x has {x.shape[0]} samples but y has {y.shape[0]}")
    if x.shape[0] < nperseg:
        raise EstimationError(f"{x.shape[0]} samples, fewer than one segment ({nperseg})")
    if x.ndim == 1 and y.ndim == 1:
        f, g = signal.csd(x, y, fs=fs, window=window, nperseg=nperseg, noverlap=noverlap,
                          nfft=nfft, detrend=detrend)
        return f, g
    x2, y2 = x.reshape(x.shape[0], -1), y.reshape(y.shape[0], -1)
    f, g = signal.csd(x2[:, :, None], y2[:, None, :], fs=fs, window=window, nperseg=nperseg,
                      noverlap=noverlap, nfft=nfft, detrend=detrend, axis=0)
    return f, g  # with axis=0 scipy keeps frequency first: (nf, p, q)


def spectral_matrix(z, *, fs, nperseg=NPERSEG, noverlap=NOVERLAP, nfft=NFFT, window=WINDOW,
                    detrend=DETREND):
    """Welch cross-spectral matrix of all columns of z from one FFT per segment and column.

    Returns ``(f, G)`` with ``G[:, a, b] = G_{z_a z_b}`` [unit^2/Hz], shape (nf, c, c); equal
    to :func:`cross_spectrum` ``(z, z)`` (scipy.signal.csd) for ``detrend`` "constant" or
    False, about 3x faster than separate csd calls for the same pairs. Other detrends go
    through :func:`cross_spectrum`.
    """
    z = np.asarray(z, dtype=float).reshape(len(z), -1)
    if detrend not in ("constant", False, None) or z.shape[0] < nperseg:
        return cross_spectrum(z, z, fs=fs, nperseg=nperseg, noverlap=noverlap, nfft=nfft,
                              window=window, detrend=detrend)
    win = signal.get_window(window, nperseg)
    segs = np.lib.stride_tricks.sliding_window_view(z, nperseg, axis=0)[::nperseg - noverlap]
    if detrend == "constant":
        segs = segs - segs.mean(axis=-1, keepdims=True)
    Z = np.fft.rfft(segs * win, n=nfft, axis=-1)               # (segments, c, nf)
    G = np.einsum("saf,sbf->fab", Z.conj(), Z) * (1.0 / (fs * np.sum(win ** 2) * len(Z)))
    G[1:-1 if nfft % 2 == 0 else None] *= 2.0
    return np.fft.rfftfreq(nfft, 1.0 / fs), G


def auto_spectrum(x, *, fs, **options):
    """Real power spectral density of each column of x (diagonal of the cross-spectrum).

    Returns ``(f, G)`` with G [unit_x^2 / Hz] of shape (nf,) or (nf, p).
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        f, g = cross_spectrum(x, x, fs=fs, **options)
        return f, g.real
    f, g = cross_spectrum(x, x, fs=fs, **options)
    return f, np.real(np.diagonal(g, axis1=1, axis2=2))


def frequency_response(x, y, *, fs, **options):
    """H1 estimate of the response from input(s) x to output(s) y.

    For scalar x: ``H = G_xy / G_xx``. For p inputs, the MIMO H1 estimate
    ``H(f) = (G_xx^-1 G_xy)^T`` of shape (nf, q, p), so that ``Y = H X``.

    Returns
    -------
    f : ndarray [Hz]
    H : ndarray [unit_y / unit_x], complex, shape (nf,), (nf, q) or (nf, q, p)
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x.ndim == 1:
        f, gxx = auto_spectrum(x, fs=fs, **options)
        f, gxy = cross_spectrum(x, y, fs=fs, **options)
        return f, (gxy if y.ndim == 1 else gxy[:, 0, :]) / (gxx if y.ndim == 1 else gxx[:, None])
    f, gxx = cross_spectrum(x, x, fs=fs, **options)
    f, gxy = cross_spectrum(x, y, fs=fs, **options)
    return f, np.swapaxes(np.linalg.solve(gxx, gxy), 1, 2)


def coherence(x, y, *, fs, **options):
    """Ordinary coherence ``|G_xy|^2 / (G_xx G_yy)`` between 1-D signals x and y.

    Returns ``(f, C)`` with C dimensionless in [0, 1]. It equals ``scipy.signal.coherence``
    with the same options.
    """
    f, gxy = cross_spectrum(x, y, fs=fs, **options)
    _, gxx = auto_spectrum(x, fs=fs, **options)
    _, gyy = auto_spectrum(y, fs=fs, **options)
    return f, ordinary_coherence(gxy, gxx, gyy)


def ordinary_coherence(gxy, gxx, gyy):
    """``|G_xy|^2 / (G_xx G_yy)`` from spectra already computed (0 where a PSD is 0)."""
    den = np.real(gxx) * np.real(gyy)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.abs(gxy) ** 2 / den
    return np.where(den > 0, c, 0.0)


def window_derivative_spectra(x, y, *, fs, nperseg=NPERSEG, noverlap=NOVERLAP, nfft=NFFT,
                              with_plain=True):
    """Cross-spectra of Hann-windowed x with y windowed by the Hann window's derivatives.

    With ``w`` the (periodic) Hann window of ``nperseg`` samples over ``L = nperseg/fs``
    seconds, returns ``(f, G0, G1, G2)``, each (nf, p, q) complex: the Welch averages of
    ``conj(FFT(w x)) FFT(v y)`` for ``v = w`` [unit_x unit_y / Hz],
    ``v = dw/dt`` [.. / (Hz s)] and ``v = d^2w/dt^2`` [.. / (Hz s^2)], all with the
    scaling of :func:`cross_spectrum` (mean removed per segment, one-sided).
    ``G0`` equals ``cross_spectrum(x, y)``. They give the window's leakage exactly: for
    ``y = a y'' + b y' + c y`` the windowed transform obeys
    ``FFT(w y'') = (jw)^2 FFT(w y) - 2 jw FFT(w' y) + FFT(w'' y)`` (docs/estimation.md).
    ``with_plain=False`` skips G0 (returned as None).
    """
    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    y = np.asarray(y, dtype=float).reshape(len(y), -1)
    if x.shape[0] != y.shape[0] or x.shape[0] < nperseg:
        raise EstimationError(f"x and y need the same length, at least {nperseg} samples; got "
                              f"{x.shape[0]} and {y.shape[0]}")
    m = np.arange(nperseg)
    length = nperseg / fs
    w0 = signal.get_window("hann", nperseg)
    w1 = (np.pi / length) * np.sin(2 * np.pi * m / nperseg)
    w2 = (2 * np.pi ** 2 / length ** 2) * np.cos(2 * np.pi * m / nperseg)
    X = _segment_ffts(x, w0, nperseg, noverlap, nfft)
    scale = 1.0 / (fs * np.sum(w0 ** 2))
    out = []
    for win in ((w0, w1, w2) if with_plain else (w1, w2)):
        Y = _segment_ffts(y, win, nperseg, noverlap, nfft)
        g = np.einsum("sfa,sfb->fab", X.conj(), Y) * (scale / X.shape[0])
        g[1:-1 if nfft % 2 == 0 else None] *= 2.0
        out.append(g)
    if not with_plain:
        out.insert(0, None)
    return (np.fft.rfftfreq(nfft, 1.0 / fs), *out)


def _segment_ffts(x, window, nperseg, noverlap, nfft):
    """FFTs of the mean-removed, windowed segments: shape (segments, nf, channels)."""
    segs = np.lib.stride_tricks.sliding_window_view(x, nperseg, axis=0)[::nperseg - noverlap]
    segs = segs - segs.mean(axis=-1, keepdims=True)  # (segments, channels, nperseg)
    return np.fft.rfft(segs * window, n=nfft, axis=-1).transpose(0, 2, 1)
