"""Accuracy measures of an impedance estimate (reference.md section 8), fixed definitions.

- ``vaf``: VAF = 100 (1 - sum |Zhat - Z|^2 / sum |Z|^2) over the band, complex FRF [%].
- ``fit_second_order``: ``Zhat ~ K - M w^2 + j B w`` by linear least squares on the real and
  imaginary parts, each bin weighted (``WEIGHTINGS``, :func:`data_weights`). R^2 is the
  fit's VAF with the same weights, against zero (so it reads 1 for a perfect fit of any
  impedance shape, a pure spring included):

      R^2 = 1 - sum w^2 |Zhat - Zfit|^2 / sum w^2 |Zhat|^2.

- Weightings taken from the data only, solved once (one answer, global in the band: the
  weighted LS problem is linear in M, B, K): ``coherence`` weights each bin by the inverse
  of the standard deviation of ``Zhat`` that its coherence predicts (Bendat & Piersol,
  Random Data, 4th ed., eq. 9.52: ``std|H| / |H| ~ sqrt(1 - g^2) / (|g| sqrt(2 nd))``),
  ``w = |g| / (|Z| sqrt(1 - g^2))``; ``smoothed`` by ``1/|Z|`` (relative error). In both,
  ``|Z|`` and ``g^2`` of a bin are the means over its neighbours 3 to 6 bins away (log
  |Zhat|, g^2), never the bin itself or the two next to it, whose errors correlate with
  its own under a Hann window: weights from the bin itself favour bins where the noise
  shrank |Zhat| (``relative``, ``1/|Zhat|``: -0.7 % on K at coherence 0.9).

- Confidence intervals: the weighted LS estimate with a heteroscedasticity- and
  autocorrelation-consistent (HAC) covariance over frequency, because Welch's Hann window
  correlates the errors of neighbouring bins (about 0.44 at one bin, 0.03 at two): the
  truncated kernel sums the score covariances of lags 0..``hac_bins`` unweighted (White
  1984; 2 bins per ``nfft/nperseg``), negative eigenvalues clipped; quantiles of
  Student's t with the effective number of independent bins minus the parameters. Coverage measured by Monte Carlo in
  docs/estimation.md. They say nothing of a systematic model error.
- Sampling compensation: ``inertia_delay_s`` fits ``K + j B w - M w^2 exp(-j w tau)``,
  the model of the left-limit sampling of the measured torque (tau = Ts/2, see
  :func:`left_limit_delay`); 0 is the ideal, continuous model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from .errors import EstimationError
from .names import WEIGHTINGS
from .estimator import BAND_HZ, band_mask


#: Neighbours of a bin whose mean sets its data weight: 3 to 6 bins away on each side.
WEIGHT_GAP, WEIGHT_REACH = 2, 6


def neighbour_mean(x, gap=WEIGHT_GAP, reach=WEIGHT_REACH) -> np.ndarray:
    """Mean of ``x[j]`` over ``gap < |j - k| <= reach`` for every k (axis 0).

    Bins near the ends use the neighbours they have; with none (fewer than ``gap + 2``
    bins) the mean over all bins. Shape of ``x``.
    """
    x = np.asarray(x, dtype=float)
    nb = x.shape[0]
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)])
    k = np.arange(nb)
    total = np.zeros_like(x)
    count = np.zeros(nb)
    for lo, hi in ((k - reach, k - gap - 1), (k + gap + 1, k + reach)):
        lo_c, hi_c = np.clip(lo, 0, nb), np.clip(hi + 1, 0, nb)
        ok = hi_c > lo_c
        total[ok] += c[hi_c[ok]] - c[lo_c[ok]]
        count += np.where(ok, hi_c - lo_c, 0)
    shape = (-1,) + (1,) * (x.ndim - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = total / count.reshape(shape)
    return np.where(count.reshape(shape) > 0, out, x.mean(axis=0))


def data_weights(z, weighting, coherence=None) -> np.ndarray:
    """Bin weights of a fit from the data alone (module docstring), shape of ``z`` (nb,).

    ``coherence`` [-] (nb,) is needed for ``weighting="coherence"`` (clipped to
    1e-3..0.999 after the neighbour mean).
    """
    z = np.asarray(z)
    if weighting == "none":
        return np.ones(z.shape)
    if weighting == "relative":
        return 1.0 / np.abs(z)
    mag = np.exp(neighbour_mean(np.log(np.abs(z))))
    if weighting == "smoothed":
        return 1.0 / mag
    if weighting == "coherence":
        if coherence is None:
            raise EstimationError("weighting='coherence' needs the coherence of the estimate")
        g2 = np.clip(neighbour_mean(coherence), 1e-3, 0.999)
        return np.sqrt(g2 / (1.0 - g2)) / mag
    raise EstimationError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")


#: Default HAC bandwidth [bins] for nfft == nperseg (Hann: errors of bins 1-2 apart
#: correlate, and the wider the more zero padding).
HAC_BINS = 2


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


def fit_second_order(f, Z, *, band_hz=BAND_HZ, inertia_delay_s=0.0, weighting="model",
                     confidence=0.95, hac_bins=HAC_BINS, coherence=None) -> SecondOrderFit:
    """Fit ``K - M w^2 exp(-j w tau) + j B w`` to each element of Z over the band.

    Parameters
    ----------
    f : array_like [Hz], shape (nf,)
    Z : array_like [N m/rad], complex, shape (nf,) or (nf, n, n)
    band_hz : (float, float), keyword-only
        Bins with ``band_hz[0] < f <= band_hz[1]`` are fitted.
    inertia_delay_s : float [s], keyword-only
        tau; 0 for the ideal model, :func:`left_limit_delay` to compensate left-limit sampling.
    weighting : {"model", "relative", "none"}, keyword-only
        ``model`` (default) weights each bin by ``1/|Zfit|`` of a first ``relative`` pass:
        relative error without the bias that weights taken from the noisy estimate itself
        (``relative``: ``1/|Zhat|``) give, which favour bins where noise shrank |Zhat|
        (about -0.7 % on K at coherence 0.9, docs/estimation.md); ``none`` for comparison;
        ``coherence`` and ``smoothed``: from the data alone, solved once
        (:func:`data_weights`).
    confidence : float, keyword-only
        Level of the confidence intervals.
    hac_bins : int, keyword-only
        Bins over which estimation errors are taken as correlated (module docstring);
        0 for independent bins.
    coherence : array_like [-], shape of Z, keyword-only
        Coherence of each element (for ``weighting="coherence"``).

    Returns
    -------
    SecondOrderFit
    """
    f, Z = np.asarray(f, dtype=float), np.asarray(Z)
    if Z.shape[0] != f.shape[0]:
        raise EstimationError(f"Z has {Z.shape[0]} frequencies but f has {f.shape[0]}")
    if weighting not in WEIGHTINGS:
        raise EstimationError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    if weighting == "coherence" and coherence is None:
        raise EstimationError("weighting='coherence' needs the coherence of the estimate")
    mask = band_mask(f, band_hz)
    if mask.sum() < 3:
        raise EstimationError(f"band {band_hz} Hz holds {mask.sum()} bins, fewer than 3")
    w = 2 * np.pi * f[mask]
    Zb = Z[mask].reshape(mask.sum(), -1)
    # Columns: M, B, K regressors (complex), split into real and imaginary rows below.
    basis = np.stack([-w ** 2 * np.exp(-1j * w * inertia_delay_s), 1j * w,
                      np.ones_like(w)], axis=1)
    Cb = (np.asarray(coherence)[mask].reshape(mask.sum(), -1) if coherence is not None
          else [None] * Zb.shape[1])
    out = [_fit_one(basis, Zb[:, e], weighting, confidence, hac_bins,
                    None if coherence is None else Cb[:, e]) for e in range(Zb.shape[1])]
    shape = Z.shape[1:]
    fields = {name: np.array([o[i] for o in out]).reshape(shape)
              for i, name in enumerate(("M", "B", "K", "M_ci", "B_ci", "K_ci", "r2"))}
    return SecondOrderFit(confidence=confidence, inertia_delay_s=inertia_delay_s, **fields)


def _fit_one(basis, z, weighting, confidence, hac_bins, coherence=None):
    if weighting == "model":
        first = _fit_one(basis, z, "relative", confidence, 0)
        wt = 1.0 / np.abs(basis @ np.asarray(first[:3]))
    else:
        wt = data_weights(z, weighting, coherence)
    Ac = basis * wt[:, None]
    A = np.vstack([Ac.real, Ac.imag])
    y = np.concatenate([(z * wt).real, (z * wt).imag])
    theta, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ theta
    half = _hac_half_widths(Ac[None], resid.reshape(2, 1, -1), confidence, hac_bins)
    r2 = 1.0 - (resid @ resid) / np.sum(np.abs(wt * z) ** 2)
    return (*theta, *half, r2)


def _hac_half_widths(Ac, resid, confidence, hac_bins):
    """CI half-widths of a stacked real LS fit with errors correlated along frequency.

    ``Ac`` (columns, nb, p) complex weighted regressors, one block per fitted column of
    the same frequencies; ``resid`` (2, columns, nb): real and imaginary residuals. The
    score of each frequency bin (summed over the columns, which share the bin's noise) is
    correlated over ``hac_bins`` neighbours with Bartlett weights (Newey & West 1987).
    """
    A = np.concatenate([Ac.real, Ac.imag], axis=1).reshape(-1, Ac.shape[-1])
    bread = np.linalg.inv(A.T @ A)
    # HC2: residuals scaled by 1/sqrt(1 - leverage) (MacKinnon & White 1985)
    lev = [np.einsum("cfp,pq,cfq->cf", part, bread, part) for part in (Ac.real, Ac.imag)]
    r_re, r_im = (resid[i] / np.sqrt(np.clip(1 - lev[i], 1e-6, None)) for i in (0, 1))
    g = (np.einsum("cfp,cf->fp", Ac.real, r_re)
         + np.einsum("cfp,cf->fp", Ac.imag, r_im))               # (nb, p) scores
    meat = g.T @ g
    for lag in range(1, hac_bins + 1):
        c = g[lag:].T @ g[:-lag]
        meat += c + c.T
    vals, vecs = np.linalg.eigh(meat)                            # truncated kernel: keep PSD
    meat = (vecs * np.clip(vals, 0, None)) @ vecs.T
    nb, p = g.shape
    cov = bread @ meat @ bread
    dof = max(nb / (1 + 2 * hac_bins) - p, 1.0)                  # effective independent bins
    return stats.t.ppf(0.5 + confidence / 2, dof) * np.sqrt(np.clip(np.diag(cov), 0, None))


def fit_impedance(estimate, *, inertia_delay_s=0.0, leakage=True, weighting="model",
                  confidence=0.95, hac_bins=None) -> SecondOrderFit:
    """Fit M, B, K (n x n) to an estimate, optionally removing Welch's window leakage.

    The model of the raw estimate ``Zhat = T P^-1`` (decomposition/full/closed-loop) is,
    per frequency, with ``L1 = P1 P^-1``, ``L2 = P2 P^-1`` (window-derivative responses)::

        Zhat ~ K + B (jw I - L1) + M ((jw)^2 exp(-j w tau) I - 2 jw L1 + L2)

    exact for a continuous second-order arm under a Hann window (docs/estimation.md); the
    L terms are what the window's edges leak. ``leakage=False`` drops them, and the fit is
    then :func:`fit_second_order` element by element. Each row i of (M, B, K) is one
    linear least-squares problem over the n columns k, bins weighted by ``1/|Z_ik|`` of a
    first fit (``weighting="model"``, see :func:`fit_second_order`) or from the data
    (``coherence``, ``smoothed``: :func:`data_weights`, solved once); R^2 and confidence
    intervals as in :func:`fit_second_order`, per element.

    Parameters
    ----------
    estimate : ImpedanceEstimate
    inertia_delay_s : float [s], keyword-only
        tau of the left-limit sampling model (:func:`left_limit_delay`), 0 for none.
    leakage : bool, keyword-only
        Model (and so remove) the window leakage. Needs ``estimate.P1``, ``estimate.P2``
        (not available for the ``direct`` method).
    """
    if weighting not in WEIGHTINGS:
        raise EstimationError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    if hac_bins is None:
        hac_bins = HAC_BINS * max(1, round(getattr(estimate, "nfft_over_nperseg", 1)))
    if not leakage:
        return fit_second_order(estimate.f, estimate.Z, band_hz=estimate.band_hz,
                                inertia_delay_s=inertia_delay_s, weighting=weighting,
                                confidence=confidence, hac_bins=hac_bins,
                                coherence=estimate.coherence_Z)
    if not np.all(np.isfinite(estimate.P1)):
        raise EstimationError(f"method {estimate.method!r} gives no window-leakage responses;"
                              f" use leakage=False")
    b = estimate.band
    Z, (AM, AB, AK) = estimate.Z[b], _leakage_regressors(estimate, inertia_delay_s)
    n = estimate.n_dof
    out = {k: np.zeros((n, n)) for k in ("M", "B", "K", "M_ci", "B_ci", "K_ci", "r2")}
    for i in range(n):
        if weighting == "model":
            wts = 1.0 / np.abs(Z[:, i, :].T)
        else:
            C = estimate.coherence_Z[b]
            wts = np.array([data_weights(Z[:, i, k], weighting, C[:, i, k])
                            for k in range(n)])
        theta, half, r2 = _solve_row(Z[:, i, :], (AM, AB, AK), wts, confidence, hac_bins)
        if weighting == "model":  # second pass: weights of the first fit, not of the noise
            zfit = sum(np.einsum("fjk,j->fk", A, theta[p * n:(p + 1) * n])
                       for p, A in enumerate((AM, AB, AK)))
            theta, half, r2 = _solve_row(Z[:, i, :], (AM, AB, AK), 1.0 / np.abs(zfit.T),
                                         confidence, hac_bins)
        for p, name in enumerate(("M", "B", "K")):
            out[name][i] = theta[p * n:(p + 1) * n]
            out[f"{name}_ci"][i] = half[p * n:(p + 1) * n]
        out["r2"][i] = r2
    return SecondOrderFit(confidence=confidence, inertia_delay_s=inertia_delay_s, **out)


def _solve_row(Zi, regressors, wts, confidence, hac_bins):
    """One row i of (M, B, K): weighted LS over the n columns k of Zhat_ik.

    ``Zi`` (nb, n); ``regressors`` (A_M, A_B, A_K), each (nb, n, n); ``wts`` (n, nb).
    Returns the 3n parameters, their CI half-widths and the R^2 of each column.
    """
    nb, n = Zi.shape
    cols = [np.concatenate([A[:, j, k] * wts[k] for k in range(n)])
            for A in regressors for j in range(n)]
    Ac = np.stack(cols, axis=1)
    y = np.concatenate([Zi[:, k] * wts[k] for k in range(n)])
    A, y_r = np.vstack([Ac.real, Ac.imag]), np.concatenate([y.real, y.imag])
    theta, *_ = np.linalg.lstsq(A, y_r, rcond=None)
    resid = y_r - A @ theta
    half = _hac_half_widths(Ac.reshape(n, nb, -1), resid.reshape(2, n, nb), confidence,
                            hac_bins)
    res_c = (resid[:y.size] + 1j * resid[y.size:]).reshape(n, -1)
    r2 = np.array([1 - np.sum(np.abs(res_c[k]) ** 2) / np.sum(np.abs(wts[k] * Zi[:, k]) ** 2)
                   for k in range(n)])
    return theta, half, r2


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
