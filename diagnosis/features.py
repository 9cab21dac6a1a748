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
    (storage.find_grid, tolerant of the storage rounding; when the samples lie on no
    resolvable grid, the smallest step the storage could reveal, or a small floor).

With a :class:`StorageContext` (storage.py: how the measured numbers were stored), every
feature also gets ``var_storage``, the variance the storage rounding adds to it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy import signal as sps

from .storage import Grid, Storage, detect_storage, find_grid, resolvable_step

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
    var_storage : ndarray, shape (F,)
        Variance the storage rounding of the numbers adds (0 without a StorageContext).
    """

    labels: list
    values: np.ndarray
    var_stat: np.ndarray
    batches: np.ndarray
    var_storage: np.ndarray | None = None

    def __post_init__(self):
        if self.var_storage is None:
            self.var_storage = np.zeros_like(self.values)


#: columns whose storage is read and re-applied (those a trial carries)
STORED_SIGNALS = ("tau_delta",) + SIGNALS + ("theta_ref",)
#: the rounding-noise model (step^2 / 12, white) is taken as known to within this fraction
ROUNDING_MODEL_TOLERANCE = 0.5


@dataclass(frozen=True)
class StorageContext:
    """How one measured trial's numbers were stored, read once from the whole trial.

    Attributes
    ----------
    storage : dict signal -> tuple of Storage
        Per column (joint j at index j-1) of ``STORED_SIGNALS``.
    rounding_var : dict signal -> ndarray (n,)
        Mean rounding variance step^2 / 12 of each column [unit^2].
    resolvable : dict signal -> ndarray (n,)
        Smallest quantisation step the storage can reveal per column (grid feature).
    transforms : dict signal -> (scale, offset)
        The trial was corrected after reading (conventions.py): value = raw * scale -
        offset; the storage applies to the raw numbers.
    """

    storage: dict
    rounding_var: dict
    resolvable: dict
    transforms: dict = field(default_factory=dict)

    @classmethod
    def from_trial(cls, trial) -> "StorageContext":
        storage, var, res = {}, {}, {}
        for s in STORED_SIGNALS:
            if getattr(trial, s, None) is None:
                continue
            x = np.asarray(trial.signal(s), dtype=float)
            cols = [detect_storage(x[:, j]) for j in range(x.shape[1])]
            storage[s] = tuple(cols)
            var[s] = np.array([c.rounding_variance(x[:, j]) for j, c in enumerate(cols)])
            res[s] = np.array([resolvable_step(x[:, j], c) for j, c in enumerate(cols)])
        return cls(storage, var, res)

    def store(self, trial):
        """A copy of ``trial`` (a simulation) with every column stored as the measured
        trial's was: measured and simulated numbers then went through the same writer."""
        if all(c.kind in ("float64", "constant") for cols in self.storage.values()
               for c in cols):
            return trial
        changes = {}
        for s in SIGNALS:
            if getattr(trial, s, None) is None or s not in self.storage:
                continue
            x = np.asarray(trial.signal(s), dtype=float)
            scale, offset = self.transforms.get(s, (1.0, 0.0))
            raw = (x + offset) / scale
            stored = np.column_stack([c.apply(raw[:, j])
                                      for j, c in enumerate(self.storage[s])])
            changes[s] = stored * scale - offset
        return dataclasses.replace(trial, **changes)

    def grid(self, s: str, j: int, x) -> "Grid":
        """The quantisation grid of column s[j] (0-based j) of samples ``x`` (measured, or
        a simulation stored alike), read on the raw numbers (storage.find_grid)."""
        scale, offset = self.transforms.get(s, (1.0, 0.0))
        off = float(np.asarray(offset, dtype=float)[j]) if np.ndim(offset) else float(offset)
        raw = (np.asarray(x, dtype=float) + off) / scale
        g = find_grid(raw, self.storage[s][j], resolvable=self.resolvable[s][j] / abs(scale))
        return Grid(g.step * abs(scale), g.sigma * abs(scale), g.resolvable * abs(scale))

    def converted(self, scale: dict, offset: dict) -> "StorageContext":
        """The context of the trial corrected as value = raw * scale - offset."""
        if not scale and not offset:
            return self
        var, res, tr = dict(self.rounding_var), dict(self.resolvable), dict(self.transforms)
        for s in set(scale) | set(offset):
            a, b = float(scale.get(s, 1.0)), np.asarray(offset.get(s, 0.0), dtype=float)
            a0, b0 = tr.get(s, (1.0, 0.0))
            tr[s] = (a0 * a, b0 * a + b)
            var[s] = var[s] * a * a
            res[s] = res[s] * abs(a)
        return StorageContext(self.storage, var, res, tr)

    def describe(self) -> dict:
        """signal -> list of the storage of each joint's column (for the report)."""
        return {s: [c.describe() for c in cols] for s, cols in self.storage.items()}


