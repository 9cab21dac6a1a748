"""The arm model of the nominal simulation, estimated from the measured trials.

The human arm is unknown in a real experiment: the diagnosis estimates the impedance from
the measured trials (estimation package) and simulates with the second-order M, B, K
fitted to it. With the robust tuning the held joints move, so the ``full`` estimator
(Z = T P^-1, which uses both decomposition trials) is used; with all-joints trials the
``closed_loop`` one; with position trials the estimator ``armimp estimate`` picks
(``full`` from a recorded reference, else ``direct``, theta to tau_h).

The fit handles sampling and leakage as ``armimp estimate`` does (estimation.lab.analyse):
the left-limit delay of the inertial term only for trials that declare
``sensors.torque_sampling = "left_limit"`` (or were simulated by this project's
orchestrator), the Hann window's leakage modelled wherever the method allows it.
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
    f: np.ndarray | None = None
    Z: np.ndarray | None = None
    fs: float = 1000.0
    #: delay of the inertial term of the fit [s] (None: the left-limit delay 0.5 / fs)
    inertia_delay_s: float | None = None
    leakage: bool = False
    ci: dict | None = None

    @property
    def sampling_delay(self) -> float:
        """The inertial-term delay of the fit [s] (estimation.accuracy.left_limit_delay
        when the trials were sampled at the left limit, 0 when instantaneously)."""
        return 0.5 / self.fs if self.inertia_delay_s is None else self.inertia_delay_s

    def to_dict(self) -> dict:
        out = {"M_h": self.M.tolist(), "B_h": self.B.tolist(), "K_h": self.K.tolist(),
               "r2": self.r2.tolist(), "method": self.method,
               "corrections": {"left_limit_sampling": self.sampling_delay > 0,
                               "inertia_delay_s": self.sampling_delay,
                               "window_leakage": self.leakage}}
        if self.ci is not None:
            out["ci95"] = {k: np.asarray(v).tolist() for k, v in self.ci.items()}
        return out


def estimator_method(trials) -> str:
    """``full`` for decomposition trials (one joint each), ``closed_loop`` for all-joints
    trials; for position trials ``full`` with a recorded reference, else ``direct``."""
    if any(t.perturbation_kind == "position" for t in trials):
        from estimation.estimator import default_method
        return default_method(trials)
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
    from estimation.accuracy import fit_impedance, left_limit_delay
    from estimation.errors import EstimationError
    from estimation.estimator import estimate_impedance
    from estimation.lab import left_limit_sampled

    method = estimator_method(trials)
    shortest = min(t.n_samples for t in trials)
    nperseg = min(nperseg, shortest)
    try:
        est = estimate_impedance(trials, method=method, nperseg=nperseg,
                                 noverlap=3 * nperseg // 4, nfft=nperseg)
    except ValueError as exc:
        raise DiagnosisInputError(f"cannot estimate the arm impedance from the trials "
                                  f"{[t.name for t in trials]}: {exc}") from None
    delay = left_limit_delay(est.fs) if left_limit_sampled(trials) else 0.0
    leakage = method != "direct"
    try:
        fit = fit_impedance(est, inertia_delay_s=delay, leakage=leakage)
    except EstimationError:
        leakage = False
        fit = fit_impedance(est, inertia_delay_s=delay, leakage=False)
    return _model(fit, est.f, est.Z, est.fs, method, leakage)


def _model(fit, f, Z, fs, method, leakage) -> ArmModel:
    shape = np.shape(np.atleast_2d(fit.M))
    as2 = lambda v: np.asarray(v, float).reshape(shape)  # noqa: E731
    return ArmModel(M=as2(fit.M), B=as2(fit.B), K=as2(fit.K), r2=as2(fit.r2),
                    method=method, f=np.asarray(f), Z=np.asarray(Z), fs=fs,
                    inertia_delay_s=float(fit.inertia_delay_s), leakage=leakage,
                    ci={"M_h": as2(fit.M_ci), "B_h": as2(fit.B_ci), "K_h": as2(fit.K_ci)})


def _fit(f, Z, fs, method, inertia_delay_s=0.0) -> ArmModel:
    from estimation.accuracy import fit_second_order
    fit = fit_second_order(f, Z, inertia_delay_s=inertia_delay_s)
    return _model(fit, f, Z, fs, method, False)


def link_inertia(meta: dict) -> np.ndarray:
    """Link-side inertia of the declared 2-joint robot at the posture, without the motor
    inertias Jm [kg m^2] (reference.md section 3: M_r(q) - diag(Jm))."""
    r = meta["robot"]
    q2 = np.radians(meta["posture_deg"][1])
    a1 = r["I1"] + r["m1"] * r["lc1"] ** 2 + r["I2"] + r["m2"] * (r["L1"] ** 2 + r["lc2"] ** 2)
    a2 = r["I2"] + r["m2"] * r["lc2"] ** 2
    a3 = r["m2"] * r["L1"] * r["lc2"]
    c = a3 * np.cos(q2)
    return np.array([[a1 + 2 * c, a2 + c], [a2 + c, a2]])


def arm_behind_transmission(arm: ArmModel, k_t, c_t, m_link) -> ArmModel | None:
    """The arm seen through a compliant transmission (encoder on the motor side), with
    the transmission and the link inertia between it and the sensor removed.

    With K_c = k_t + j w c_t and Z_link = -w^2 M_link, the link obeys
    K_c (theta_mot - theta_link) = tau_h + Z_link theta_link, so
    Z_arm = (Z_meas^-1 - K_c^-1)^-1 (I + K_c^-1 Z_link). None when not possible.
    """
    if arm.Z is None:
        return None
    w, good, n = _grid(arm)
    kc = _diag(k_t, c_t, w, n)
    zl = (-w ** 2)[:, None, None] * np.asarray(m_link, float)[None]
    try:
        kci = np.linalg.inv(kc)
        behind = np.linalg.inv(np.linalg.inv(arm.Z[good]) - kci) @ (np.eye(n) + kci @ zl)
        return _checked(_fit(arm.f[good], behind, arm.fs, arm.method + " behind transmission",
                             arm.sampling_delay))
    except (np.linalg.LinAlgError, ValueError, ArithmeticError):
        return None


def _grid(arm):
    good = (arm.f > 0) & np.isfinite(arm.Z).all(axis=(1, 2))
    return 2 * np.pi * arm.f[good], good, arm.Z.shape[1]


def _diag(k, c, w, n):
    z = np.asarray(k, float)[None, :] + 1j * w[:, None] * np.asarray(c, float)[None, :]
    return z[:, :, None] * np.eye(n)[None]


def _checked(out: ArmModel) -> ArmModel | None:
    if not all(np.isfinite(m).all() for m in (out.M, out.B, out.K)):
        return None
    return out


def arm_behind_cuff(arm: ArmModel, k_s, c_s) -> ArmModel | None:
    """The arm seen through a compliant cuff, with the cuff removed.

    With a cuff (stiffness ``k_s`` [N m/rad], damping ``c_s`` [N m s/rad] per joint)
    between the robot link and the arm, the impedance estimated from the link angle and
    the cuff torque is the series combination Z_meas^-1 = Z_arm^-1 + Z_cuff^-1, far from
    second order when the cuff is soft (the fit then gives a negative inertia). A
    candidate cuff is therefore simulated with Z_arm = (Z_meas^-1 - Z_cuff^-1)^-1 refitted
    to second order. None when that is not possible (no stored estimate, singular).
    """
    if arm.Z is None:
        return None
    w, good, n = _grid(arm)
    try:
        behind = np.linalg.inv(np.linalg.inv(arm.Z[good]) - np.linalg.inv(_diag(k_s, c_s, w, n)))
        return _checked(_fit(arm.f[good], behind, arm.fs, arm.method + " behind cuff",
                             arm.sampling_delay))
    except (np.linalg.LinAlgError, ValueError, ArithmeticError):
        return None
