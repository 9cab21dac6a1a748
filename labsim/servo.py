"""The position servo loop and its solution with the limb's nonlinear, time-varying torque.

The loop's linear time-invariant part (motor, controller, the limb's nominal K0, B0, I0)
is one state space, with inputs the reference r and a torque d, per joint:

    (J_m + I0) x'' = u - B0 x' - K0 x - d,      u = Kp (r - x) + Ki int(r - x) - Kd x'
    (with an actuator lag:  T_a u' = u_cmd - u)

and outputs x, x', x'', u. The torque sensor sits between motor and footplate, so it reads
``tau_h = u - J_m x''``. The limb's full torque tau_h(x, x', x'') (labsim.limb) differs
from the nominal ``I0 x'' + B0 x' + K0 x`` by ``d``: the loop is solved as the fixed point
``d = tau_limb(x[d]) - nominal(x[d])`` (waveform relaxation; White et al., IEEE TCAD 4,
1985), accelerated by Anderson mixing (Walker & Ni, SIAM J Numer Anal 49:1715, 2011).
Because the servo is stiff (Kp >> K), the limb's deviation moves the joint little and the
iteration contracts fast (2-16 iterations; a backlash's play about 40); it stops when the
torque residual is below 1e-9 of the torque scale (or stagnates below 1e-7 at the
round-off of the linear parts) and refuses (SimulationError) if it does not converge.
"""

from __future__ import annotations

import numpy as np

from .limb import per_joint
from .lti import StateSpace


_TRACE = None  # a list to record the residuals of each iteration (debugging)


class SimulationError(RuntimeError):
    """The simulation could not be carried out as specified (the message says why)."""


class ServoLoop:
    """The LTI loop of a ``"pd"`` servo for n joints (module docstring).

    With ``contact_hz`` (backlash between motor and footplate), the footplate side follows
    the motor through a linear contact, x_f'' = wc^2 (x - x_f) - 1.4 wc x_f', and the
    motor carries the load I0 x_f'' + B0 x_f' + K0 x_f (the play's deviation from it is
    in d); the gains are still set for the motor plus the limb.

    Attributes ``Kp``, ``Kd``, ``Ki`` (n,) [N m/rad, N m s/rad, N m/(rad s)], ``Jm`` (n,).
    """

    def __init__(self, servo, I0, B0, K0, h: float, contact_hz: float | None = None):
        n = I0.shape[0]
        self.n, self.h = n, h
        self.Jm = per_joint(servo.motor_inertia, n, "servo.motor_inertia")
        mass = self.Jm + np.diag(I0)
        w = 2 * np.pi * servo.f_hz
        self.Kp = mass * w * w
        self.Kd = 2 * servo.damping * mass * w
        self.Ki = self.Kp * 2 * np.pi * servo.integral_hz
        lag = servo.actuator_lag_s
        blocks = ["x", "v"] + (["u"] if lag > 0 else []) + \
            (["e"] if servo.integral_hz > 0 else []) + (["xf", "vf"] if contact_hz else [])
        idx = {b: slice(i * n, (i + 1) * n) for i, b in enumerate(blocks)}
        ns = len(blocks) * n
        width = ns + 2 * n  # rows over [state | r, d]
        eye = np.eye(n)
        ucmd = np.zeros((n, width))  # u_cmd = Kp (r - x) - Kd v + Ki e
        ucmd[:, idx["x"]] = -np.diag(self.Kp)
        ucmd[:, idx["v"]] = -np.diag(self.Kd)
        ucmd[:, ns:ns + n] = np.diag(self.Kp)
        if "e" in idx:
            ucmd[:, idx["e"]] = np.diag(self.Ki)
        if "u" in idx:
            uact = np.zeros_like(ucmd)
            uact[:, idx["u"]] = eye
        else:
            uact = ucmd
        if contact_hz:
            wc = 2 * np.pi * contact_hz
            pos, vel = np.zeros((n, width)), np.zeros((n, width))
            pos[:, idx["xf"]], vel[:, idx["vf"]] = eye, eye
            accf = np.zeros((n, width))
            accf[:, idx["x"]] = wc * wc * eye
            accf[:, idx["xf"]] = -wc * wc * eye
            accf[:, idx["vf"]] = -1.4 * wc * eye
            force = uact - I0 @ accf - B0 @ vel - K0 @ pos
            force[:, ns + n:] -= eye
            acc = np.linalg.inv(np.diag(self.Jm)) @ force
        else:
            force = uact.copy()
            force[:, idx["x"]] -= K0
            force[:, idx["v"]] -= B0
            force[:, ns + n:] -= eye
            acc = np.linalg.inv(np.diag(self.Jm) + I0) @ force
            pos, vel, accf = np.zeros((n, width)), np.zeros((n, width)), acc
            pos[:, idx["x"]], vel[:, idx["v"]] = eye, eye
        M = np.zeros((ns, width))
        M[idx["x"], idx["v"]] = eye
        M[idx["v"]] = acc
        if "u" in idx:
            M[idx["u"]] = (ucmd - uact) / lag
        if "e" in idx:
            M[idx["e"], ns:ns + n] = eye
            M[idx["e"], idx["x"]] = -eye
        if contact_hz:
            M[idx["xf"]] = vel
            M[idx["vf"]] = accf
        self.contact = bool(contact_hz)
        out = np.zeros(((7 if contact_hz else 4) * n, width))
        out[0:n, idx["x"]] = eye
        out[n:2 * n, idx["v"]] = eye
        out[2 * n:3 * n] = acc
        out[3 * n:4 * n] = uact
        if contact_hz:  # the footplate side's own outputs (else it is the motor's)
            out[4 * n:5 * n], out[5 * n:6 * n], out[6 * n:] = pos, vel, accf
        self.sys_r = StateSpace(M[:, :ns], M[:, ns:ns + n], out[:, :ns], out[:, ns:ns + n])
        self.sys_d = StateSpace(M[:, :ns], M[:, ns + n:], out[:, :ns], out[:, ns + n:])

    def respond(self, sys: StateSpace, u: np.ndarray, smooth: bool = True) -> dict:
        y = sys.simulate(u, self.h, smooth=smooth)
        n = self.n
        names = ("x", "v", "a", "u", "xf", "vf", "af") if self.contact else ("x", "v", "a", "u")
        out = {k: y[i * n:(i + 1) * n] for i, k in enumerate(names)}
        if not self.contact:
            out.update(xf=out["x"], vf=out["v"], af=out["a"])
        return out


