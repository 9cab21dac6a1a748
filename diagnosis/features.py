"""Features of a trial that the gap measure compares (docs/diagnosis.md, "Gap measure").

The same function computes them on a measured and on a simulated trial. Four kinds:

``frf``
    Coherent part: the FRF from the perturbation ``tau_delta[k]`` to each signal (theta,
    tau_h, tau_m) of each joint, as band means of ln|H| (``part="logmag"``) and of the
    phase (``part="phase"`` [rad]) in the coherent bands (Welch, Hann, ``nperseg``).
``noise``
    Incoherent part: ln of the band mean of the spectrum not coherent with the
    perturbation, Pyy (1 - coherence), per signal, joint and noise band.
``static``
    Low-frequency part of the motor torque: the least-squares fit
    tau_m[j] ~ a0 + a1 theta + a2 omega + a3 alpha + a_c tanh(omega / omega0) of each joint;
    ``a0`` [N m] (offsets such as gravity) for every joint and ``a_c`` [N m] (Coulomb-like
    friction compensation) for the perturbed joint. Also computed per time batch.
``grid``
    The sample grid: log10 of the quantisation step seen in theta [rad] and tau_h [N m]
    (0 when the samples lie on no grid, then a small floor).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal as sps

SIGNALS = ("theta", "tau_h", "tau_m")


@dataclass(frozen=True)
class FeatureConfig:
    """Options of the features and of their uncertainty floors (kept fixed: the gap
    measure is defined by them).

    Attributes
    ----------
    nperseg, noverlap : int
        Welch segment and overlap [samples] (Hann window, mean removed).
    coherent_bands, noise_bands : tuple of (float, float)
        Frequency bands [Hz], lower edge inclusive, upper edge inclusive.
    n_batches : int
        Time batches for the uncertainty of the ``static`` features.
    floor_logmag, floor_phase, floor_noise, floor_grid : float
        Model-tolerance floors of the normalising uncertainty: ln-units, rad, ln-units,
        decades. They are what a difference must exceed to count when the data are
        noise-free; calibrated on nominal-vs-nominal comparisons (docs/diagnosis.md).
    floor_static_nm, floor_static_rel : float
        Floor of the ``static`` features: absolute [N m] plus relative to |value|.
    noise_psd_floor : dict
        Absolute floor added to each incoherent spectrum before the log [unit^2/Hz].
    grid_floor : dict
        Smallest grid step reported per signal [rad or N m].
    min_coherence : float
        A coherent feature whose band-mean coherence (measured trial) is below this is
        given an infinite uncertainty: the Welch variance formula does not hold there.
    velocity_cutoff_hz, omega0 : float
        Low-pass [Hz] used to differentiate theta, and the tanh velocity scale [rad/s].
    """

    nperseg: int = 1024
    noverlap: int = 512
    coherent_bands: tuple = ((1.0, 3.0), (3.0, 6.0), (6.0, 10.0), (10.0, 15.0), (15.0, 25.0),
                             (25.0, 40.0))
    noise_bands: tuple = ((1.0, 15.0), (15.0, 60.0), (60.0, 200.0), (200.0, 500.0))
    n_batches: int = 4
    floor_logmag: float = 0.02
    floor_phase: float = 0.02
    floor_noise: float = 0.15
    floor_grid: float = 0.02
    floor_static_nm: float = 0.004
    floor_static_rel: float = 0.03
    noise_psd_floor: dict = field(default_factory=lambda: {
        "theta": 1e-14, "tau_h": 2e-9, "tau_m": 2e-9})
    grid_floor: dict = field(default_factory=lambda: {"theta": 1e-8, "tau_h": 1e-6})
    min_coherence: float = 0.5
    velocity_cutoff_hz: float = 20.0
    omega0: float = 0.05

    def to_dict(self) -> dict:
        return {k: (list(map(list, v)) if k.endswith("bands") else v)
                for k, v in self.__dict__.items()}


@dataclass
class FeatureVector:
    """Features of one trial (or one time segment of it).

    Attributes
    ----------
    labels : list of tuple
        ``(kind, signal, joint, band, part)`` per feature; joint 1-based, band a string.
    values : ndarray, shape (F,)
    var_stat : ndarray, shape (F,)
        Analytic statistical variance of the value (Welch), NaN where the variance comes
        from time batches instead, inf where the feature is not reliable.
    batches : ndarray, shape (n_batches, F)
        Per-batch values of the ``static`` features (NaN for the others).
    """

    labels: list
    values: np.ndarray
    var_stat: np.ndarray
    batches: np.ndarray


def trial_features(trial, config: FeatureConfig = FeatureConfig(), *, start: int = 0,
                   stop: int | None = None) -> FeatureVector:
    """Features of ``trial`` over the samples ``start:stop``.

    Parameters
    ----------
    trial : trialformat.Trial
    config : FeatureConfig
    start, stop : int
        Sample range (python slice convention).
    """
    sl = slice(start, stop)
    fs = trial.fs
    data = {s: np.asarray(trial.signal(s))[sl] for s in ("tau_delta",) + SIGNALS}
    n = data["theta"].shape[1]
    inputs = [trial.perturbed_dof] if trial.perturbed_dof is not None else list(range(1, n + 1))
    rows = []  # (label, value, var_stat, batch values)
    for k in inputs:
        tag = f"_in{k}" if len(inputs) > 1 else ""
        rows += _spectral_rows(data, k, n, fs, config, tag)
    rows += _static_rows(data, inputs, n, fs, config)
    rows += _grid_rows(data, n, config)
    n_b = config.n_batches
    batches = np.array([r[3] if r[3] is not None else np.full(n_b, np.nan) for r in rows]).T
    return FeatureVector(labels=[r[0] for r in rows],
                         values=np.array([r[1] for r in rows], dtype=float),
                         var_stat=np.array([r[2] for r in rows], dtype=float),
                         batches=batches)


def _band_label(band) -> str:
    return f"{band[0]:g}-{band[1]:g} Hz"


def _spectral_rows(data, k, n, fs, cfg, tag):
    x = data["tau_delta"][:, k - 1]
    kw = dict(fs=fs, window="hann", nperseg=cfg.nperseg, noverlap=cfg.noverlap)
    f, pxx = sps.welch(x, **kw)
    n_seg = 1 + (x.shape[0] - cfg.nperseg) // (cfg.nperseg - cfg.noverlap)
    rows = []
    for s in SIGNALS:
        for i in range(1, n + 1):
            y = data[s][:, i - 1]
            _, pxy = sps.csd(x, y, **kw)
            _, pyy = sps.welch(y, **kw)
            pyy = np.maximum(pyy, np.finfo(float).tiny)
            h = pxy / pxx
            coh = np.clip(np.abs(pxy) ** 2 / (pxx * pyy), 1e-6, 1.0)
            var_bin = (1.0 - coh) / (2.0 * n_seg * coh)
            for band in cfg.coherent_bands:
                sel = (f >= band[0]) & (f <= band[1])
                m_eff = max(1.0, sel.sum() / 1.5)  # Hann: neighbouring bins correlate
                var = float(np.mean(var_bin[sel]) / m_eff)
                if np.mean(coh[sel]) < cfg.min_coherence:
                    var = np.inf  # Welch's variance formula fails here: feature unused
                hb = h[sel]
                logmag = float(np.mean(np.log(np.abs(hb) + 1e-300)))
                phase = float(np.angle(np.mean(hb / (np.abs(hb) + 1e-300))))
                lab = _band_label(band)
                rows.append((("frf", s, i, lab, f"logmag{tag}"), logmag, var, None))
                rows.append((("frf", s, i, lab, f"phase{tag}"), phase, var, None))
            p_inc = pyy * (1.0 - coh)
            for band in cfg.noise_bands:
                sel = (f >= band[0]) & (f <= band[1])
                m_eff = max(1.0, sel.sum() / 1.5)
                value = float(np.log(np.mean(p_inc[sel]) + cfg.noise_psd_floor[s]))
                rows.append((("noise", s, i, _band_label(band), f"lnpsd{tag}"), value,
                             1.0 / (n_seg * m_eff), None))
    return rows


def _static_coefficients(theta, tau_m, fs, cfg):
    """(a0, a_c) of the regression of tau_m on [1, theta, omega, alpha, tanh(omega/w0)]."""
    sos = sps.butter(2, cfg.velocity_cutoff_hz, fs=fs, output="sos")
    th = sps.sosfiltfilt(sos, theta)
    omega = np.gradient(th) * fs
    alpha = np.gradient(omega) * fs
    design = np.column_stack([np.ones_like(th), th, omega, alpha, np.tanh(omega / cfg.omega0)])
    coef, *_ = np.linalg.lstsq(design, tau_m, rcond=None)
    return coef[0], coef[4]


def _static_rows(data, inputs, n, fs, cfg):
    n_samples = data["theta"].shape[0]
    edges = np.linspace(0, n_samples, cfg.n_batches + 1).astype(int)
    rows = []
    for j in range(1, n + 1):
        th, tm = data["theta"][:, j - 1], data["tau_m"][:, j - 1]
        a0, ac = _static_coefficients(th, tm, fs, cfg)
        per_batch = np.array([_static_coefficients(th[a:b], tm[a:b], fs, cfg)
                              for a, b in zip(edges[:-1], edges[1:])])
        rows.append((("static", "tau_m", j, "0 Hz", "a0"), a0, np.nan, per_batch[:, 0]))
        if j in inputs:
            rows.append((("static", "tau_m", j, "0 Hz", "a_c"), ac, np.nan, per_batch[:, 1]))
    return rows


def grid_step(x: np.ndarray, *, rtol: float = 1e-6) -> float:
    """Quantisation step of the samples ``x`` (0 when they lie on no grid).

    The step is the smallest positive difference between distinct values; the samples
    are on that grid when every difference between distinct values is an integer
    multiple of it (within ``rtol``). Exact for r * round(x / r) data.
    """
    u = np.unique(np.asarray(x, dtype=float))
    if u.size < 3:
        return 0.0
    du = np.diff(u)
    step = du.min()
    if step <= 0:
        return 0.0
    ratio = du / step
    if ratio.max() > 1e7 or np.max(np.abs(ratio - np.round(ratio))) > rtol:
        return 0.0
    return float(step)


def _grid_rows(data, n, cfg):
    rows = []
    for s in ("theta", "tau_h"):
        for j in range(1, n + 1):
            step = grid_step(data[s][:, j - 1])
            rows.append((("grid", s, j, "-", "log10step"),
                         float(np.log10(max(step, cfg.grid_floor[s]))), 0.0, None))
    return rows
