"""An independent Python implementation of the plant equations (friction off), for cross-checks.

Written from docs/spec (reference.md sections 2-3, effects.md), not from the C code.
State x (16): theta, w (link), tau_act, q_mot, w_mot, theta_h, w_h, y; states of an effect
that is off have zero derivative.  Outputs: theta at the encoder (2), tau_h at the sensor (2).
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from fmus.variables import VARIABLES

G_ACC = 9.81


def defaults() -> dict:
    return {v.name: v.start for v in VARIABLES if v.causality == "parameter"}


class Plant:
    def __init__(self, params: dict | None = None):
        p = defaults()
        p.update(params or {})
        self.p = p
        g = lambda k: np.array([p[f"{k}[1]"], p[f"{k}[2]"]])  # noqa: E731
        mat = lambda k: np.array([[p[f"{k}[{i},{j}]"] for j in (1, 2)] for i in (1, 2)])  # noqa: E731
        m1, m2, L1, lc1, lc2, I1, I2 = (p[f"robot.{k}"] for k in ("m1", "m2", "L1", "lc1", "lc2", "I1", "I2"))
        s = p["inertia_mismatch.scale"]
        self.a1 = s * (I1 + m1 * lc1**2 + I2 + m2 * (L1**2 + lc2**2))
        self.a2 = s * (I2 + m2 * lc2**2)
        self.a3 = s * m2 * L1 * lc2
        self.Jm = g("robot.Jm")
        self.q0 = np.deg2rad(g("posture_deg"))
        self.Mh, self.Bh, self.Kh = mat("arm.M_h"), mat("arm.B_h"), mat("arm.K_h")
        gs = G_ACC * np.sin(np.deg2rad(p["gravity.tilt_deg"]))
        self.gc1, self.gc2 = gs * (m1 * lc1 + m2 * L1), gs * m2 * lc2
        self.Ta = p["actuator_lag.time_constant_s"]
        self.Ts = p["torque_sensor_lag.time_constant_s"]
        self.kt, self.ct = g("transmission_compliance.k_t"), g("transmission_compliance.c_t")
        self.ks, self.cs = g("interface_compliance.k_s"), g("interface_compliance.c_s")

    def M_r(self, q2, with_jm=True):
        c = np.cos(q2)
        J = self.Jm * (self.kt == 0) if with_jm else np.zeros(2)
        return np.array([[self.a1 + 2 * self.a3 * c + J[0], self.a2 + self.a3 * c],
                         [self.a2 + self.a3 * c, self.a2 + J[1]]])

    def gravity(self, q):
        c1, c12 = np.cos(q[0]), np.cos(q[0] + q[1])
        return np.array([self.gc1 * c1 + self.gc2 * c12, self.gc2 * c12])

    def f(self, x, u):
        th, w, ta, qm, wm, thh, wh, y = x.reshape(8, 2)
        u = np.asarray(u, float)
        dx = np.zeros((8, 2))
        q = self.q0 + th
        tau_act = ta if self.Ta > 0 else u
        if self.Ta > 0:
            dx[2] = (u - ta) / self.Ta
        comp = self.kt > 0
        tau_t = self.kt * (qm - th) + self.ct * (wm - w)
        force = np.where(comp, tau_t, tau_act)
        dx[3] = np.where(comp, wm, 0.0)
        dx[4] = np.where(comp, (tau_act - tau_t) / np.where(comp, self.Jm, 1.0), 0.0)
        cr = self.a3 * np.sin(q[1]) * np.array([-(2 * w[0] * w[1] + w[1] ** 2), w[0] ** 2])
        rhs = force - cr - self.gravity(q)
        M = self.M_r(q[1])
        if np.all(self.ks > 0):
            tau_h = self.ks * (th - thh) + self.cs * (w - wh)
            acc = np.linalg.solve(M, rhs - tau_h)
            dx[5] = wh
            dx[6] = np.linalg.solve(self.Mh, tau_h - self.Bh @ wh - self.Kh @ thh)
        else:
            acc = np.linalg.solve(M + self.Mh, rhs - self.Bh @ w - self.Kh @ th)
            tau_h = self.Mh @ acc + self.Bh @ w + self.Kh @ th
        dx[0], dx[1] = w, acc
        if self.Ts > 0:
            dx[7] = (tau_h - y) / self.Ts
        theta_enc = np.where(comp, qm, th)
        out = np.concatenate([theta_enc, y if self.Ts > 0 else tau_h])
        return dx.ravel(), out

    def linearise(self, u0, eps=1e-7):
        """A, B, C, D of the plant about x = 0, u = u0 (central differences)."""
        n, m = 16, 2
        x0 = np.zeros(n)
        A, C = np.zeros((n, n)), np.zeros((4, n))
        B, D = np.zeros((n, m)), np.zeros((4, m))
        for i in range(n):
            e = np.zeros(n)
            e[i] = eps
            fp, yp = self.f(x0 + e, u0)
            fm, ym = self.f(x0 - e, u0)
            A[:, i], C[:, i] = (fp - fm) / (2 * eps), (yp - ym) / (2 * eps)
        for i in range(m):
            e = np.zeros(m)
            e[i] = eps
            fp, yp = self.f(x0, u0 + e)
            fm, ym = self.f(x0, u0 - e)
            B[:, i], D[:, i] = (fp - fm) / (2 * eps), (yp - ym) / (2 * eps)
        return A, B, C, D

    def simulate_linear_zoh(self, u0, du, Ts):
        """Exact sampled response of the affine linearisation about (x = 0, u0) to
        u0 + du[n] held over [n Ts, (n+1) Ts):  x' = A x + B du + f(0, u0).

        Returns y (len(du) + 1, 4) sampled like the FMU loop: y[0] = y0 + D du[0], then
        y[n+1] = y0 + C x[n+1] + D du[n] (end of interval n, input n still applied).
        """
        u0 = np.asarray(u0, float)
        A, B, C, D = self.linearise(u0)
        f0, y0 = self.f(np.zeros(16), u0)
        n = A.shape[0]
        big = np.zeros((n + 3, n + 3))
        big[:n, :n], big[:n, n:n + 2], big[:n, n + 2] = A * Ts, B * Ts, f0 * Ts
        E = expm(big)
        Ad, Bd = E[:n, :n], E[:n, n:]
        x = np.zeros(n)
        y = np.empty((len(du) + 1, 4))
        y[0] = y0 + D @ du[0]
        for k, uk in enumerate(du):
            x = Ad @ x + Bd @ np.append(uk, 1.0)
            y[k + 1] = y0 + C @ x + D @ uk
        return y
