"""A position-controlled apparatus (``perturbation.kind = "position"``, log-format.md).

An actuator servo imposes the perturbation on the joint(s); a torque sensor between
actuator and limb measures ``tau_h``. The diagnosis re-simulates the limb model
(``diagnosis.limb``: intrinsic K, B, I per joint plus the catalogue's limb and apparatus
effects):

- with a recorded reference ``theta_ref[j]``: the servo tracks it,
  ``theta, tau_h = limb.servo_response(theta_ref, fs, limb, effects)``; the features are
  the FRFs ``theta_ref -> theta`` and ``theta_ref -> tau_h``;
- without one (archived data such as the reklab ankle recordings): the measured angle
  drives the limb, ``tau_h = limb.limb_torque(theta, fs, limb, effects)``; the feature is
  the FRF ``theta -> tau_h`` (the joint's impedance).

Only the coherent (FRF) features are compared: the limb's own torque not coherent with
the perturbation (voluntary activity, sensor noise) is not modelled, so its spectrum is
no evidence for or against a model. The limb is estimated as ``armimp estimate`` does
(``direct`` method from theta to tau_h without a reference, ``full`` with one), with the
sampling the trials declare (real recordings: instantaneous).
"""

from __future__ import annotations

import numpy as np

import trialformat as tf

from ..arm import estimate_arm
from ..errors import DiagnosisInputError
from .base import Experiment


class PositionServo(Experiment):
    """Position servo with a torque sensor between actuator and limb (any n >= 1)."""

    kind = "position"
    title = "position servo imposes the angle, torque sensor between actuator and limb"
    declared_keys = ("fs", "n_dof")
    feature_kinds = ("frf",)

    @classmethod
    def accepts(cls, trials) -> bool:
        return all(t.perturbation_kind == "position" for t in trials)

    def check_metadata(self, trials) -> None:
        with_ref = {t.name: t.theta_ref is not None for t in trials}
        if len(set(with_ref.values())) > 1:
            raise DiagnosisInputError(
                f"position trials with and without a recorded theta_ref in one diagnosis "
                f"({with_ref}): one experiment either tracks a reference or not")

    def perturbation_signal(self, trial) -> str:
        return "theta_ref" if trial.theta_ref is not None else "theta"

    def output_signals(self, trial) -> tuple:
        return ("theta", "tau_h") if trial.theta_ref is not None else ("tau_h",)

    def estimate(self, trials):
        return estimate_arm(trials)

    def simulator(self, model, *, plant=None, rk4_step=None):
        limb_api = _limb_api()
        limb = _limb_model(limb_api, model)

        def simulate(trial, effects, n_samples):
            n = int(n_samples)
            fs = trial.fs
            try:
                if trial.theta_ref is not None and limb_api is not None:
                    theta, tau = limb_api.servo_response(trial.theta_ref[:n], fs, limb,
                                                         effects or {})
                else:
                    theta = np.array(trial.theta[:n], dtype=float)
                    if limb_api is not None:
                        tau = limb_api.limb_torque(theta, fs, limb, effects or {})
                    else:
                        tau = intrinsic_torque(theta, fs, model.K, model.B, model.M,
                                               effects or {})
            except (FloatingPointError, OverflowError, np.linalg.LinAlgError):
                return None
            theta, tau = np.asarray(theta, float), np.asarray(tau, float)
            if not (np.isfinite(theta).all() and np.isfinite(tau).all()):
                return None
            return tf.Trial(meta=trial.meta, t=trial.t[:n], theta=theta.reshape(n, -1),
                            tau_h=tau.reshape(n, -1),
                            theta_ref=None if trial.theta_ref is None else trial.theta_ref[:n],
                            name=f"{trial.name}-sim")
        return simulate

    def describe(self) -> dict:
        out = super().describe()
        out["limb_model"] = ("diagnosis.limb" if _limb_api() is not None else
                             "intrinsic K, B, I only (diagnosis.limb not installed)")
        return out


def _limb_api():
    """The limb forward models (diagnosis.limb), None where that module is absent."""
    try:
        from .. import limb
    except ImportError:
        return None
    return limb


def _limb_model(api, model):
    if api is None:
        return None
    return api.LimbModel(K=np.asarray(model.K, float), B=np.asarray(model.B, float),
                         I=np.asarray(model.M, float))


def intrinsic_torque(theta, fs, K, B, I, effects=None):
    """Torque of the intrinsic limb ``tau = I theta'' + B theta' + K theta`` [N m], (N, n).

    ``theta`` (N, n) [rad] at ``fs`` [Hz]; K, B, I (n, n). Derivatives by second-order
    central differences (one-sided at the ends): the inertial term is exact to
    (w/fs)^2 / 12 (0.5 % at 40 Hz, 1 kHz). Used only where diagnosis.limb is absent: then
    no effect can be simulated (DiagnosisInputError for a non-empty ``effects``).
    """
    if effects:
        raise DiagnosisInputError(f"effects {sorted(effects)} need diagnosis.limb (the limb "
                                  f"forward models), which is not installed")
    theta = np.asarray(theta, float)
    omega = np.gradient(theta, 1.0 / fs, axis=0)
    alpha = np.zeros_like(theta)
    alpha[1:-1] = (theta[2:] - 2.0 * theta[1:-1] + theta[:-2]) * fs * fs
    alpha[0], alpha[-1] = alpha[1], alpha[-2]
    return alpha @ np.asarray(I).T + omega @ np.asarray(B).T + theta @ np.asarray(K).T
