"""The declared (nominal) experimental set-up, plus the arm that is simulated.

Everything in the declared part goes into a trial's metadata (log-format.md keys); the arm
matrices are the simulation's truth and go only under ``meta["simulation"]``.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from trialformat import FORMAT
from trialformat import reference as ref

from .controller import ControllerConfig
from .errors import SetupError

_ROBOT_SCALARS = ("m1", "L1", "lc1", "I1", "m2", "L2", "lc2", "I2")


def _tuning_of(controller: dict) -> str:
    """Name of the reference tuning whose Mbar and wn a controller block has, else custom."""
    for name in ("reference", "robust"):
        block = ref.controller(name)
        if all(np.allclose(controller[k], block[k]) for k in ("Mbar", "wn")):
            return name
    return "custom"


def _table_one():
    return tuple(m.copy() for m in ref.arm_matrices())


@dataclass(frozen=True)
class Setup:
    """A declared set-up and the simulated arm.

    Attributes
    ----------
    n_dof : int
    fs : float [Hz]
        Control and sampling rate.
    posture_deg : list of float [deg]
    robot, friction, sensors, controller : dict
        log-format.md metadata blocks (the nominal model the experimenter knows).
    arm : tuple of ndarray (M_h, B_h, K_h)
        The simulated human arm [kg m^2], [N m s/rad], [N m/rad]; Table I by default.
    levels : dict
        ``friction_level``, ``resolution_level`` when built from reference levels (for
        naming); empty otherwise.
    """

    n_dof: int
    fs: float
    posture_deg: list
    robot: dict
    friction: dict
    sensors: dict
    controller: dict
    arm: tuple = field(default_factory=_table_one)
    levels: dict = field(default_factory=dict)

    def __post_init__(self):
        n = self.n_dof
        for name, mat in zip(("M_h", "B_h", "K_h"), self.arm):
            if np.shape(mat) != (n, n) or not np.all(np.isfinite(mat)):
                raise SetupError(f"arm matrix {name} must be a finite {n}x{n} array, got "
                                 f"{np.asarray(mat).tolist()!r}")
        if len(self.posture_deg) != n:
            raise SetupError(f"posture_deg has {len(self.posture_deg)} values for n_dof={n}")
        if not self.fs > 0:
            raise SetupError(f"fs must be > 0, got {self.fs!r}")
        self.controller_config()  # validates the controller block

    # ------------------------------------------------------------------ constructors
    @classmethod
    def reference(cls, friction_level: int = 0, resolution_level: int = 0,
                  tuning: str = "reference") -> "Setup":
        """The reference set-up (reference.md) at the given levels and tuning."""
        r = ref.reference()
        try:
            friction = ref.friction_level(friction_level, 2)
            sensors = ref.sensor_level(resolution_level)
            controller = ref.controller(tuning)
        except ValueError as exc:
            raise SetupError(str(exc)) from None
        return cls(n_dof=2, fs=1.0 / r["timing"]["control_period_s"],
                   posture_deg=list(r["human_arm"]["posture_deg"]), robot=ref.robot(),
                   friction=friction, sensors=sensors, controller=controller,
                   levels={"friction_level": friction_level,
                           "resolution_level": resolution_level})

    @classmethod
    def from_metadata(cls, meta: dict) -> "Setup":
        """The declared set-up of a trial's metadata (absent keys from the reference);
        the arm is Table I (a real trial's arm is unknown)."""
        n = int(meta.get("n_dof", 2))
        r = ref.reference()
        blocks = {"robot": ref.robot(), "friction": ref.friction_level(0, n),
                  "sensors": ref.sensor_level(0), "controller": ref.controller("reference")}
        for key, default in blocks.items():
            default.update(copy.deepcopy(meta.get(key, {})))
        if "tuning" not in meta.get("controller", {}):
            blocks["controller"]["tuning"] = _tuning_of(blocks["controller"])
        return cls(n_dof=n, fs=float(meta.get("fs", 1.0 / r["timing"]["control_period_s"])),
                   posture_deg=list(meta.get("posture_deg", r["human_arm"]["posture_deg"])),
                   **blocks)

    def with_arm(self, M_h, B_h, K_h) -> "Setup":
        """A copy simulating another arm [kg m^2], [N m s/rad], [N m/rad]."""
        arm = tuple(np.array(m, dtype=float) for m in (M_h, B_h, K_h))
        return dataclasses.replace(self, arm=arm)

    def with_controller(self, **changes) -> "Setup":
        """A copy with controller block keys changed, e.g. ``time_delay_estimation=False``
        or ``Mbar=[...]`` (the tuning becomes ``"custom"`` unless given)."""
        block = copy.deepcopy(self.controller)
        if any(k in changes for k in ("Mbar", "wn", "M_rd", "B_rd", "K_rd")):
            block["tuning"] = "custom"
        block.update(changes)
        return dataclasses.replace(self, controller=block)

    # ------------------------------------------------------------------ views
    @property
    def Ts(self) -> float:
        """Control period [s]."""
        return 1.0 / self.fs

    def controller_config(self) -> ControllerConfig:
        return ControllerConfig.from_metadata(self.controller, Ts=self.Ts)

    def to_metadata(self) -> dict:
        """The declared set-up as log-format.md metadata keys (no trial-specific keys)."""
        return {"format": FORMAT, "fs": self.fs, "n_dof": self.n_dof,
                "posture_deg": list(self.posture_deg),
                "controller": copy.deepcopy(self.controller),
                "sensors": copy.deepcopy(self.sensors),
                "robot": copy.deepcopy(self.robot),
                "friction": copy.deepcopy(self.friction)}

    def arm_metadata(self) -> dict:
        return {name: np.asarray(m).tolist() for name, m in zip(("M_h", "B_h", "K_h"), self.arm)}

    def plant_parameters(self) -> dict:
        """FMU parameter name -> value of the declared set-up and the simulated arm."""
        n = self.n_dof
        p = {f"posture_deg[{j}]": float(v) for j, v in enumerate(self.posture_deg, 1)}
        for name, mat in zip(("M_h", "B_h", "K_h"), self.arm):
            for i in range(n):
                for j in range(n):
                    p[f"arm.{name}[{i + 1},{j + 1}]"] = float(mat[i][j])
        for key in _ROBOT_SCALARS:
            if key in self.robot:
                p[f"robot.{key}"] = float(self.robot[key])
        for j, v in enumerate(self.robot.get("Jm", []), 1):
            p[f"robot.Jm[{j}]"] = float(v)
        if "gravity_tilt_deg" in self.robot:
            p["gravity.tilt_deg"] = float(self.robot["gravity_tilt_deg"])
        for key in ("Fc", "Fs", "sigma2"):
            for j, v in enumerate(self.friction[key], 1):
                p[f"friction.{key}[{j}]"] = float(v)
        for key in ("sigma0", "sigma1", "ws"):
            p[f"friction.{key}"] = float(self.friction[key])
        return p

    def encoder_resolution_rad(self) -> float:
        return math.radians(float(self.sensors["encoder_resolution_deg"]))
