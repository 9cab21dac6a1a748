"""Truth models of effects outside the catalogue, for the validation (docs/diagnosis.md).

Active torques of the limb, from the true joint angles, that no catalogue effect models:

``cubic_stiffness`` (a nonlinearity)
    Muscle stiffness that grows with stretch: tau = -k3 theta^3 per joint; the effective
    stiffness K + 3 k3 theta^2 depends on the perturbation amplitude.
``wobbling_mass`` (a dynamic element)
    Soft tissue moving against the bone (a wobbling mass, Gruber et al. 1998): a mass m
    tied to each joint by a spring-damper (k, c), tau = -k (theta - x) - c (omega - v),
    m x'' = k (theta - x) + c (omega - v). Adds a resonance at sqrt(k/m) / (2 pi).
``stretch_reflex`` (neural)
    Short-latency stretch reflex: tau = -G omega_f(t - d), omega_f the joint velocity
    low-passed at 20 Hz (first order), d the reflex loop delay (25-50 ms).

Each is a callable ``model(n, outputs) -> torques`` for ``orchestrator.simulate_trial
(human=...)``; ``outputs`` are the true plant outputs ``[theta..., tau_h...]``.
"""

from __future__ import annotations

import math
from collections import deque


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
        return [-k3 * th ** 3 for th in outputs[:self.n]]


class WobblingMass(_Model):
    def __init__(self, n_dof, fs, **params):
        super().__init__(n_dof, fs, **params)
        self.x = [0.0] * n_dof
        self.v = [0.0] * n_dof

    def __call__(self, n, outputs):
        m, k, c = self.params["m"], self.params["k"], self.params["c"]
        theta = outputs[:self.n]
        omega = self._omega(theta)
        out = []
        for j in range(self.n):
            force = k * (theta[j] - self.x[j]) + c * (omega[j] - self.v[j])
            self.v[j] += self.ts * force / m          # semi-implicit Euler
            self.x[j] += self.ts * self.v[j]
            out.append(-force)
        return out


class StretchReflex(_Model):
    def __init__(self, n_dof, fs, **params):
        super().__init__(n_dof, fs, **params)
        lag = max(1, int(round(params["delay_s"] * fs)))
        self.buffer = deque([[0.0] * n_dof] * lag, maxlen=lag)
        self.alpha = 1.0 - math.exp(-2 * math.pi * 20.0 * self.ts)
        self.omega_f = [0.0] * n_dof

    def __call__(self, n, outputs):
        omega = self._omega(outputs[:self.n])
        self.omega_f = [f + self.alpha * (w - f) for f, w in zip(self.omega_f, omega)]
        delayed = self.buffer[0]
        self.buffer.append(list(self.omega_f))
        return [-self.params["gain"] * w for w in delayed]


MODELS = {"cubic_stiffness": CubicStiffness, "wobbling_mass": WobblingMass,
          "stretch_reflex": StretchReflex}


def make_model(name: str, params: dict, n_dof: int, fs: float):
    """A fresh model instance (state reset) for one trial."""
    try:
        cls = MODELS[name]
    except KeyError:
        raise ValueError(f"unknown outside model {name!r}; known: {', '.join(MODELS)}") from None
    return cls(n_dof, fs, **params)
