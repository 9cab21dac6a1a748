"""The limb side of the torque sensor: intrinsic mechanics, reflex, wobbling mass,
footplate effects and the subject's torque.

All signals are time-last arrays: (n, N) for n joints on the fine grid of N points.
The torque the limb (with the footplate) takes from the sensor, in the convention of
docs/spec/log-format.md (tau_h positive in the joint's positive direction), is

    tau_h = I(t) x'' + B(t, x) x' + tau_e(t, x) + tau_srs + tau_w + tau_r + tau_f - tau_bg

with the elastic torque ``tau_e = f_t f_tau K0 F(x) + k3 x^3``, ``F(x) = int_0^x f_a``
(so its local stiffness dtau_e/dx is ``K0 f_t f_tau f_a(x) + 3 k3 x^2``), the wobbling
mass's tau_w, the reflex tau_r, the footplate friction tau_f and the subject's own
torque tau_bg (background plus voluntary). The equations of each part are in
:mod:`labsim.spec`'s docstrings and docs/labsim.md.
"""

from __future__ import annotations

import numpy as np

from .lti import StateSpace, affine_scan, play_scan


# ------------------------------------------------------------------------------ factors


def time_factor(var, t: np.ndarray, duration: float) -> np.ndarray:
    """f_t(t) of a :class:`labsim.spec.Variation` (1 for t < 0: the state at the start
    holds during the pre-roll)."""
    tt = np.maximum(t, 0.0)
    r = var.ratio
    if var.time == "constant":
        return np.ones_like(t)
    if var.time == "linear":
        return 1.0 + (r - 1.0) * tt / duration
    if var.time == "saturating":
        return 1.0 + (r - 1.0) * -np.expm1(-tt / var.tau_s)
    if var.time == "switching":
        phase = np.floor((tt - var.phase_s) / (0.5 * var.period_s))
        high = (tt >= var.phase_s) & (np.mod(phase, 2) == 1)
        return np.where(high, r, 1.0)
    if var.time == "sine":
        arg = 2 * np.pi * (tt + var.phase_s) / var.period_s
        return 1.0 + (r - 1.0) * np.sin(arg)
    raise ValueError(f"Variation.time must be one of constant, linear, saturating, "
                     f"switching, sine; got {var.time!r}")


def angle_factor(var, x: np.ndarray) -> np.ndarray:
    """f_a(x), 1 at x = 0."""
    c, x0 = var.angle_coef, var.angle_ref_rad
    if var.angle == "constant" or c == 0:
        return np.ones_like(x)
    if var.angle == "exp":
        return np.exp(c * (x - x0)) / np.exp(-c * x0)
    if var.angle == "quadratic":
        return 1.0 + c * ((x - x0) ** 2 - x0 ** 2)
    if var.angle == "linear":
        return 1.0 + c * x
    raise ValueError(f"Variation.angle must be one of constant, exp, quadratic, linear; "
                     f"got {var.angle!r}")


def angle_integral(var, x: np.ndarray) -> np.ndarray:
    """F(x) = int_0^x f_a (the elastic torque's shape; F'(x) = f_a(x))."""
    c, x0 = var.angle_coef, var.angle_ref_rad
    if var.angle == "constant" or c == 0:
        return np.array(x, dtype=float)
    if var.angle == "exp":
        return np.expm1(c * x) / c
    if var.angle == "quadratic":
        return x + c * (((x - x0) ** 3 + x0 ** 3) / 3.0 - x0 ** 2 * x)
    if var.angle == "linear":
        return x + 0.5 * c * x * x
    raise ValueError(f"Variation.angle must be one of constant, exp, quadratic, linear; "
                     f"got {var.angle!r}")


def torque_factor(var, tau_bg: np.ndarray) -> np.ndarray:
    return 1.0 + var.torque_coef * np.abs(tau_bg)


def scalar_factor(var, t, duration, tau_bg):
    """f_t f_tau (n, N): the part of a variation that does not depend on the angle."""
    if var is None:
        return np.ones_like(tau_bg)
    return time_factor(var, t, duration)[None, :] * torque_factor(var, tau_bg)


# ------------------------------------------------------------------------------ parts


def as_matrix(value, n: int, name: str) -> np.ndarray:
    """A scalar (n = 1, or a diagonal), a per-joint list or an n x n list as (n, n)."""
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        return np.eye(n) * float(a)
    if a.shape == (n,):
        return np.diag(a)
    if a.shape == (n, n):
        return a
    raise ValueError(f"limb.{name}: expected a number, {n} numbers or an {n}x{n} matrix, "
                     f"got shape {a.shape}")


def per_joint(value, n: int, name: str, first_only: bool = False) -> np.ndarray:
    """A scalar (every joint, or joint 1 only with ``first_only``) or n numbers as (n,)."""
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        out = np.zeros(n) if first_only else np.full(n, float(a))
        out[0] = float(a)
        return out
    if a.shape == (n,):
        return a.copy()
    raise ValueError(f"{name}: expected a number or {n} numbers, got shape {a.shape}")