def trial_features(trial, config: FeatureConfig = FeatureConfig(), *, start: int = 0,
                   stop: int | None = None, context: StorageContext | None = None,
                   perturbation: str = "tau_delta", signals: tuple = SIGNALS,
                   kinds: tuple = ("frf", "noise", "static", "grid")) -> FeatureVector:
    """Features of ``trial`` over the samples ``start:stop``.

    Parameters
    ----------
    trial : trialformat.Trial
    config : FeatureConfig
    start, stop : int
        Sample range (python slice convention).
    context : StorageContext, optional
        The *measured* trial's storage: adds the rounding variance of every feature and
        fixes the smallest resolvable grid (pass the same context for a simulation of
        it, after ``context.store(sim)``). Default: exact numbers.
    perturbation : str
        The known input the FRFs are taken from (the experiment's: ``tau_delta``, or
        ``theta_ref`` / ``theta`` for a position servo).
    signals : tuple of str
        The signals compared (the experiment's outputs).
    kinds : tuple of str
        Feature kinds computed (``static`` needs ``tau_m``, ``grid`` theta or tau_h).
    """
    sl = slice(start, stop)
    fs = trial.fs
    data = {s: np.asarray(trial.signal(s))[sl] for s in dict.fromkeys((perturbation,) + signals)}
    n = trial.n_dof
    inputs = [trial.perturbed_dof] if trial.perturbed_dof is not None else list(range(1, n + 1))
    rows = []  # (label, value, var_stat, batch values, storage variance)
    spectra = _Spectra(data, fs, config)
    for k in inputs:
        tag = f"_in{k}" if len(inputs) > 1 else ""
        rows += _spectral_rows(data, k, n, fs, config, tag, context, spectra,
                               perturbation=perturbation, signals=signals, kinds=kinds)
    if "static" in kinds and "tau_m" in signals and "theta" in data:
        rows += _static_rows(data, inputs, n, fs, config, context)
    if "grid" in kinds:
        rows += _grid_rows(data, n, config, context,
                           signals=tuple(s for s in ("theta", "tau_h") if s in signals))
    n_b = config.n_batches
    batches = np.array([r[3] if r[3] is not None else np.full(n_b, np.nan) for r in rows]).T
    return FeatureVector(labels=[r[0] for r in rows],
                         values=np.array([r[1] for r in rows], dtype=float),
                         var_stat=np.array([r[2] for r in rows], dtype=float),
                         batches=batches,
                         var_storage=np.array([r[4] for r in rows], dtype=float))


def _rounding_psd(context, s, j, fs) -> float:
    """One-sided PSD of the storage rounding noise of column s[j] [unit^2/Hz]."""
    if context is None:
        return 0.0
    return 2.0 * float(context.rounding_var[s][j - 1]) / fs


def _band_label(band) -> str:
    return f"{band[0]:g}-{band[1]:g} Hz"


