"""IMBIC: internal model based impedance control with time-delay estimation (reference.md s. 7).

The controller runs on Python floats (one loop over the joints, constants precomputed per
joint): at 1 kHz over 50 s it is evaluated 50 000 times, and small numpy arrays would cost
more than the arithmetic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from trialformat import reference as ref

from .errors import DivergenceError, SetupError

#: A closed loop whose motor torque command leaves +-this [N m] has diverged.
TORQUE_LIMIT_NM = 1.0e3


@dataclass(frozen=True)
class ControllerConfig:
    """Parameters of the IMBIC controller, per joint.

    Attributes
    ----------
    M_rd, B_rd, K_rd : tuple of float [kg m^2], [N m s/rad], [N m/rad]
        Desired (internal model) inertia, damping and stiffness.
    theta_rd : tuple of float [rad]
        Internal model rest position (deviation from the posture).
    Mbar : tuple of float [kg m^2]
        Constant inertia estimate of the time-delay estimation.
    wn : tuple of float [rad/s]
        Tracking bandwidth: Kd = 2 wn, Kp = wn^2.
    Ts : float [s]
        Control period.
    tde : bool
        Use the time-delay estimation term ``tau_m[n-1] - Mbar a_hat[n-1]``; without it the
        controller is the internal model plus a PD tracking law scaled by Mbar.
    tuning : str
        Name of the tuning (``"reference"``, ``"robust"`` or ``"custom"``).
    """

    M_rd: tuple
    B_rd: tuple
    K_rd: tuple
    theta_rd: tuple
    Mbar: tuple
    wn: tuple
    Ts: float = 1e-3
    tde: bool = True
    tuning: str = "reference"

    def __post_init__(self):
        n = len(self.M_rd)
        for name in ("B_rd", "K_rd", "theta_rd", "Mbar", "wn"):
            if len(getattr(self, name)) != n:
                raise SetupError(f"controller {name} has {len(getattr(self, name))} values, "
                                 f"M_rd has {n}")
        for name in ("M_rd", "Mbar"):
            bad = [v for v in getattr(self, name) if not v > 0]
            if bad:
                raise SetupError(f"controller {name} must be > 0 per joint, got {bad}")
        if not self.Ts > 0:
            raise SetupError(f"controller period Ts must be > 0, got {self.Ts!r}")

    @property
    def n_dof(self) -> int:
        return len(self.M_rd)

    @classmethod
    def reference(cls, tuning: str = "reference", Ts: float = 1e-3) -> "ControllerConfig":
        """The reference defaults with the ``"reference"`` or ``"robust"`` tuning."""
        try:
            block = ref.controller(tuning)
        except ValueError as exc:
            raise SetupError(str(exc)) from None
        return cls.from_metadata(block, Ts=Ts)

    @classmethod
    def from_metadata(cls, block: dict, Ts: float = 1e-3) -> "ControllerConfig":
        """From a log-format ``controller`` block (``theta_rd_deg`` in degrees)."""
        try:
            return cls(M_rd=tuple(map(float, block["M_rd"])),
                       B_rd=tuple(map(float, block["B_rd"])),
                       K_rd=tuple(map(float, block["K_rd"])),
                       theta_rd=tuple(math.radians(float(v)) for v in block["theta_rd_deg"]),
                       Mbar=tuple(map(float, block["Mbar"])),
                       wn=tuple(map(float, block["wn"])),
                       Ts=float(Ts), tde=bool(block.get("time_delay_estimation", True)),
                       tuning=str(block.get("tuning", "custom")))
        except KeyError as exc:
            raise SetupError(f"controller block lacks key {exc.args[0]!r}") from None


class IMBIC:
    """The IMBIC control law of reference.md section 7, one sample at a time.

    Parameters
    ----------
    config : ControllerConfig
    perturbed_dof : int or None
        1-based joint k whose internal model receives ``u_k = -tau_h_k + tau_delta_k``;
        the others receive ``u_j = 0`` (decomposition masking: held at theta_rd).
        None: every joint receives ``-tau_h_j + tau_delta_j``.
    torque_limit : float [N m]
        A command beyond it (or not finite) means the loop diverged: DivergenceError.
    """

    def __init__(self, config: ControllerConfig, perturbed_dof: int | None, *,
                 torque_limit: float = TORQUE_LIMIT_NM):
        n = config.n_dof
        if perturbed_dof is not None and not 1 <= perturbed_dof <= n:
            raise SetupError(f"perturbed_dof must be None or in 1..{n}, got {perturbed_dof!r}")
        self.config = config
        self.perturbed_dof = perturbed_dof
        self.torque_limit = float(torque_limit)
        self._joints = tuple(range(n))
        self._active = tuple(perturbed_dof is None or j == perturbed_dof - 1 for j in range(n))
        self._ts, self._ts2, self._tde = config.Ts, config.Ts * config.Ts, config.tde
        c = config
        # one tuple of constants per joint: the per-sample loop unpacks instead of indexing
        self._per_joint = tuple(
            (j, n + j, c.M_rd[j], c.B_rd[j], c.K_rd[j], c.theta_rd[j], c.Mbar[j], 2.0 * c.wn[j],
             c.wn[j] * c.wn[j], self._active[j]) for j in range(n))
        self.reset()

    def reset(self) -> None:
        """Zero the internal model and the history terms (theta[-1], theta[-2], tau_m[-1])."""
        n = self.config.n_dof
        self._w_m = [0.0] * n
        self._th_m = list(self.config.theta_rd)
        self._theta_1 = [0.0] * n
        self._theta_2 = [0.0] * n
        self._tau_1 = [0.0] * n

    @property
    def internal_model(self) -> tuple[list, list]:
        """Current internal model state ``(th_m, w_m)`` [rad], [rad/s]."""
        return list(self._th_m), list(self._w_m)

    def step(self, measured, tau_delta) -> list:
        """Motor torque command tau_m[n] [N m] from the samples of instant n.

        Parameters
        ----------
        measured : sequence of float
            The sampled signals of instant n, ``theta[1..n]`` [rad] then ``tau_h[1..n]``
            [N m] (the plant's output order, so the master passes one list).
        tau_delta : sequence of float [N m]
            Perturbation tau_delta[n].

        Returns
        -------
        list of float [N m]
            tau_m[n], to be applied from n Ts to (n+1) Ts.

        Raises
        ------
        DivergenceError
            |tau_m_j| above the torque limit or not finite (the loop has diverged).
        """
        ts, ts2, tde, lim = self._ts, self._ts2, self._tde, self.torque_limit
        w_m, th_m, th_1, th_2, tau_1 = (self._w_m, self._th_m, self._theta_1,
                                        self._theta_2, self._tau_1)
        out = []
        for j, jh, m_rd, b_rd, k_rd, th_rd, mbar, kd, kp, active in self._per_joint:
            th = measured[j]
            u = tau_delta[j] - measured[jh] if active else 0.0
            wm, thm, th1 = w_m[j], th_m[j], th_1[j]
            a_m = (u - b_rd * wm - k_rd * (thm - th_rd)) / m_rd
            w_hat = (th - th1) / ts
            tau = mbar * (a_m + kd * (wm - w_hat) + kp * (thm - th))
            if tde:
                tau += tau_1[j] - mbar * ((th - 2.0 * th1 + th_2[j]) / ts2)
            if not -lim < tau < lim:
                raise DivergenceError(f"tau_m[{j + 1}]={tau!r} N m beyond the torque limit "
                                      f"{lim!r} N m")
            wm += ts * a_m
            w_m[j] = wm
            th_m[j] = thm + ts * wm
            th_2[j] = th1
            th_1[j] = th
            tau_1[j] = tau
            out.append(tau)
        return out
