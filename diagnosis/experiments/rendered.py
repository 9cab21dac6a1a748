"""A robot that renders its target impedance exactly, torque perturbation: the
experiment of a set-up with no plant model (no ``robot`` block, or no plant FMU of its
number of joints), e.g. the one-joint trials of ``estimation.synthetic.torque_trial``.

The controller block declares the rendered impedance ``Z_a = M_rd s^2 + B_rd s + K_rd``
(diagonal, per joint); with the limb ``Z = I s^2 + B s + K`` estimated from the trials,
the loop is

    (Z + Z_a) theta = tau_delta,   tau_h = Z theta,   tau_m = tau_delta - tau_h

simulated in discrete time (bilinear transform of the continuous state space at the
trials' rate; exact to (w/fs)^2/12 in phase, < 0.1 % at 25 Hz and 1 kHz). The FRFs from
``tau_delta`` to theta, tau_h and tau_m are compared (the limb's own torque and the
sensor noise are not modelled). No catalogue effect is simulated for this experiment
yet: its diagnosis says whether the nominal model reproduces the trials, and where it
does not.
"""

from __future__ import annotations

import numpy as np
from scipy import signal as sps

import trialformat as tf

from ..arm import estimate_arm
from ..errors import DiagnosisInputError
from .base import Experiment

RENDERED_KEYS = ("M_rd", "B_rd", "K_rd")


def _has_plant(n_dof: int) -> bool:
    try:
        from fmus.variables import N_LINKS
    except ImportError:
        return False
    return n_dof in N_LINKS


class RenderedImpedance(Experiment):
    """Torque perturbation on a robot rendering M_rd, B_rd, K_rd exactly (any n >= 1)."""

    kind = "rendered"
    title = ("torque perturbation, robot rendering its target impedance exactly (no "
             "plant model of this set-up)")
    declared_keys = ("fs", "n_dof", "controller")
    feature_kinds = ("frf",)

    @classmethod
    def accepts(cls, trials) -> bool:
        t = trials[0]
        return (all(x.perturbation_kind == "torque" for x in trials)
                and (not t.meta.get("robot") or not _has_plant(t.n_dof)))

    def check_metadata(self, trials) -> None:
        t = trials[0]
        block = t.meta.get("controller") or {}
        missing = [k for k in RENDERED_KEYS if k not in block]
        if missing:
            raise DiagnosisInputError(
                f"trial {t.name!r}: no plant model of this {self.n_dof}-joint set-up, and "
                f"the metadata key(s) {['controller.' + k for k in missing]} that declare "
                f"the rendered impedance are missing")
        for k in RENDERED_KEYS:
            if np.shape(block[k]) != (self.n_dof,):
                raise DiagnosisInputError(
                    f"trial {t.name!r}: metadata key 'controller.{k}' has shape "
                    f"{np.shape(block[k])}; expected ({self.n_dof},)")

    def estimate(self, trials):
        return estimate_arm(trials)

    def simulator(self, model, *, plant=None, rk4_step=None):
        block = self.meta["controller"]
        n = self.n_dof
        Ma, Ba, Ka = (np.diag(np.asarray(block[k], float)) for k in RENDERED_KEYS)
        M, B, K = (np.atleast_2d(np.asarray(m, float)) for m in (model.M, model.B, model.K))
        Mt = M + Ma
        try:
            Mi = np.linalg.inv(Mt)
        except np.linalg.LinAlgError:
            Mi = None
        cache: dict = {}

        def system(fs):
            if fs not in cache:
                A = np.block([[np.zeros((n, n)), np.eye(n)], [-Mi @ (K + Ka), -Mi @ (B + Ba)]])
                Bm = np.vstack([np.zeros((n, n)), Mi])
                C = np.hstack([np.eye(n), np.zeros((n, n))])
                cache[fs] = sps.cont2discrete((A, Bm, C, np.zeros((n, n))), 1.0 / fs,
                                              method="bilinear")
            return cache[fs]

        def simulate(trial, effects, n_samples):
            if effects:
                raise DiagnosisInputError(f"no effect can be simulated for the {self.kind} "
                                          f"experiment (got {sorted(effects)})")
            if Mi is None:
                return None
            n_s = int(n_samples)
            d = np.asarray(trial.tau_delta[:n_s], float)
            Ad, Bd, Cd, Dd, _ = system(trial.fs)
            x = np.zeros(2 * n)
            states = np.empty((n_s, 2 * n))
            for i in range(n_s):  # dlsim without its interpolation
                states[i] = x
                x = Ad @ x + Bd @ d[i]
            theta = states @ Cd.T + d @ Dd.T
            if not np.isfinite(theta).all() or np.abs(theta).max() > 1e3:
                return None
            fs = trial.fs
            omega = np.gradient(theta, 1.0 / fs, axis=0)
            alpha = np.zeros_like(theta)
            alpha[1:-1] = (theta[2:] - 2.0 * theta[1:-1] + theta[:-2]) * fs * fs
            alpha[0], alpha[-1] = alpha[1], alpha[-2]
            tau_h = theta @ K.T + omega @ B.T + alpha @ M.T
            return tf.Trial(meta=trial.meta, t=trial.t[:n_s], tau_delta=d, theta=theta,
                            tau_h=tau_h, tau_m=d - tau_h, name=f"{trial.name}-sim")
        return simulate