class _Spectra:
    """Welch (Hann, mean removed per segment, one-sided density) auto- and cross-spectra
    of a trial's columns from one FFT per column: the same numbers as scipy.signal.welch
    and csd (tested), which recompute the FFT of x for every pair."""

    def __init__(self, data, fs, cfg):
        self.fs, self.cfg = fs, cfg
        self.window = sps.get_window("hann", cfg.nperseg)
        self.scale = 1.0 / (fs * np.sum(self.window ** 2))
        self.f = np.fft.rfftfreq(cfg.nperseg, 1.0 / fs)
        self._data, self._fft = data, {}

    def fft(self, signal, j):
        key = (signal, j)
        if key not in self._fft:
            x = self._data[signal][:, j - 1]
            step = self.cfg.nperseg - self.cfg.noverlap
            seg = np.lib.stride_tricks.sliding_window_view(x, self.cfg.nperseg)[::step]
            seg = seg - seg.mean(axis=1, keepdims=True)
            self._fft[key] = np.fft.rfft(seg * self.window, axis=1)
        return self._fft[key]

    def cross(self, a, b):
        """One-sided cross-spectral density of columns a = (signal, j) and b, conj(Fa) Fb."""
        p = np.mean(np.conj(self.fft(*a)) * self.fft(*b), axis=0) * self.scale
        p[1:] *= 2.0
        if self.cfg.nperseg % 2 == 0:
            p[-1] /= 2.0
        return p

    def auto(self, a):
        return self.cross(a, a).real


def _spectral_rows(data, k, n, fs, cfg, tag, context=None, spectra=None, *,
                   perturbation="tau_delta", signals=SIGNALS, kinds=("frf", "noise")):
    spectra = spectra or _Spectra(data, fs, cfg)
    x = data[perturbation][:, k - 1]
    sx = _rounding_psd(context, perturbation, k, fs)
    f, pxx = spectra.f, spectra.auto((perturbation, k))
    n_seg = 1 + (x.shape[0] - cfg.nperseg) // (cfg.nperseg - cfg.noverlap)
    rows = []
    for s in signals:
        for i in range(1, n + 1):
            if s == perturbation and i == k:
                continue  # the input's FRF to itself is 1
            pxy = spectra.cross((perturbation, k), (s, i))
            pyy = np.maximum(spectra.auto((s, i)), np.finfo(float).tiny)
            h = pxy / pxx
            coh = np.clip(np.abs(pxy) ** 2 / (pxx * pyy), 1e-6, 1.0)
            var_bin = (1.0 - coh) / (2.0 * n_seg * coh)
            # storage rounding: white noise of PSD sy on y (and sx on x) lowers the
            # coherence by sy / (|H|^2 Pxx): ln|H| variance (1 - coh) / (2 n coh), same form
            sy = _rounding_psd(context, s, i, fs)
            gain = np.maximum(np.abs(pxy) ** 2 / pxx, np.finfo(float).tiny)
            var_q = (sy / gain + sx / pxx) / (2.0 * n_seg)
            for band in (cfg.coherent_bands if "frf" in kinds else ()):
                sel = (f >= band[0]) & (f <= band[1])
                m_eff = max(1.0, sel.sum() / 1.5)  # Hann: neighbouring bins correlate
                var = float(np.mean(var_bin[sel]) / m_eff)
                vq = float(np.mean(var_q[sel]) / m_eff)
                if np.mean(coh[sel]) < cfg.min_coherence:
                    var = np.inf  # Welch's variance formula fails here: feature unused
                hb = h[sel]
                logmag = float(np.mean(np.log(np.abs(hb) + 1e-300)))
                phase = float(np.angle(np.mean(hb / (np.abs(hb) + 1e-300))))
                lab = _band_label(band)
                rows.append((("frf", s, i, lab, f"logmag{tag}"), logmag, var, None, vq))
                rows.append((("frf", s, i, lab, f"phase{tag}"), phase, var, None, vq))
            p_inc = pyy * (1.0 - coh)
            for band in (cfg.noise_bands if "noise" in kinds else ()):
                sel = (f >= band[0]) & (f <= band[1])
                m_eff = max(1.0, sel.sum() / 1.5)
                level = np.mean(p_inc[sel]) + cfg.noise_psd_floor[s]
                value = float(np.log(level))
                # the rounding noise sy is in both the measurement and the stored model;
                # its model (step^2/12, white) is uncertain by ROUNDING_MODEL_TOLERANCE
                vq = float((ROUNDING_MODEL_TOLERANCE * sy / level) ** 2)
                rows.append((("noise", s, i, _band_label(band), f"lnpsd{tag}"), value,
                             1.0 / (n_seg * m_eff), None, vq))
    return rows


