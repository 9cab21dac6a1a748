"""The arm model of the nominal simulation, estimated from the measured trials.

The human arm is unknown in a real experiment: the diagnosis estimates the impedance from
the measured trials (estimation package) and simulates with the second-order M, B, K
fitted to it. With the robust tuning the held joints move, so the ``full`` estimator
(Z = T P^-1, which uses both decomposition trials) is used; with all-joints trials the
``closed_loop`` one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import DiagnosisInputError


@dataclass
class ArmModel:
    """Second-order arm impedance fitted to the measured trials.

    Attributes
    ----------
    M, B, K : ndarray (n, n) [kg m^2], [N m s/rad], [N m/rad]
    r2 : ndarray (n, n)
        Weighted R^2 of the fit (estimation.fit_second_order).
    method : str
        Estimator used.
    """

    M: np.ndarray
    B: np.ndarray
    K: np.ndarray
    r2: np.ndarray
    method: str

    def to_dict(self) -> dict:
        return {"M_h": self.M.tolist(), "B_h": self.B.tolist(), "K_h": self.K.tolist(),
                "r2": self.r2.tolist(), "method": self.method}


def estimator_method(trials) -> str:
    """``full`` for decomposition trials (one joint each), ``closed_loop`` otherwise."""
    if all(t.perturbed_dof is not None for t in trials):
        return "full"
    if all(t.perturbed_dof is None for t in trials):
        return "closed_loop"
    raise DiagnosisInputError("trials mix single-joint and all-joints perturbations: "
                              + ", ".join(f"{t.name} (perturbed_dof={t.perturbed_dof})"
                                          for t in trials))


def estimate_arm(trials, *, nperseg: int = 8192) -> ArmModel:
    """Estimate the arm impedance from the measured trials and fit M, B, K.

    Parameters
    ----------
    trials : list of trialformat.Trial
        Measured trials (every joint perturbed by at least one of them).
    nperseg : int
        Welch segment [samples] (Table IV: 8192, overlap 3/4).
    """
    # submodules, not the package namespace: robust to what estimation/__init__ exports
    from estimation.accuracy import fit_second_order, left_limit_delay
    from estimation.estimator import estimate_impedance

    method = estimator_method(trials)
    shortest = min(t.n_samples for t in trials)
    nperseg = min(nperseg, shortest)
    try:
        est = estimate_impedance(trials, method=method, nperseg=nperseg,
                                 noverlap=3 * nperseg // 4, nfft=nperseg)
    except ValueError as exc:
        raise DiagnosisInputError(f"cannot estimate the arm impedance from the trials "
                                  f"{[t.name for t in trials]}: {exc}") from None
    fit = fit_second_order(est.f, est.Z, inertia_delay_s=left_limit_delay(est.fs))
    return ArmModel(M=np.asarray(fit.M, float), B=np.asarray(fit.B, float),
                    K=np.asarray(fit.K, float), r2=np.asarray(fit.r2, float), method=method)
