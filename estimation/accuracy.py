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


def fit_impedance(estimate, *, inertia_delay_s=0.0, leakage=True, weighting="relative",
                  confidence=0.95) -> SecondOrderFit:
    """Fit M, B, K (n x n) to an estimate, optionally removing Welch's window leakage.

    The model of the raw estimate ``Zhat = T P^-1`` (decomposition/full/closed-loop) is,
    per frequency, with ``L1 = P1 P^-1``, ``L2 = P2 P^-1`` (window-derivative responses)::

        Zhat ~ K + B (jw I - L1) + M ((jw)^2 exp(-j w tau) I - 2 jw L1 + L2)

    exact for a continuous second-order arm under a Hann window (docs/estimation.md); the
    L terms are what the window's edges leak. ``leakage=False`` drops them, and the fit is
    then :func:`fit_second_order` element by element. Each row i of (M, B, K) is one
    linear least-squares problem over the n columns k, bins weighted by ``1/|Zhat_ik|``;
    R^2 and confidence intervals as in :func:`fit_second_order`, per element.

    Parameters
    ----------
    estimate : ImpedanceEstimate
    inertia_delay_s : float [s], keyword-only
        tau of the left-limit sampling model (:func:`left_limit_delay`), 0 for none.
    leakage : bool, keyword-only
        Model (and so remove) the window leakage. Needs ``estimate.P1``, ``estimate.P2``
        (not available for the ``direct`` method).
    """
    if weighting not in ("relative", "none"):
        raise EstimationError(f"weighting must be 'relative' or 'none', got {weighting!r}")
    if not leakage:
        return fit_second_order(estimate.f, estimate.Z, band_hz=estimate.band_hz,
                                inertia_delay_s=inertia_delay_s, weighting=weighting,
                                confidence=confidence)
    if not np.all(np.isfinite(estimate.P1)):
        raise EstimationError(f"method {estimate.method!r} gives no window-leakage responses;"
                              f" use leakage=False")
    b = estimate.band
    Z, (AM, AB, AK) = estimate.Z[b], _leakage_regressors(estimate, inertia_delay_s)
    n = estimate.n_dof
    out = {k: np.zeros((n, n)) for k in ("M", "B", "K", "M_ci", "B_ci", "K_ci", "r2")}
    for i in range(n):
        wts = [1.0 / np.abs(Z[:, i, k]) if weighting == "relative" else np.ones(len(Z))
               for k in range(n)]
        cols = [np.concatenate([A[:, j, k] * wts[k] for k in range(n)])
                for A in (AM, AB, AK) for j in range(n)]
        A = np.stack(cols, axis=1)
        y = np.concatenate([Z[:, i, k] * wts[k] for k in range(n)])
        A, y_r = np.vstack([A.real, A.imag]), np.concatenate([y.real, y.imag])
        theta, *_ = np.linalg.lstsq(A, y_r, rcond=None)
        resid = y_r - A @ theta
        dof = y_r.size - theta.size
        cov = np.linalg.inv(A.T @ A) * (resid @ resid) / dof
        half = stats.t.ppf(0.5 + confidence / 2, dof) * np.sqrt(np.diag(cov))
        for p, name in enumerate(("M", "B", "K")):
            out[name][i] = theta[p * n:(p + 1) * n]
            out[f"{name}_ci"][i] = half[p * n:(p + 1) * n]
        res_c = (resid[:y.size] + 1j * resid[y.size:]).reshape(n, -1)
        for k in range(n):
            z, wt = Z[:, i, k], wts[k]
            zc = np.sum(wt ** 2 * z) / np.sum(wt ** 2)
            out["r2"][i, k] = 1 - np.sum(np.abs(res_c[k]) ** 2) / np.sum(wt ** 2 * np.abs(z - zc) ** 2)
    return SecondOrderFit(confidence=confidence, inertia_delay_s=inertia_delay_s, **out)


def corrected_impedance(estimate, fit, *, leakage=True) -> np.ndarray:
    """The band part of ``estimate.Z`` with the modelled sampling (and leakage) terms removed.

    ``Zhat - M (jw)^2 (exp(-j w tau) - 1) [- (B (-L1) + M (-2 jw L1 + L2))]`` with the fitted
    M, B and ``tau = fit.inertia_delay_s``: what the continuous arm would give, if the
    models hold. Shape (nb, n, n) over ``estimate.band``.
    """
    b = estimate.band
    jw = 1j * 2 * np.pi * estimate.f[b][:, None, None]
    Z = estimate.Z[b] - fit.M @ ((jw ** 2) * (np.exp(-jw * fit.inertia_delay_s) - 1)
                                 * np.eye(estimate.n_dof))
    if leakage:
        L1, L2 = _leakage_matrices(estimate)
        Z = Z + fit.B @ L1 - fit.M @ (-2 * jw * L1 + L2)
    return Z


def _leakage_matrices(estimate):
    b = estimate.band
    P, P1, P2 = estimate.P[b], estimate.P1[b], estimate.P2[b]
    if estimate.method == "decomposition":  # Z = T / R_kk: only the diagonal responses
        P, P1, P2 = (np.einsum("fkk->fk", a)[:, :, None] * np.eye(a.shape[1])
                     for a in (P, P1, P2))
    Pinv = np.linalg.inv(P)
    return P1 @ Pinv, P2 @ Pinv


def _leakage_regressors(estimate, delay):
    """(A_M, A_B, A_K), each (nb, n, n): Zhat ~ M A_M + B A_B + K A_K (matrix products)."""
    L1, L2 = _leakage_matrices(estimate)
    jw = 1j * 2 * np.pi * estimate.f[estimate.band][:, None, None]
    eye = np.eye(estimate.n_dof)
    AM = (jw ** 2) * np.exp(-jw * delay) * eye - 2 * jw * L1 + L2
    AB = jw * eye - L1
    return AM, AB, np.broadcast_to(eye, AM.shape)
