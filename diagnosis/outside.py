"""Truth models of effects outside the catalogue, for the validation (docs/diagnosis.md).

The stretch reflex and the wobbling mass of the earlier validation joined the catalogue
(diagnosis.limb); the effects here stay outside it, each physically different from every
catalogue effect of either experiment kind:

``cubic_stiffness`` (a nonlinearity of the limb)
    Stiffness growing with stretch: tau = k3 theta^3 per joint, instantaneous (the
    catalogue's stiffness_amplitude softens with the running amplitude instead).
``quadratic_damping`` (a nonlinearity of the limb)
    Viscosity growing with speed (turbulent-like tissue damping, co-contraction that
    rises with movement speed): tau = b2 omega |omega| per joint.
``tremor`` (an active torque not caused by the perturbation)
    Physiological tremor: a torque of RMS ``rms_nm`` band-limited around ``frequency_hz``
    (8-12 Hz; a resonator of quality factor 4 driven by white noise), independent of
    the imposed movement.
``backlash`` (the apparatus, position experiments)
    Play of total width ``width_rad`` in the coupling between actuator and limb: the
    limb moves with the (measured) actuator angle only once the play is taken up.

The exoskeleton forms are callables ``model(n, outputs) -> torques`` for
``orchestrator.simulate_trial(human=...)`` (torques the limb adds; ``outputs`` are the true
plant outputs ``[theta..., tau_h...]``); the position forms (:func:`position_outside`)
act on whole arrays and give the angle the limb sees and the torque it adds.
"""

from __future__ import annotations

import math

import numpy as np


class _Model:
    def __init__(self, n_dof: int, fs: float, **params):
        self.n, self.ts, self.params = n_dof, 1.0 / fs, params
        self._last = None

    def _omega(self, theta):
        last = theta if self._last is None else self._last
        self._last = list(theta)
        return [(a - b) / self.ts for a, b in zip(theta, last)]

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.items())
        return f"{type(self).__name__}({args})"


class CubicStiffness(_Model):
    def __call__(self, n, outputs):
        k3 = self.params["k3"]
        return [-k3 * th ** 3 for th in outputs[:self.n]]  # the limb's torque on the robot


class QuadraticDamping(_Model):
    def __call__(self, n, outputs):
        b2 = self.params["b2"]
        return [-b2 * w * abs(w) for w in self._omega(outputs[:self.n])]  # resists motion


class Tremor(_Model):
    """Sample by sample the resonator of :func:`tremor_torque` (same parameters)."""

    def __init__(self, n_dof, fs, **params):
        super().__init__(n_dof, fs, **params)
        self.b, self.a, self.gain = _tremor_filter(params["frequency_hz"], fs)
        self.rng = np.random.default_rng(int(params.get("seed", 0)))
        self.state = [[0.0, 0.0, 0.0, 0.0] for _ in range(n_dof)]  # x1, x2, y1, y2

    def __call__(self, n, outputs):
        out = []
        for j in range(self.n):
            x0 = float(self.rng.standard_normal())
            x1, x2, y1, y2 = self.state[j]
            y0 = (self.b[0] * x0 + self.b[1] * x1 + self.b[2] * x2
                  - self.a[1] * y1 - self.a[2] * y2) / self.a[0]
            self.state[j] = [x0, x1, y0, y1]
            out.append(self.params["rms_nm"] * self.gain * y0)
        return out


MODELS = {"cubic_stiffness": CubicStiffness, "quadratic_damping": QuadraticDamping,
          "tremor": Tremor}


def _tremor_filter(frequency_hz, fs, q=4.0):
    """(b, a, gain): a resonator (band-pass, quality factor q) and the gain that gives its
    output unit RMS for unit white input (from its impulse response energy)."""
    from scipy import signal
    b, a = signal.iirpeak(float(frequency_hz), q, fs=fs)
    _, h = signal.dimpulse((b, a, 1.0 / fs), n=int(20 * fs / frequency_hz) + 100)
    return b, a, 1.0 / math.sqrt(float(np.sum(np.square(h[0]))))


def tremor_torque(n_samples: int, n_dof: int, fs: float, rms_nm: float,
                  frequency_hz: float, seed: int = 0) -> np.ndarray:
    """Tremor torque (n_samples, n_dof) [N m] of RMS ``rms_nm`` (see module docstring)."""
    from scipy import signal
    b, a, gain = _tremor_filter(frequency_hz, fs)
    rng = np.random.default_rng(seed)
    warm = int(2 * fs)
    x = rng.standard_normal((n_samples + warm, n_dof))
    return rms_nm * gain * signal.lfilter(b, a, x, axis=0)[warm:]


def backlash(theta: np.ndarray, width_rad: float) -> np.ndarray:
    """The angle (N, n) of a limb coupled through play of total width ``width_rad`` to an
    actuator at ``theta`` (N, n): it holds still until the actuator takes up the play."""
    half = 0.5 * float(width_rad)
    out = np.empty_like(theta)
    y = theta[0].copy()
    for i in range(theta.shape[0]):  # a play operator has state; 30 000 samples ~ 50 ms
        y = np.minimum(np.maximum(y, theta[i] - half), theta[i] + half)
        out[i] = y
    return out


#: outside effects of the position experiments: (name, draw(rng) -> params)
POSITION_OUTSIDE = ("cubic_stiffness", "quadratic_damping", "tremor", "backlash")


def position_outside(name: str, params: dict, theta: np.ndarray, fs: float):
    """(angle the limb sees (N, n) [rad], torque it adds (N, n) [N m]) for an outside
    effect of a position experiment with actuator angle ``theta``.

    Raises ValueError for an unknown name.
    """
    from .limb import derivatives
    if name == "cubic_stiffness":
        return theta, params["k3"] * theta ** 3
    if name == "quadratic_damping":
        omega, _ = derivatives(theta, fs)
        return theta, params["b2"] * omega * np.abs(omega)
    if name == "tremor":
        return theta, tremor_torque(theta.shape[0], theta.shape[1], fs, params["rms_nm"],
                                    params["frequency_hz"], int(params.get("seed", 0)))
    if name == "backlash":
        return backlash(theta, params["width_rad"]), np.zeros_like(theta)
    raise ValueError(f"unknown outside effect {name!r}; known: {', '.join(POSITION_OUTSIDE)}")


def make_model(name: str, params: dict, n_dof: int, fs: float):
    """A fresh model instance (state reset) for one trial."""
    try:
        cls = MODELS[name]
    except KeyError:
        raise ValueError(f"unknown outside model {name!r}; known: {', '.join(MODELS)}") from None
    return cls(n_dof, fs, **params)