def reflex_filter(rx) -> StateSpace:
    """The activation dynamics LP (unit DC gain) of a :class:`labsim.spec.Reflex`.

    The triple pole is realised as poles wc (1 - 1e-3), wc, wc (1 + 1e-3) (a response
    within 1e-6 of the exact triple pole): a repeated pole has no modal form.
    """
    w = 2 * np.pi * rx.f_hz
    if rx.form in ("second_order", "cascade"):
        if rx.damping <= 0:
            raise ValueError(f"reflex.damping must be positive, got {rx.damping!r}")
        poles = np.roots([1.0, 2 * rx.damping * w, w * w])
        if rx.form == "cascade":
            poles = np.append(poles, -1.0 / rx.tau_s)
    elif rx.form == "triple_pole":
        poles = -w * np.array([1 - 1e-3, 1.0, 1 + 1e-3])
    else:
        raise ValueError(f"reflex.form must be second_order, triple_pole or cascade; got "
                         f"{rx.form!r}")
    gain = float(np.real(np.prod(-poles)))
    return StateSpace.from_zpk([], poles, gain)


def rectifier(rx, v: np.ndarray) -> np.ndarray:
    th = rx.threshold_rad_s
    if rx.rectify == "positive":
        return np.maximum(v - th, 0.0)
    if rx.rectify == "negative":
        return np.minimum(v + th, 0.0)
    if rx.rectify == "none":
        return v
    raise ValueError(f"reflex.rectify must be positive, negative or none; got {rx.rectify!r}")


def delayed(x: np.ndarray, delay_steps: float) -> np.ndarray:
    """x(t - d) on the grid, linearly interpolated; 0 before the grid's start (rest)."""
    n = x.shape[-1]
    pos = np.arange(n) - delay_steps
    out = np.empty_like(x)
    for j in range(x.shape[0]):
        out[j] = np.interp(pos, np.arange(n), x[j], left=0.0)
    return out


def wobble_filter(wm, n: int) -> list:
    """Per joint: the state space from the joint's acceleration to tau_w (None: none).

    With e = x - x_w: e'' = x'' - tau_w / I_w and tau_w = k e + b e' (k = I_w wn^2,
    b = 2 zeta I_w wn), i.e. tau_w / x'' = I_w (b s + k) / (I_w s^2 + b s + k).
    """
    inertia = per_joint(wm.inertia, n, "wobbling.inertia")
    f = per_joint(wm.f_hz, n, "wobbling.f_hz")
    zeta = per_joint(wm.damping, n, "wobbling.damping")
    out = []
    for j in range(n):
        if inertia[j] <= 0:
            out.append(None)
            continue
        wn = 2 * np.pi * f[j]
        k, b = inertia[j] * wn * wn, 2 * zeta[j] * inertia[j] * wn
        out.append(StateSpace.from_tf([inertia[j] * b, inertia[j] * k],
                                      [inertia[j], b, k]))
    return out


def lugre(v: np.ndarray, fp, h: float):
    """LuGre friction for the velocity trajectory v (n, N), exactly per step.

    Given v, the bristle state obeys the linear z' = v - a(t) z, a = sigma0 |v| / g(v):
    its exact step with v held at the step's mid value over h is z[k] = e^{-a h} z[k-1] +
    v (1 - e^{-a h}) / a (second order in h), an affine recursion solved by a scan
    (:func:`labsim.lti.affine_scan`).
    """
    Fs = fp.Fs if fp.Fs is not None else 1.5 * fp.Fc

    def rate(vel):
        return fp.sigma0 * np.abs(vel) / (fp.Fc + (Fs - fp.Fc) * np.exp(-(vel / fp.v_s) ** 2))

    vm = np.concatenate([v[:, :1], 0.5 * (v[:, 1:] + v[:, :-1])], axis=1)
    am = rate(vm)
    ah = am * h
    c = np.exp(-ah)
    d = np.where(ah > 1e-12, vm * -np.expm1(-ah) / np.where(ah > 1e-12, am, 1.0), vm * h)
    z = np.vstack([affine_scan(c[j], d[j]) for j in range(v.shape[0])])
    dz = v - rate(v) * z
    return fp.sigma0 * z + fp.sigma1 * dz + fp.sigma2 * v


def friction(v: np.ndarray, fp, h: float) -> np.ndarray:
    if fp.friction == "tanh":
        return fp.Fc * np.tanh(v / fp.v_s) + fp.sigma2 * v
    if fp.friction == "lugre":
        return lugre(v, fp, h)
    raise ValueError(f"footplate.friction must be None, 'tanh' or 'lugre'; got "
                     f"{fp.friction!r}")


def soft_clip_below(tau: np.ndarray, limit: float) -> np.ndarray:
    """tau kept above -limit, smoothly (a hyperbola of width 5 % of the limit)."""
    eps = 0.05 * limit
    y = tau + limit
    return -limit + 0.5 * (y + np.sqrt(y * y + eps * eps))


