"""Impedance estimators on trials: the paper's decomposition estimator and three others.

Methods (docs/estimation.md has the derivations):

``"decomposition"`` (paper, eqs. 15-18)
    One trial per joint k (``perturbed_dof = k``). ``R_kk = G(d_k, theta_k) / G(d_k, d_k)``,
    ``T_ik = G(d_k, tau_h_i) / G(d_k, d_k)``, ``Z_ik = T_ik / R_kk``. Assumes the held
    joints do not move; when they do, ``Z_ik`` is biased by ``Z_ij P_jk / P_kk``.
``"full"``
    The same trials, but the full response from the perturbations to the angles,
    ``P_ik = G(d_k, theta_i) / G(d_k, d_k)`` (column k from trial k), so that
    ``T = Z P`` holds exactly and ``Z = T P^-1``: no assumption on the held joints.
``"closed_loop"`` (de Vlugt 2003, Palazzolo 2007)
    Trials with every joint perturbed at once by independent perturbations
    (``perturbed_dof = null``); the perturbation is the instrument:
    ``P = G_{d theta} G_{dd}^-1``, ``T = G_{d tau} G_{dd}^-1`` (MIMO H1), ``Z = T P^-1``.
``"direct"`` (open loop, Perreault 1999 style)
    The same all-joints trials, measured angles as input: ``Z = G_{theta tau} G_{theta theta}^-1``
    (MIMO H1 from theta to tau_h). Biased by noise on theta and by feedback.

Position-perturbation trials (``perturbation.kind = "position"``, log-format.md) use the
recorded reference ``theta_ref[k]`` as the perturbation in place of ``tau_delta[k]``, so
``"decomposition"``/``"full"`` give ``Z_ik = G(ref_k, tau_i) / G(ref_k, theta_k)`` (column k);
without a recorded reference only ``"direct"`` (angle to torque) applies.
:func:`default_method` picks the method a set of trials supports.

Spectral conventions are those of :mod:`estimation.spectral` (Table IV by default).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from . import spectral
from .errors import EstimationError
from .names import METHODS
from .spectral import WelchOptions

BAND_HZ = (0.0, 15.0)


@dataclass
class ImpedanceEstimate:
    """An impedance estimate with its building blocks and reliability measures.

    Attributes
    ----------
    f : ndarray [Hz], shape (nf,)
    Z : ndarray [N m/rad], complex, shape (nf, n, n)
        ``Z[:, i, k]`` is the estimate of Z_ik (torque at joint i per angle of joint k).
    P : ndarray [rad/(N m)], complex, shape (nf, n, n)
        Response from perturbation k to angle i (``R_kk`` on the diagonal); NaN for the
        ``direct`` method, which does not use the perturbation.
    T : ndarray [-], complex, shape (nf, n, n)
        Response from perturbation k to measured torque i (NaN for ``direct``).
    coherence_P, coherence_T : ndarray [-], shape (nf, n, n)
        Ordinary coherence of each SIMO path d_k -> theta_i, d_k -> tau_h_i (decomposition
        trials), or multiple coherence of the output on all inputs (all-joints trials;
        then equal along k).
    P1, P2 : ndarray, complex, shape (nf, n, n)
        Window-leakage responses: as P, with the angle windowed by the first and second
        time derivatives of the Hann window [rad/(N m s)], [rad/(N m s^2)]
        (:func:`estimation.spectral.window_derivative_spectra`); NaN for ``direct``.
        They let :func:`estimation.accuracy.fit_impedance` remove Welch's leakage.
    coherence_Z : ndarray [-], shape (nf, n, n)
        Derived coherence of each Z_ik (docs/estimation.md): ``coherence_T[:, i, k] *
        coherence_P[:, k, k]``, the coherence the direct estimate from theta_k to tau_h_i
        would have with the same, uncorrelated, output noise.
    method : str
    fs : float [Hz]
    band_hz : tuple of float
        Evaluation band ``(f_lo, f_hi)``: bins with ``f_lo < f <= f_hi``.
    nfft_over_nperseg : float
        Zero-padding factor of the Welch FFT (sets the bin correlation of the fit's CIs).
    n_segments : int
        Welch segments averaged per joint (smallest over the joints).
    trials : list of str
        Names of the trials used.
    """

    f: np.ndarray
    Z: np.ndarray
    P: np.ndarray
    T: np.ndarray
    coherence_P: np.ndarray
    coherence_T: np.ndarray
    coherence_Z: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    method: str
    fs: float
    band_hz: tuple = BAND_HZ
    nfft_over_nperseg: float = 1.0
    n_segments: int = 0
    trials: list = field(default_factory=list)

    @property
    def n_dof(self) -> int:
        return int(self.Z.shape[1])

    @property
    def R(self) -> np.ndarray:
        """Diagonal responses ``R_kk`` [rad/(N m)], shape (nf, n)."""
        return np.diagonal(self.P, axis1=1, axis2=2).copy()

    @property
    def band(self) -> np.ndarray:
        """Boolean mask of the evaluation band, ``f_lo < f <= f_hi``."""
        return band_mask(self.f, self.band_hz)

    def mean_coherence(self) -> np.ndarray:
        """Band mean of the derived coherence of each Z_ik, shape (n, n)."""
        return self.coherence_Z[self.band].mean(axis=0)


def perturbation_of(trial) -> np.ndarray:
    """The known perturbation of a trial, (N, n): ``tau_delta`` [N m] or ``theta_ref`` [rad].

    Raises EstimationError for a position trial without a recorded reference.
    """
    if trial.perturbation_kind != "position":
        return trial.tau_delta
    if trial.theta_ref is None:
        raise EstimationError(f"trial {trial.name!r} is a position perturbation without a "
                              f"recorded reference (theta_ref): only method='direct' "
                              f"(angle to torque) applies")
    return trial.theta_ref


def default_method(trials) -> str:
    """The method the trials support, bias-free first (docs/estimation.md).

    ``"full"`` for single-joint torque trials or position trials with a recorded reference
    (equal to ``"decomposition"`` for one joint), ``"closed_loop"`` for all-joints trials,
    ``"direct"`` for position trials without a reference.
    """
    trials = list(trials)
    if any(t.perturbation_kind == "position" and t.theta_ref is None for t in trials):
        return "direct"
    if all(t.perturbed_dof is None for t in trials) and trials[0].n_dof > 1:
        return "closed_loop"
    return "full"


def band_mask(f, band_hz=BAND_HZ) -> np.ndarray:
    """True for the bins with ``band_hz[0] < f <= band_hz[1]`` [Hz]."""
    f = np.asarray(f)
    return (f > band_hz[0]) & (f <= band_hz[1])


def estimate_impedance(trials, *, method="decomposition", band_hz=BAND_HZ,
                       nperseg=spectral.NPERSEG, noverlap=spectral.NOVERLAP,
                       nfft=spectral.NFFT, window=spectral.WINDOW,
                       detrend=spectral.DETREND) -> ImpedanceEstimate:
    """Estimate the joint impedance matrix from trials.

    Parameters
    ----------
    trials : sequence of trialformat.Trial
        ``decomposition``/``full``: at least one trial per joint with ``perturbed_dof = k``;
        ``closed_loop``/``direct``: trials with ``perturbed_dof = None``. Several trials of
        one joint (seeds, repeats) are pooled by averaging their Welch spectra.
    method : {"decomposition", "full", "closed_loop", "direct"}, keyword-only
    band_hz : (float, float), keyword-only
        Evaluation band [Hz] stored with the estimate (used by the accuracy measures).
    nperseg, noverlap, nfft, window, detrend : keyword-only
        Welch options (Table IV by default).

    Returns
    -------
    ImpedanceEstimate

    Raises
    ------
    EstimationError
        Unknown method, trials of the wrong kind, a joint without a trial, mixed fs or n.
    """
    if method not in METHODS:
        raise EstimationError(f"method must be one of {METHODS}, got {method!r}")
    trials = list(trials)
    if not trials:
        raise EstimationError("no trial given")
    options = WelchOptions(nperseg=nperseg, noverlap=noverlap, nfft=nfft, window=window,
                           detrend=detrend)
    fs, n = _common_rate_and_size(trials)
    if method in ("closed_loop", "direct") and n > 1:
        _check_mimo_segments(trials, n, options)
    try:
        if method in ("decomposition", "full"):
            f, P, T, cP, cT, P1, P2, nseg = _decomposed_responses(trials, n, fs, options)
        else:
            f, P, T, cP, cT, P1, P2, nseg = _mimo_responses(trials, n, fs, options, method)
        if method == "decomposition":
            Z = T / np.diagonal(P, axis1=1, axis2=2)[:, None, :]
        elif method == "direct":
            Z = T  # _mimo_responses put the theta -> tau_h H1 estimate there
            T = np.full_like(Z, np.nan)
        else:
            Z = np.linalg.solve(np.swapaxes(P, 1, 2), np.swapaxes(T, 1, 2)).swapaxes(1, 2)
    except np.linalg.LinAlgError as exc:
        raise EstimationError(
            f"trials {[t.name for t in trials]}: the {method} estimate is singular ({exc}): "
            f"the trials do not excite every joint independently over "
            f"{sum(options.n_segments(t.n_samples) for t in trials)} Welch segment(s) of "
            f"{options.nperseg} samples") from None
    cZ = cT * np.diagonal(cP, axis1=1, axis2=2)[:, None, :]
    return ImpedanceEstimate(f=f, Z=Z, P=P, T=T, coherence_P=cP, coherence_T=cT,
                             coherence_Z=cZ, P1=P1, P2=P2, method=method, fs=fs,
                             band_hz=tuple(band_hz), nfft_over_nperseg=nfft / nperseg,
                             n_segments=nseg, trials=[t.name for t in trials])


def as_method(estimate: ImpedanceEstimate, method: str) -> ImpedanceEstimate:
    """The ``decomposition`` estimate from a ``full`` one or back: both use the same
    per-joint responses P and T, only Z differs (T/R_kk or T P^-1); no spectra recomputed."""
    pair = ("decomposition", "full")
    if estimate.method not in pair or method not in pair:
        raise EstimationError(f"only {pair} share their spectra; got {estimate.method!r} -> "
                              f"{method!r}")
    if method == "decomposition":
        Z = estimate.T / np.diagonal(estimate.P, axis1=1, axis2=2)[:, None, :]
    else:
        Z = np.linalg.solve(np.swapaxes(estimate.P, 1, 2),
                            np.swapaxes(estimate.T, 1, 2)).swapaxes(1, 2)
    return replace(estimate, Z=Z, method=method)


#: Welch averages below which the coherence and the intervals are not trustworthy (one
#: segment gives coherence 1 by construction).
MIN_AVERAGES = 8


def nperseg_for(n_samples: int, options: WelchOptions, averages: int = MIN_AVERAGES) -> int:
    """Largest power-of-two Welch segment giving ``averages`` segments of ``n_samples``
    at the options' overlap fraction (a value to suggest to the user)."""
    step = 1.0 - options.noverlap / options.nperseg
    longest = n_samples / (1.0 + (averages - 1) * step)
    return int(2 ** max(4, int(np.floor(np.log2(max(longest, 16))))))


def _check_mimo_segments(trials, n, options) -> None:
    """Refuse an all-joints (MIMO) estimate over fewer Welch segments than joints: its
    n x n cross-spectral matrix of the perturbations is then singular at every frequency."""
    nseg = sum(max(options.n_segments(t.n_samples), 0) for t in trials)
    if nseg < n:
        shortest = min(t.n_samples for t in trials)
        raise EstimationError(
            f"trials {[t.name for t in trials]}: {nseg} Welch segment(s) of "
            f"{options.nperseg} samples cannot separate {n} joints perturbed at once (the "
            f"perturbations' cross-spectral matrix is singular with fewer than {n} "
            f"segments; {MIN_AVERAGES} or more for a usable coherence): use --nperseg "
            f"{nperseg_for(shortest, options)} or longer trials")


def _common_rate_and_size(trials) -> tuple[float, int]:
    fs, n = trials[0].fs, trials[0].n_dof
    for t in trials[1:]:
        if t.fs != fs or t.n_dof != n:
            raise EstimationError(f"trial {t.name!r} has fs={t.fs} Hz, n_dof={t.n_dof} but "
                                  f"trial {trials[0].name!r} has fs={fs} Hz, n_dof={n}")
    return fs, n


def _pooled(trials, fs, options, x_of, y_of, leak_of=None):
    """Welch spectra of x and y pooled over trials, weighted by their segment counts.

    Returns ``(f, Gxx (nf, p, p), Gxy (nf, p, q), Gyy_diag (nf, q), G1, G2, n_segments)``,
    G1 and G2 the window-derivative cross-spectra of x with ``leak_of(trial)`` (or None).
    """
    total, acc, nan_shape = 0, None, None
    for trial in trials:
        x, y = x_of(trial), y_of(trial)
        p = x.shape[1]
        f, G = spectral.spectral_matrix(np.hstack([x, y]), fs=fs, **options.__dict__)
        gxx, gxy = G[:, :p, :p], G[:, :p, p:]
        gyy = np.real(np.diagonal(G[:, p:, p:], axis1=1, axis2=2))
        w = options.n_segments(x.shape[0])
        parts = [w * gxx, w * gxy, w * gyy]
        if leak_of is not None and (options.window != "hann" or options.detrend != "constant"):
            nan_shape = gxy.shape[:2] + (leak_of(trial).shape[1],)
            leak_of = None  # the leakage model is that of a Hann window: P1, P2 left NaN
        if leak_of is not None:
            _, _, g1, g2 = spectral.window_derivative_spectra(
                x, leak_of(trial), fs=fs, nperseg=options.nperseg,
                noverlap=options.noverlap, nfft=options.nfft, with_plain=False)
            parts += [w * g1, w * g2]
        acc = parts if acc is None else [a + p for a, p in zip(acc, parts)]
        total += w
    acc = [a / total for a in acc]
    if leak_of is not None:
        g1, g2 = acc[3:]
    elif nan_shape is not None:
        g1 = g2 = np.full(nan_shape, np.nan, complex)
    else:
        g1 = g2 = None
    return (f, *acc[:3], g1, g2, total)


def _decomposed_responses(trials, n, fs, options):
    by_joint = {k: [t for t in trials if t.perturbed_dof == k] for k in range(1, n + 1)}
    others = [t.name for t in trials if t.perturbed_dof is None]
    if others:
        raise EstimationError(f"decomposition trials must perturb one joint; trial(s) "
                              f"{others} have perturbed_dof=null (use method='closed_loop')")
    missing = [k for k, group in by_joint.items() if not group]
    if missing:
        raise EstimationError(f"no trial perturbs joint(s) {missing}: the decomposition "
                              f"needs one trial per joint 1..{n}, got "
                              f"{[t.name for t in trials]}")
    P = T = cP = cT = P1 = P2 = None
    segments = []
    for k, group in by_joint.items():
        f, gdd, gdy, gyy, g1, g2, nseg = _pooled(
            group, fs, options, lambda t, k=k: perturbation_of(t)[:, k - 1:k],
            lambda t: np.hstack([t.theta, t.tau_h]), lambda t: t.theta)
        if P is None:
            shape = (f.size, n, n)
            P, T, P1, P2 = (np.empty(shape, complex) for _ in range(4))
            cP, cT = np.empty(shape), np.empty(shape)
        gdd, gdy = gdd[:, 0, 0].real, gdy[:, 0, :]
        H = gdy / gdd[:, None]
        P1[:, :, k - 1], P2[:, :, k - 1] = g1[:, 0, :] / gdd[:, None], g2[:, 0, :] / gdd[:, None]
        C = spectral.ordinary_coherence(gdy, gdd[:, None], gyy)
        P[:, :, k - 1], T[:, :, k - 1] = H[:, :n], H[:, n:]
        cP[:, :, k - 1], cT[:, :, k - 1] = C[:, :n], C[:, n:]
        segments.append(nseg)
    return f, P, T, cP, cT, P1, P2, min(segments)


def _mimo_responses(trials, n, fs, options, method):
    if method == "direct":
        return _direct_responses(trials, n, fs, options)
    single = [t.name for t in trials if t.perturbed_dof is not None]
    if single and n > 1:
        raise EstimationError(f"method {method!r} needs trials with every joint perturbed at "
                              f"once (perturbed_dof=null); trial(s) {single} perturb one joint")
    f, gdd, gdy, gyy, g1, g2, nseg = _pooled(trials, fs, options, perturbation_of,
                                             lambda t: np.hstack([t.theta, t.tau_h]),
                                             lambda t: t.theta)
    H = np.swapaxes(np.linalg.solve(gdd, gdy), 1, 2)  # (nf, 2n, n): Y = H D
    P1 = np.swapaxes(np.linalg.solve(gdd, g1), 1, 2)
    P2 = np.swapaxes(np.linalg.solve(gdd, g2), 1, 2)
    cmult = _multiple_coherence(gdd, gdy, gyy)         # (nf, 2n)
    P, T = H[:, :n, :], H[:, n:, :]
    cP = np.repeat(cmult[:, :n, None], n, axis=2)
    cT = np.repeat(cmult[:, n:, None], n, axis=2)
    return f, P, T, cP, cT, P1, P2, nseg


def _direct_responses(trials, n, fs, options):
    """MIMO H1 from the measured angles to the torques, spectra pooled over the trials.

    Any trials whose angles together excite every joint (all-joints trials, one trial per
    joint, or one trial of a 1-joint limb).
    """
    f, gtt, gty, gyy, *_ , nseg = _pooled(trials, fs, options, lambda t: t.theta,
                                          lambda t: t.tau_h)
    cond = np.linalg.cond(gtt[1:])
    if not np.all(np.isfinite(cond)) or cond.max() > 1e12:
        raise EstimationError(f"method 'direct': the angles of trials "
                              f"{[t.name for t in trials]} do not excite every joint "
                              f"(angle spectral matrix singular)")
    T = np.swapaxes(np.linalg.solve(gtt, gty), 1, 2)  # theta -> tau_h, (nf, n, n)
    cT = np.repeat(_multiple_coherence(gtt, gty, gyy)[:, :, None], n, axis=2)
    cP = np.broadcast_to(np.eye(n), cT.shape).copy()  # theta is the input: no P path
    P = P1 = P2 = np.full_like(T, np.nan)
    return f, P, T, cP, cT, P1, P2, nseg


def _multiple_coherence(gxx, gxy, gyy):
    """Multiple coherence of each output on all inputs: ``G_yx G_xx^-1 G_xy / G_yy``."""
    explained = np.einsum("fab,fab->fb", gxy.conj(), np.linalg.solve(gxx, gxy)).real
    with np.errstate(invalid="ignore", divide="ignore"):
        c = explained / gyy
    return np.where(gyy > 0, c, 0.0)
