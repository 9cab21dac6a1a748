"""Grouping trials into experimental conditions by their metadata, and scoring them.

A condition is (friction level, resolution level, perturbation level, tuning), read from
the declared metadata (never from file names and never from ``meta["simulation"]``).
A level that matches no reference level is shown as ``"custom"``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trialformat import reference as ref

from .accuracy import (corrected_impedance, fit_impedance, left_limit_delay, true_impedance,
                       vaf)
from .errors import EstimationError
from .estimator import as_method, estimate_impedance

#: (name, estimator method, sampling compensation, leakage removal), evaluated per
#: condition when the trials allow. "*_corrected" = both corrections (docs/estimation.md).
VARIANTS = (
    ("decomposition", "decomposition", False, False),
    ("decomposition_corrected", "decomposition", True, True),
    ("full", "full", False, False),
    ("full_sampling", "full", True, False),
    ("full_corrected", "full", True, True),
    ("closed_loop", "closed_loop", False, False),
    ("closed_loop_corrected", "closed_loop", True, True),
    ("direct", "direct", False, False),
    ("direct_sampling", "direct", True, False),
)

from .names import PAPER, RECOMMENDED  # noqa: E402  (the recommended and the paper's variant)

#: Short descriptions of the variants, for figure titles and tables.
VARIANT_LABELS = {
    "decomposition": "paper: T/R, plain fit",
    "decomposition_corrected": "paper's T/R, sampling + leakage corrected",
    "full": "T P^-1, plain fit",
    "full_sampling": "T P^-1, sampling corrected",
    "full_corrected": "recommended: T P^-1, sampling + leakage corrected",
    "closed_loop": "MIMO closed loop, all joints, plain fit",
    "closed_loop_corrected": "MIMO closed loop, all joints, corrected",
    "direct": "MIMO direct (open loop), all joints, plain fit",
    "direct_sampling": "MIMO direct (open loop), all joints, sampling corrected",
}


def variant_spec(name) -> tuple:
    """``(name, method, compensate_sampling, remove_leakage)`` of a variant in VARIANTS."""
    for spec in VARIANTS:
        if spec[0] == name:
            return spec
    raise EstimationError(f"unknown variant {name!r}; one of {[v[0] for v in VARIANTS]}")


def uses_single_joint_trials(method) -> bool:
    """True for the methods on decomposition trials, False for those on all-joints trials."""
    return method in ("decomposition", "full")


def variant_impedance(trials, variant, *, band_hz=(0.0, 15.0)):
    """The band frequencies [Hz] and the impedance [N m/rad] a variant scores.

    The raw estimate for a plain variant; the corrected estimate
    (:func:`estimation.accuracy.corrected_impedance`) for a corrected one. Trials of the
    wrong kind for the variant's method are ignored.

    Returns
    -------
    f : ndarray [Hz], shape (nb,)
    Z : ndarray [N m/rad], complex, shape (nb, n, n)
    """
    _, method, compensate, leakage = variant_spec(variant)
    use = [t for t in trials
           if (t.perturbed_dof is not None) == uses_single_joint_trials(method)]
    est = estimate_impedance(use, method=method, band_hz=band_hz)
    _, Z = _fit_and_impedance(est, compensate, leakage)
    return est.f[est.band], Z


def _fit_and_impedance(est, compensate, leakage):
    delay = left_limit_delay(est.fs) if compensate else 0.0
    fit = fit_impedance(est, inertia_delay_s=delay, leakage=leakage)
    Z = corrected_impedance(est, fit, leakage=leakage) if (compensate or leakage) \
        else est.Z[est.band]
    return fit, Z


@dataclass(frozen=True, order=True)
class Condition:
    """An experimental condition; levels are ints, or ``"custom"`` when no reference matches."""

    friction: object
    resolution: object
    perturbation: object
    tuning: str

    @property
    def label(self) -> str:
        return f"F{self.friction}R{self.resolution}P{self.perturbation}"


def condition_of(trial) -> Condition:
    """The condition a trial declares in its metadata."""
    meta = trial.meta
    fric = meta["friction"]
    arm = "3dof" if trial.n_dof == 3 else "2dof"  # reference-3dof.md: joint 3 at 0.25 x
    friction = next((lvl for lvl in range(4) if all(
        np.allclose(fric[k], ref.friction_level(lvl, trial.n_dof, arm)[k])
        for k in ("Fc", "Fs", "sigma2"))), "custom")
    sens = meta["sensors"]
    resolution = next((lvl for lvl in range(4) if all(
        np.isclose(sens[k], ref.sensor_level(lvl)[k]) for k in sens
        if k in ref.sensor_level(lvl))), "custom")
    pert = meta.get("perturbation", {}).get("level", "custom")
    ctrl = meta.get("controller") or {}  # a set-up without a controller block (one joint)
    tuning = ctrl.get("tuning") or (_tuning_from_gains(ctrl) if {"Mbar", "wn"} <= set(ctrl)
                                    else "custom")
    return Condition(friction, resolution, pert, tuning)


def _tuning_from_gains(controller) -> str:
    for name in ("reference", "robust"):
        c = ref.controller(name)
        if np.allclose(controller["Mbar"], c["Mbar"]) and np.allclose(controller["wn"], c["wn"]):
            return name
    return "custom"


def group_conditions(trials) -> dict:
    """``{Condition: [trials]}``, sorted by condition (custom levels last)."""
    groups = {}
    for t in trials:
        groups.setdefault(condition_of(t), []).append(t)
    return dict(sorted(groups.items(), key=lambda kv: tuple(
        (1, str(v)) if isinstance(v, str) else (0, v) for v in
        (kv[0].friction, kv[0].resolution, kv[0].perturbation)) + (kv[0].tuning,)))


def evaluate(trials, *, truth=None, variants=VARIANTS, band_hz=(0.0, 15.0)) -> list[dict]:
    """Score every variant that the trials allow.

    Parameters
    ----------
    trials : list of trialformat.Trial
        One condition: decomposition trials (``perturbed_dof`` set) and/or all-joints trials.
    truth : (M, B, K) or None
        True arm matrices. None (lab data): VAF is computed against the fitted
        second-order model, and parameter errors are not given.
    variants : sequence of (name, method, compensate_sampling, remove_leakage)

    Returns
    -------
    list of dict
        One row per variant: ``variant, method, compensated``, and per element ``ik``:
        ``vaf_ik`` [%], ``r2_ik``, ``coh_ik``, ``M_ik``, ``B_ik``, ``K_ik``, their CI
        half-widths ``M_ci_ik``..., and with a truth ``err_M_ik``... [%]; plus the
        summaries ``vaf_min, r2_min, coh_min, err_M_max, err_B_max, err_K_max``.
    """
    has_single = any(t.perturbed_dof is not None for t in trials)
    has_all = any(t.perturbed_dof is None for t in trials)
    rows, cache = [], {}
    for name, method, compensate, leakage in variants:
        needs_single = uses_single_joint_trials(method)
        if (needs_single and not has_single) or (not needs_single and not has_all):
            continue
        use = [t for t in trials if (t.perturbed_dof is not None) == needs_single]
        if method not in cache:
            twin = {"decomposition": "full", "full": "decomposition"}.get(method)
            cache[method] = (as_method(cache[twin], method) if twin in cache else
                             estimate_impedance(use, method=method, band_hz=band_hz))
        rows.append(score(cache[method], truth=truth, compensate=compensate,
                          leakage=leakage, name=name))
    return rows


def score(est, *, truth=None, compensate=False, leakage=False, name="") -> dict:
    """Accuracy and reliability of one estimate (see :func:`evaluate`).

    VAF is that of the raw estimate, or with corrections of the corrected estimate
    (:func:`estimation.accuracy.corrected_impedance`).
    """
    fit, Z = _fit_and_impedance(est, compensate, leakage)
    b = est.band
    if truth is None:
        reference_Z = true_impedance(est.f[b], fit.M, fit.B, fit.K)
    else:
        reference_Z = true_impedance(est.f[b], *truth)
    row = {"variant": name or est.method, "method": est.method, "compensated": compensate,
           "leakage_removed": leakage, "n_segments": est.n_segments}
    per = {"vaf": vaf(Z, reference_Z), "r2": fit.r2, "coh": est.mean_coherence(),
           "M": fit.M, "B": fit.B, "K": fit.K, "M_ci": fit.M_ci, "B_ci": fit.B_ci,
           "K_ci": fit.K_ci}
    if truth is not None:
        for k, v in fit.relative_errors(*truth).items():
            per[f"err_{k}"] = 100 * v
    n = est.n_dof
    for key, arr in per.items():
        for i in range(n):
            for k in range(n):
                row[f"{key}_{i + 1}{k + 1}"] = float(arr[i, k])
    row.update(vaf_min=float(per["vaf"].min()), r2_min=float(per["r2"].min()),
               coh_min=float(per["coh"].min()))
    if truth is not None:
        row.update({f"err_{p}_max": float(np.abs(per[f"err_{p}"]).max()) for p in "MBK"})
    return row
