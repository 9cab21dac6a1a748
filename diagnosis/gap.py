"""The gap measure between measured and simulated trials (docs/diagnosis.md).

For each feature i of features.py, with d_i = (measured - simulated) value,

    z_i = d_i / sigma_i,   sigma_i^2 = v_i + floor_i^2,
    gap = max(0, mean_i(z_i^2) - mean_i(e_i)),   e_i = 2 v_i / sigma_i^2,

where v_i is the statistical variance of the *measured* feature (Welch variance from its
coherence and number of segments, or, for the static features, the variance over time
batches of the measured-minus-nominal difference), floor_i a fixed model tolerance, and
e_i the value z_i^2 takes on average when the difference is noise alone: the difference
of two independent realisations (measurement and a model that reproduces its noise), each
with variance v_i.
sigma is computed once per measured data set (against the nominal simulation) and then
kept fixed for every candidate model, so gaps of different effects are comparable, and a
model cannot lower its gap by adding noise (noise only adds to |d|). A trial compared
with itself has d = 0, hence gap 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .features import FeatureConfig, FeatureVector


@dataclass
class Normaliser:
    """The fixed normalisation of one measured trial's features.

    Attributes
    ----------
    sigma : ndarray, shape (F,)
    expected : ndarray, shape (F,)
        e_i, the mean z_i^2 of noise alone (two independent realisations).
    """

    sigma: np.ndarray
    expected: np.ndarray


def make_normaliser(measured: FeatureVector, nominal: FeatureVector,
                    config: FeatureConfig = FeatureConfig()) -> Normaliser:
    """Normalisation of ``measured`` features, using the nominal simulation for the
    batch variance of the static features."""
    _check_same_labels(measured, nominal)
    var = measured.var_stat.copy()
    batch = np.isnan(var)
    if batch.any():
        diff = measured.batches[:, batch] - nominal.batches[:, batch]
        var[batch] = np.var(diff, axis=0, ddof=1) / diff.shape[0]
    var = var + measured.var_storage  # the rounding of the stored numbers (storage.py)
    floor = np.array([_floor(lab, v, config) for lab, v in zip(measured.labels,
                                                                measured.values)])
    sigma2 = var + floor ** 2
    unused = ~np.isfinite(sigma2)
    expected = np.where(unused, 0.0, 2.0 * var / np.where(unused, 1.0, sigma2))
    return Normaliser(sigma=np.sqrt(sigma2), expected=expected)


def _floor(label, value, cfg: FeatureConfig) -> float:
    kind, part = label[0], label[4]
    if kind == "frf":
        return cfg.floor_phase if part.startswith("phase") else cfg.floor_logmag
    if kind == "noise":
        return cfg.floor_noise
    if kind == "grid":
        return cfg.floor_grid
    return cfg.floor_static_nm + cfg.floor_static_rel * abs(value)


def _check_same_labels(a: FeatureVector, b: FeatureVector) -> None:
    if a.labels != b.labels:
        raise ValueError("feature vectors of different layouts cannot be compared "
                         "(different joints, perturbed joint or configuration)")


def z_scores(measured: FeatureVector, simulated: FeatureVector,
             norm: Normaliser) -> np.ndarray:
    """Normalised differences z_i (phase differences wrapped to (-pi, pi])."""
    _check_same_labels(measured, simulated)
    d = measured.values - simulated.values
    is_phase = np.array([lab[4].startswith("phase") for lab in measured.labels])
    d[is_phase] = np.angle(np.exp(1j * d[is_phase]))
    return d / norm.sigma


def gap_value(z: np.ndarray, expected: np.ndarray) -> float:
    """max(0, mean(z^2) - mean(expected)) over the given features."""
    if z.size == 0:
        return 0.0
    return float(max(0.0, np.mean(z ** 2) - np.mean(expected)))


@dataclass
class GapResult:
    """Gap of a set of trials, with everything needed for a breakdown.

    Attributes
    ----------
    value : float
        The gap over all features of all trials.
    z : ndarray
        Every z_i, concatenated over trials.
    expected : ndarray
    labels : list of tuple
        ``(trial, level, kind, signal, joint, band, part)`` per feature.
    sigma : ndarray
        The normalising uncertainty of every feature (z * sigma is the difference).
    """

    value: float
    z: np.ndarray
    expected: np.ndarray
    labels: list
    sigma: np.ndarray | None = None

    @property
    def excess(self) -> float:
        """mean(z^2) - mean(expected), not clipped at 0: the objective a fit minimises
        (the clipped gap is flat wherever the model is within noise)."""
        return float(np.mean(self.z ** 2) - np.mean(self.expected)) if self.z.size else 0.0

    def breakdown(self, *keys: str) -> dict:
        """Gap per group of features, grouped by the named label fields
        (``trial``, ``level``, ``kind``, ``signal``, ``joint``, ``band``, ``part``)."""
        index = [LABEL_FIELDS.index(k) for k in keys]
        groups: dict = {}
        for pos, lab in enumerate(self.labels):
            groups.setdefault(tuple(lab[i] for i in index), []).append(pos)
        return {key: gap_value(self.z[p], self.expected[p]) for key, p in groups.items()}

    def coherent_share(self) -> float:
        """Fraction of sum(z^2) carried by the coherent (FRF) features."""
        total = float(np.sum(self.z ** 2))
        if total == 0:
            return 0.0
        frf = np.array([lab[2] == "frf" for lab in self.labels])
        return float(np.sum(self.z[frf] ** 2) / total)


LABEL_FIELDS = ("trial", "level", "kind", "signal", "joint", "band", "part")


def set_gap(pairs) -> GapResult:
    """Gap over several trials.

    Parameters
    ----------
    pairs : iterable of (name, level, measured FeatureVector, simulated FeatureVector,
        Normaliser)
    """
    zs, es, ss, labels = [], [], [], []
    for name, level, meas, sim, norm in pairs:
        zs.append(z_scores(meas, sim, norm))
        es.append(norm.expected)
        ss.append(norm.sigma)
        labels += [(name, level) + tuple(lab) for lab in meas.labels]
    z = np.concatenate(zs) if zs else np.zeros(0)
    e = np.concatenate(es) if es else np.zeros(0)
    sigma = np.concatenate(ss) if ss else np.zeros(0)
    return GapResult(value=gap_value(z, e), z=z, expected=e, labels=labels, sigma=sigma)
