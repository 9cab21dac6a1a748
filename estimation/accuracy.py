"""Accuracy measures of an impedance estimate (reference.md section 8), fixed definitions.

- ``vaf``: VAF = 100 (1 - sum |Zhat - Z|^2 / sum |Z|^2) over the band, complex FRF [%].
- ``fit_second_order``: ``Zhat ~ K - M w^2 + j B w`` by linear least squares on the real and
  imaginary parts, each bin weighted by ``1/|Zhat|`` (relative error). R^2 is defined with
  the same weights, against the best constant (complex) impedance:

      R^2 = 1 - sum w^2 |Zhat - Zfit|^2 / sum w^2 |Zhat - Zc|^2,  w = 1/|Zhat|,
      Zc = sum w^2 Zhat / sum w^2.

  Confidence intervals come from the weighted LS covariance, assuming the 2 nf weighted
  residuals (real and imaginary parts) are independent with one common variance.
  Welch's Hann window correlates neighbouring bins, so the intervals are optimistic
  (too narrow) by roughly the square root of that correlation length; they say nothing of
  a systematic model error (docs/estimation.md).
- Sampling compensation: ``inertia_delay_s`` fits ``K + j B w - M w^2 exp(-j w tau)``,
  the model of the left-limit sampling of the measured torque (tau = Ts/2, see
  :func:`left_limit_delay`); 0 is the ideal, continuous model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from .errors import EstimationError
from .estimator import BAND_HZ, band_mask


def true_impedance(f, M, B, K) -> np.ndarray:
    """``Z(f) = -M w^2 + j B w + K``, w = 2 pi f.

    Parameters
    ----------
    f : array_like [Hz], shape (nf,)
    M : array_like [kg m^2], B : [N m s/rad], K : [N m/rad]
        Scalars or (n, n) matrices (used as given, not symmetrised).

    Returns
    -------
    Z : ndarray [N m/rad], complex, shape (nf,) or (nf, n, n)
    """
    w = 2 * np.pi * np.asarray(f, dtype=float)
    M, B, K = (np.asarray(a, dtype=float) for a in (M, B, K))
    w = w.reshape((-1,) + (1,) * M.ndim)
    return K - M * w ** 2 + 1j * B * w


def left_limit_delay(fs) -> float:
    """Delay [s] of the inertial term when tau_h is sampled at the left limit: ``0.5 / fs``.

    Under a zero-order-held motor torque the acceleration jumps at each sample; the left
    limit sees the acceleration of the interval just ended, i.e. the acceleration half a
    sample earlier to first order in ``w Ts`` (docs/estimation.md).
    """
    return 0.5 / float(fs)


def vaf(Z_hat, Z_true) -> np.ndarray:
    """Variance accounted for [%] of each element, summed over axis 0 (frequency).

    ``VAF = 100 (1 - sum |Z_hat - Z_true|^2 / sum |Z_true|^2)``; pass band-limited arrays.
    Returns a scalar for 1-D input, else an (n, n) array.
    """
    Z_hat, Z_true = np.asarray(Z_hat), np.asarray(Z_true)
    if Z_hat.shape != Z_true.shape:
        raise EstimationError(f"Z_hat has shape {Z_hat.shape} but Z_true {Z_true.shape}")
    err = np.sum(np.abs(Z_hat - Z_true) ** 2, axis=0)
    return 100.0 * (1.0 - err / np.sum(np.abs(Z_true) ** 2, axis=0))


@dataclass
class SecondOrderFit:
    """Weighted LS fit ``Z ~ K - M w^2 + j B w`` of each element.

    Attributes
    ----------
    M, B, K : ndarray [kg m^2], [N m s/rad], [N m/rad]
        Fitted values, scalar or (n, n).
    M_ci, B_ci, K_ci : ndarray
        Half-widths of the confidence intervals (same units), at ``confidence``.
    r2 : ndarray [-]
        Weighted R^2 (module docstring).
    confidence : float
    inertia_delay_s : float [s]
        Delay of the inertial term in the fitted model (0: ideal model).
    """

    M: np.ndarray
    B: np.ndarray
    K: np.ndarray
    M_ci: np.ndarray
    B_ci: np.ndarray
    K_ci: np.ndarray
    r2: np.ndarray
    confidence: float
    inertia_delay_s: float

    def model(self, f) -> np.ndarray:
        """The fitted model, with its inertia delay, at frequencies f [Hz]."""
        w = 2 * np.pi * np.asarray(f, dtype=float).reshape((-1,) + (1,) * np.ndim(self.M))
        return self.K + 1j * self.B * w - self.M * w ** 2 * np.exp(-1j * w * self.inertia_delay_s)

    def relative_errors(self, M, B, K) -> dict:
        """Relative errors ``(fit - true) / true`` of M, B, K per element [-]."""
        return {name: (fit - np.asarray(true, float)) / np.asarray(true, float)
                for name, fit, true in (("M", self.M, M), ("B", self.B, B), ("K", self.K, K))}


def fit_second_order(f, Z, *, band_hz=BAND_HZ, inertia_delay_s=0.0, weighting="relative",
                     confidence=0.95) -> SecondOrderFit:
    """Fit ``K - M w^2 exp(-j w tau) + j B w`` to each element of Z over the band.

    Parameters
    ----------
    f : array_like [Hz], shape (nf,)
    Z : array_like [N m/rad], complex, shape (nf,) or (nf, n, n)
    band_hz : (float, float), keyword-only
        Bins with ``band_hz[0] < f <= band_hz[1]`` are fitted.
    inertia_delay_s : float [s], keyword-only
        tau; 0 for the ideal model, :func:`left_limit_delay` to compensate left-limit sampling.
    weighting : {"relative", "none"}, keyword-only
        ``relative`` weights each bin by ``1/|Z|`` (the project's fixed choice); ``none``
        is offered for comparison only.
    confidence : float, keyword-only
        Level of the confidence intervals.

    Returns
    -------
    SecondOrderFit
    """
    f, Z = np.asarray(f, dtype=float), np.asarray(Z)
    if Z.shape[0] != f.shape[0]:
        raise EstimationError(f"Z has {Z.shape[0]} frequencies but f has {f.shape[0]}")
    if weighting not in ("relative", "none"):
        raise EstimationError(f"weighting must be 'relative' or 'none', got {weighting!r}")
    mask = band_mask(f, band_hz)
    if mask.sum() < 3:
        raise EstimationError(f"band {band_hz} Hz holds {mask.sum()} bins, fewer than 3")
    w = 2 * np.pi * f[mask]
    Zb = Z[mask].reshape(mask.sum(), -1)
    # Columns: M, B, K regressors (complex), split into real and imaginary rows below.
    basis = np.stack([-w ** 2 * np.exp(-1j * w * inertia_delay_s), 1j * w,
                      np.ones_like(w)], axis=1)
    out = [_fit_one(basis, Zb[:, e], weighting, confidence) for e in range(Zb.shape[1])]
    shape = Z.shape[1:]
    fields = {name: np.array([o[i] for o in out]).reshape(shape)
              for i, name in enumerate(("M", "B", "K", "M_ci", "B_ci", "K_ci", "r2"))}
    return SecondOrderFit(confidence=confidence, inertia_delay_s=inertia_delay_s, **fields)


def _fit_one(basis, z, weighting, confidence):
    wt = 1.0 / np.abs(z) if weighting == "relative" else np.ones(z.shape)
    A = np.vstack([(basis * wt[:, None]).real, (basis * wt[:, None]).imag])
    y = np.concatenate([(z * wt).real, (z * wt).imag])
    theta, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ theta
    dof = y.size - theta.size
    cov = np.linalg.inv(A.T @ A) * (resid @ resid) / dof
    half = stats.t.ppf(0.5 + confidence / 2, dof) * np.sqrt(np.diag(cov))
    zc = np.sum(wt ** 2 * z) / np.sum(wt ** 2)
    r2 = 1.0 - (resid @ resid) / np.sum(wt ** 2 * np.abs(z - zc) ** 2)
    return (*theta, *half, r2)