class LimbModel:
    """The limb side, prepared once per recording (:func:`labsim.simulate`).

    ``torque(x, v, a)`` gives tau_h (n, N) and its parts for the joint trajectories
    (n, N) on the fine grid ``t`` of step ``h``.
    """

    def __init__(self, spec, t: np.ndarray, h: float, tau_bg: np.ndarray, slow: np.ndarray):
        n = spec.n_dof
        lb = spec.limb
        self.spec, self.t, self.h, self.n = spec, t, h, n
        self.K0 = as_matrix(lb.K, n, "K")
        self.B0 = as_matrix(lb.B, n, "B")
        self.I0 = as_matrix(lb.I, n, "I")
        self.k3 = per_joint(lb.k3, n, "limb.k3")
        self.srs_K = per_joint(lb.srs_K, n, "limb.srs_K")
        self.tau_bg = tau_bg
        T = spec.duration_s
        self.fK = scalar_factor(lb.K_var, t, T, tau_bg)
        self.fB = scalar_factor(lb.B_var, t, T, tau_bg)
        self.fI = scalar_factor(lb.I_var, t, T, tau_bg)
        rx = spec.reflex
        if rx is not None:
            self.G = per_joint(rx.gain, n, "reflex.gain", first_only=True)[:, None] * \
                scalar_factor(rx.gain_var, t, T, tau_bg)
            if rx.gain_var is not None:
                self.G = self.G * angle_factor(rx.gain_var, slow)
            self.reflex_lp = reflex_filter(rx)
        self.wobble = wobble_filter(spec.wobbling, n) if spec.wobbling else None
        self.fp = spec.footplate
        self.contact = None
        if self.fp is not None and self.fp.backlash_rad:
            w = 2 * np.pi * self.fp.contact_hz
            self.contact = StateSpace.from_zpk([], np.roots([1.0, 1.4 * w, w * w]), w * w,
                                               derivatives=2)

    def kinematics(self, x, v, a):
        """The footplate's angle, velocity, acceleration: the encoder's x, or with backlash
        the play operator's output (half-width backlash_rad) through the contact's
        2nd-order low-pass (contact_hz, damping 0.7)."""
        if self.contact is None:
            return x, v, a
        played = play_scan(x.T, self.fp.backlash_rad).T
        out = [self.contact.simulate(played[j], self.h, smooth=True) for j in range(self.n)]
        return (np.vstack([o[0] for o in out]), np.vstack([o[1] for o in out]),
                np.vstack([o[2] for o in out]))

    def torque(self, x, v, a) -> tuple[np.ndarray, dict]:
        lb, n = self.spec.limb, self.n
        x, v, a = self.kinematics(x, v, a)
        Kv, Bv, Iv = lb.K_var, lb.B_var, lb.I_var
        Fx = angle_integral(Kv, x) if Kv is not None else x
        parts = {"elastic": self.fK * (self.K0 @ Fx) + self.k3[:, None] * x ** 3}
        vB = v * angle_factor(Bv, x) if Bv is not None else v
        parts["viscous"] = self.fB * (self.B0 @ vB)
        aI = a * angle_factor(Iv, x) if Iv is not None else a
        parts["inertial"] = self.fI * (self.I0 @ aI)
        if self.srs_K.any():
            parts["srs"] = self.srs_K[:, None] * (x - play_scan(
                x.T, lb.srs_limit_rad).T)
        if self.wobble is not None:
            parts["wobble"] = np.vstack([
                np.zeros(x.shape[1]) if w is None else w.simulate(a[j], self.h, smooth=True)
                for j, w in enumerate(self.wobble)])
        rx = self.spec.reflex
        if rx is not None:
            u = self.G * rectifier(rx, delayed(v, rx.delay_s / self.h))
            parts["reflex"] = np.vstack([self.reflex_lp.simulate(u[j], self.h, smooth=True)
                                         for j in range(n)])
        if self.fp is not None and self.fp.friction:
            parts["friction"] = friction(v, self.fp, self.h)
        parts["subject"] = -self.tau_bg
        total = sum(parts.values())
        if self.fp is not None and self.fp.contact_limit_nm:
            clipped = soft_clip_below(total, self.fp.contact_limit_nm)
            parts["contact"] = clipped - total
            total = clipped
        return total, parts

    def local(self, x: np.ndarray, idx: np.ndarray) -> dict:
        """Local K, B, I (n, n, M) and reflex gain (n, M) at the angles x (n, M) at the
        fine-grid points ``idx``: dtau_e/dx, the coefficients of x' and of x''
        (docs/labsim.md, the truth)."""
        lb = self.spec.limb
        out = {}
        for name, M0, f, var in (("K", self.K0, self.fK, lb.K_var),
                                 ("B", self.B0, self.fB, lb.B_var),
                                 ("I", self.I0, self.fI, lb.I_var)):
            fa = angle_factor(var, x) if var is not None else np.ones_like(x)
            # row i carries joint i's factor f_t f_tau, column j the angle factor of x_j
            out[name] = M0[:, :, None] * f[:, None, idx] * fa[None, :, :]
        out["K"] = out["K"] + np.einsum("ij,jt->ijt", np.eye(self.n), 3 * self.k3[:, None] * x ** 2)
        if self.spec.reflex is not None:
            out["G"] = self.G[:, idx]
        return out