def _static_design(theta, fs, cfg):
    sos = sps.butter(2, cfg.velocity_cutoff_hz, fs=fs, output="sos")
    th = sps.sosfiltfilt(sos, theta)
    omega = np.gradient(th) * fs
    alpha = np.gradient(omega) * fs
    return np.column_stack([np.ones_like(th), th, omega, alpha, np.tanh(omega / cfg.omega0)])


def _static_coefficients(theta, tau_m, fs, cfg):
    """(a0, a_c) of the regression of tau_m on [1, theta, omega, alpha, tanh(omega/w0)]."""
    coef, *_ = np.linalg.lstsq(_static_design(theta, fs, cfg), tau_m, rcond=None)
    return coef[0], coef[4]


def _static_rounding_var(theta, fs, cfg, var_tau) -> tuple[float, float]:
    """Variance of (a0, a_c) from white rounding noise of variance var_tau on tau_m:
    var_tau (X^T X)^-1 (least squares)."""
    if not var_tau:
        return 0.0, 0.0
    design = _static_design(theta, fs, cfg)
    try:
        cov = np.linalg.pinv(design.T @ design) * var_tau
    except np.linalg.LinAlgError:
        return np.inf, np.inf
    return float(cov[0, 0]), float(cov[4, 4])


def _static_rows(data, inputs, n, fs, cfg, context=None):
    n_samples = data["theta"].shape[0]
    edges = np.linspace(0, n_samples, cfg.n_batches + 1).astype(int)
    rows = []
    for j in range(1, n + 1):
        th, tm = data["theta"][:, j - 1], data["tau_m"][:, j - 1]
        a0, ac = _static_coefficients(th, tm, fs, cfg)
        per_batch = np.array([_static_coefficients(th[a:b], tm[a:b], fs, cfg)
                              for a, b in zip(edges[:-1], edges[1:])])
        var_tau = 0.0 if context is None else float(context.rounding_var["tau_m"][j - 1])
        v0, vc = _static_rounding_var(th, fs, cfg, var_tau)
        rows.append((("static", "tau_m", j, "0 Hz", "a0"), a0, np.nan, per_batch[:, 0], v0))
        if j in inputs:
            rows.append((("static", "tau_m", j, "0 Hz", "a_c"), ac, np.nan, per_batch[:, 1],
                         vc))
    return rows


def grid_step(x: np.ndarray, storage: Storage | None = None) -> float:
    """Quantisation step of the samples ``x`` (0 when they lie on no resolvable grid);
    ``storage`` (default: detected) is how the numbers were stored (storage.find_grid)."""
    return find_grid(x, storage).step


def _grid_rows(data, n, cfg, context=None, signals=("theta", "tau_h")):
    rows = []
    for s in signals:
        for j in range(1, n + 1):
            x = data[s][:, j - 1]
            if context is None:
                grid = find_grid(x)
            else:
                grid = context.grid(s, j - 1, x)
            # no grid: the smallest step the storage could have revealed (a bound)
            step = grid.step if grid.step > 0 else grid.resolvable
            step = max(step, cfg.grid_floor[s])
            var = 0.0
            if grid.step > 0:  # uncertainty of the step, in decades
                var = (grid.sigma / (grid.step * np.log(10.0))) ** 2
            rows.append((("grid", s, j, "-", "log10step"), float(np.log10(step)), 0.0,
                         None, var))
    return rows
