"""An independent Python model of the three-link plant, written from
docs/spec/reference-3dof.md (the printed M_r entries a1..b23, Coriolis torques from the
Christoffel symbols of M_r by central differences, gravity from the numerical gradient of
the potential energy) and docs/spec/effects.md; not from the C code.

State (9 x 3): theta, w (link), tau_act, q_mot, w_mot, theta_h, w_h, y, z (LuGre).
"""
from __future__ import annotations

import numpy as np

from fmus.variables import table

G_ACC = 9.81
N = 3


def defaults() -> dict:
    return {v.name: v.start for v in table(N).variables if v.causality == "parameter"}


class Plant3:
    def __init__(self, params: dict | None = None):
        p = defaults()
        p.update(params or {})
        self.p = p
        vec = lambda k: np.array([p[f"{k}[{j}]"] for j in (1, 2, 3)])  # noqa: E731
        mat = lambda k: np.array([[p[f"{k}[{i},{j}]"] for j in (1, 2, 3)] for i in (1, 2, 3)])  # noqa: E731
        r = {k: p[f"robot.{k}"] for k in ("m1", "L1", "lc1", "I1", "m2", "L2", "lc2", "I2",
                                           "m3", "L3", "lc3", "I3")}
        self.r = r
        s = p["inertia_mismatch.scale"]
        m1, m2, m3, L1, L2 = r["m1"], r["m2"], r["m3"], r["L1"], r["L2"]
        lc1, lc2, lc3, I1, I2, I3 = r["lc1"], r["lc2"], r["lc3"], r["I1"], r["I2"], r["I3"]
        self.a1 = s * (I1 + m1 * lc1**2 + I2 + m2 * (L1**2 + lc2**2) + I3 + m3 * (L1**2 + L2**2 + lc3**2))
        self.a2 = s * (I2 + m2 * lc2**2 + I3 + m3 * (L2**2 + lc3**2))
        self.a3 = s * (I3 + m3 * lc3**2)
        self.b12 = s * (m2 * L1 * lc2 + m3 * L1 * L2)
        self.b13 = s * m3 * L1 * lc3
        self.b23 = s * m3 * L2 * lc3
        self.Jm = vec("robot.Jm")
        self.q0 = np.deg2rad(vec("posture_deg"))
        self.Mh, self.Bh, self.Kh = mat("arm.M_h"), mat("arm.B_h"), mat("arm.K_h")
        self.gs = G_ACC * np.sin(np.deg2rad(p["gravity.tilt_deg"]))
        self.Ta = p["actuator_lag.time_constant_s"]
        self.Ts = p["torque_sensor_lag.time_constant_s"]
        self.kt, self.ct = vec("transmission_compliance.k_t"), vec("transmission_compliance.c_t")
        self.ks, self.cs = vec("interface_compliance.k_s"), vec("interface_compliance.c_s")
        self.Fc, self.Fs, self.sig2 = vec("friction.Fc"), vec("friction.Fs"), vec("friction.sigma2")
        self.sig0, self.sig1, self.ws = p["friction.sigma0"], p["friction.sigma1"], p["friction.ws"]
        self.J_link = np.where(self.kt > 0, 0.0, self.Jm)

    def M_r(self, q):
        """reference-3dof.md's M_r(q) (Jm where it moves with the link)."""
        c2, c3, c23 = np.cos(q[1]), np.cos(q[2]), np.cos(q[1] + q[2])
        a1, a2, a3, b12, b13, b23 = self.a1, self.a2, self.a3, self.b12, self.b13, self.b23
        M11 = a1 + 2 * b12 * c2 + 2 * b13 * c23 + 2 * b23 * c3
        M12 = a2 + b12 * c2 + b13 * c23 + 2 * b23 * c3
        M13 = a3 + b13 * c23 + b23 * c3
        M22 = a2 + 2 * b23 * c3
        M23 = a3 + b23 * c3
        M33 = a3
        return np.array([[M11, M12, M13], [M12, M22, M23], [M13, M23, M33]]) + np.diag(self.J_link)

    def coriolis(self, q, qd, eps=1e-6):
        """c_i = sum_jk G_ijk q_j' q_k', G_ijk = (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i) / 2."""
        dM = np.empty((3, 3, 3))  # dM[:, :, k] = dM/dq_k
        for k in range(3):
            e = np.zeros(3)
            e[k] = eps
            dM[:, :, k] = (self.M_r(q + e) - self.M_r(q - e)) / (2 * eps)
        G = 0.5 * (dM + dM.transpose(0, 2, 1) - dM.transpose(2, 0, 1))
        return np.einsum("ijk,j,k->i", G, qd, qd)

    def potential(self, q):
        r = self.r
        p1, p2, p3 = q[0], q[0] + q[1], q[0] + q[1] + q[2]
        y = (r["m1"] * r["lc1"] * np.sin(p1)
             + r["m2"] * (r["L1"] * np.sin(p1) + r["lc2"] * np.sin(p2))
             + r["m3"] * (r["L1"] * np.sin(p1) + r["L2"] * np.sin(p2) + r["lc3"] * np.sin(p3)))
        return self.gs * y

    def gravity(self, q, eps=1e-6):
        out = np.empty(3)
        for k in range(3):
            e = np.zeros(3)
            e[k] = eps
            out[k] = (self.potential(q + e) - self.potential(q - e)) / (2 * eps)
        return out

    def friction(self, v, z):
        lugre = self.Fs > 0
        g = np.where(lugre, self.Fc + (self.Fs - self.Fc) * np.exp(-(v / self.ws) ** 2), 1.0)
        zd = np.where(lugre, v - self.sig0 * np.abs(v) * z / g, 0.0)
        tf = np.where(lugre, self.sig0 * z + self.sig1 * zd, 0.0) + self.sig2 * v
        return tf, zd

    def f(self, x, u):
        th, w, ta, qm, wm, thh, wh, y, z = x.reshape(9, 3)
        dx = np.zeros((9, 3))
        q = self.q0 + th
        comp_t, iface = self.kt > 0, self.ks[0] > 0
        tau_act = ta if self.Ta > 0 else np.asarray(u, float)
        if self.Ta > 0:
            dx[2] = (u - ta) / self.Ta
        v_f = np.where(comp_t, wm, w)
        tf, zd = self.friction(v_f, z)
        dx[8] = zd
        tau_t = self.kt * (qm - th) + self.ct * (wm - w)
        f_link = np.where(comp_t, tau_t, tau_act - tf)
        dx[3] = np.where(comp_t, wm, 0.0)
        dx[4] = np.where(comp_t, (tau_act - tf - tau_t) / np.where(comp_t, self.Jm, 1.0), 0.0)
        rhs = f_link - self.coriolis(q, w) - self.gravity(q)
        M = self.M_r(q)
        if iface:
            tau_h = self.ks * (th - thh) + self.cs * (w - wh)
            acc = np.linalg.solve(M, rhs - tau_h)
            dx[5], dx[6] = wh, np.linalg.solve(self.Mh, tau_h - self.Bh @ wh - self.Kh @ thh)
        else:
            p = self.Bh @ w + self.Kh @ th
            acc = np.linalg.solve(M + self.Mh, rhs - p)
            tau_h = self.Mh @ acc + p
        dx[0], dx[1] = w, acc
        if self.Ts > 0:
            dx[7] = (tau_h - y) / self.Ts
        return dx.ravel(), tau_h

    def outputs(self, x, u):
        th, w, ta, qm, wm, thh, wh, y, z = x.reshape(9, 3)
        _, tau_h = self.f(x, u)
        comp_t = self.kt > 0
        theta = np.where(comp_t, qm, th)
        return np.concatenate([theta, y if self.Ts > 0 else tau_h])

    def simulate(self, u, Ts=1e-3, rtol=1e-10, atol=1e-12):
        """Outputs [theta(3), tau_h(3)] at n Ts, u[n] held over [n Ts, (n+1) Ts)."""
        from scipy.integrate import solve_ivp

        x = np.zeros(27)
        Y = [self.outputs(x, u[0])]
        for k in range(len(u)):
            sol = solve_ivp(lambda t, xx: self.f(xx, u[k])[0], (0, Ts), x, method="Radau",
                            rtol=rtol, atol=atol)
            x = sol.y[:, -1]
            Y.append(self.outputs(x, u[k]))  # read before the next input is set
        return np.array(Y)