def solve_loop(loop: ServoLoop, limb, r: np.ndarray, *, smooth_reference: bool = True,
               tol: float = 1e-9, max_iter: int = 80, memory: int = 5) -> dict:
    """The servo loop with the limb: x, v, a, u, tau_h (n, N), the limb's parts, and
    ``iterations`` and ``residual`` (module docstring).

    Raises
    ------
    SimulationError
        The fixed point is not reached within ``max_iter`` iterations.
    """
    base = loop.respond(loop.sys_r, r, smooth_reference)

    def state(d):
        if d is None:
            return base
        # d unequalised: the sensor's torque u - J_m x'' then equals the limb's own sum
        # at every grid point (an algebraic output of the loop)
        dd = loop.respond(loop.sys_d, d, smooth=False)
        s = {k: base[k] + dd[k] for k in ("x", "v", "a", "u")}
        if loop.contact:
            s.update({k: base[k] + dd[k] for k in ("xf", "vf", "af")})
        else:
            s.update(xf=s["x"], vf=s["v"], af=s["a"])
        return s

    def nominal(s):  # the load the loop's LTI part carries (footplate side)
        return limb.I0 @ s["af"] + limb.B0 @ s["vf"] + limb.K0 @ s["xf"]

    def g(d):
        s = state(d)
        total, parts = limb.torque(s["x"], s["v"], s["a"])
        return total - nominal(s), s, parts

    d = np.zeros_like(r)
    gd, s, parts = g(None)
    scale = np.sqrt(np.mean(nominal(s) ** 2)) + np.sqrt(np.mean(gd ** 2)) + 1e-300
    dF, dG = [], []
    f_prev = g_prev = None
    history = []
    for it in range(1, max_iter + 1):
        f = gd - d
        res = np.max(np.abs(f)) / scale
        if _TRACE is not None:
            _TRACE.append(res)
        if res <= tol:
            break
        history.append(res)
        if len(history) > 8 and res < 1e-7 and min(history[-8:]) > 0.5 * history[-9]:
            break  # stagnant at the round-off of the linear parts: accepted, reported
        if f_prev is not None:
            dF.append((f - f_prev).ravel())
            dG.append((gd - g_prev).ravel())
            if len(dF) > memory:
                dF.pop(0)
                dG.pop(0)
        f_prev, g_prev = f, gd
        if dF:
            Fm = np.array(dF)
            gamma = np.linalg.lstsq(Fm.T, f.ravel(), rcond=None)[0]
            d = gd - (gamma @ np.array(dG)).reshape(d.shape)
        else:
            d = gd
        gd, s, parts = g(d)
    else:
        raise SimulationError(
            f"servo loop did not converge in {max_iter} iterations (torque residual "
            f"{res:.3g} of the torque scale); a friction smoother than footplate.v_s, a "
            f"stiffer servo (servo.f_hz) or a smaller limb variation converges")
    tau_h = s["u"] - loop.Jm[:, None] * s["a"]
    total = nominal(s) + gd
    return {**s, "tau_h": tau_h, "tau_limb": total, "parts": parts, "iterations": it,
            "residual": res}
