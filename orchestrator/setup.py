"""The declared (nominal) experimental set-up, plus the arm that is simulated.

Everything in the declared part goes into a trial's metadata (log-format.md keys); the arm
matrices are the simulation's truth and go only under ``meta["simulation"]``.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
from dataclasses import dataclass, field

import numpy as np

from trialformat import FORMAT
from trialformat import reference as ref

from .controller import ControllerConfig
from .errors import SetupError

#: Robot link scalars of the metadata (m1, L1, lc1, I1, m2, ...), FMU ``robot.<name>``.
_ROBOT_SCALAR = re.compile(r"(?:m|L|lc|I)([1-9][0-9]*)")
#: Built-in reference configurations: name -> number of joints.
REFERENCE_ARMS = {"2dof": 2, "3dof": 3}


def reference_arm_of(n_dof: int) -> str | None:
    """The built-in reference configuration of n joints (``"2dof"``, ``"3dof"``), or None."""
    return next((name for name, n in REFERENCE_ARMS.items() if n == n_dof), None)


def _tuning_of(controller: dict, n_dof: int = 2) -> str:
    """Name of the reference tuning whose Mbar and wn a controller block has, else custom."""
    arm = reference_arm_of(n_dof)
    if arm is None:
        return "custom"
    for name in ("reference", "robust"):
        block = ref.controller(name, arm)
        if all(np.shape(controller[k]) == np.shape(block[k])
               and np.allclose(controller[k], block[k]) for k in ("Mbar", "wn")):
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
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise SetupError(f"n_dof must be a positive integer, got {n!r}")
        if len(self.arm) != 3:
            raise SetupError(f"arm must be (M_h, B_h, K_h), got {len(self.arm)} matrices")
        for name, mat in zip(("M_h", "B_h", "K_h"), self.arm):
            if np.shape(mat) != (n, n) or not np.all(np.isfinite(mat)):
                raise SetupError(f"arm matrix {name} must be a finite {n}x{n} array for "
                                 f"n_dof={n}, got shape {np.shape(mat)}: "
                                 f"{np.asarray(mat).tolist()!r}")
        if len(self.posture_deg) != n:
            raise SetupError(f"posture_deg has {len(self.posture_deg)} values for n_dof={n}; "
                             f"expected shape ({n},)")
        for block, keys in (("controller", ("M_rd", "B_rd", "K_rd", "theta_rd_deg", "Mbar", "wn")),
                            ("friction", ("Fc", "Fs", "sigma2")), ("robot", ("Jm",))):
            for key in keys:
                value = getattr(self, block).get(key)
                if value is not None and np.shape(value) != (n,):
                    raise SetupError(f"{block} {key} has shape {np.shape(value)} for "
                                     f"n_dof={n}; expected shape ({n},)")
        links = {int(m.group(1)) for m in map(_ROBOT_SCALAR.fullmatch, self.robot) if m}
        if links and max(links) > n:
            raise SetupError(f"robot has link {max(links)} parameters for n_dof={n}")
        if not self.fs > 0:
            raise SetupError(f"fs must be > 0, got {self.fs!r}")
        self.controller_config()  # validates the controller block

    # ------------------------------------------------------------------ constructors
    @classmethod
    def reference(cls, friction_level: int = 0, resolution_level: int = 0,
                  tuning: str = "reference", arm: str = "2dof") -> "Setup":
        """The reference set-up at the given levels and tuning.

        ``arm``: ``"2dof"`` (reference.md, Table I) or ``"3dof"`` (reference-3dof.md:
        shoulder, elbow, wrist; its arm matrices are simulated).
        """
        if arm not in REFERENCE_ARMS:
            raise SetupError(f"arm must be one of {sorted(REFERENCE_ARMS)}, got {arm!r}")
        n = REFERENCE_ARMS[arm]
        r = ref.reference(arm)
        try:
            friction = ref.friction_level(friction_level, n, arm)
            sensors = ref.sensor_level(resolution_level)
            controller = ref.controller(tuning, arm)
        except ValueError as exc:
            raise SetupError(str(exc)) from None
        return cls(n_dof=n, fs=1.0 / r["timing"]["control_period_s"],
                   posture_deg=list(r["human_arm"]["posture_deg"]), robot=ref.robot(arm),
                   friction=friction, sensors=sensors, controller=controller,
                   arm=ref.arm_matrices(arm),
                   levels={"friction_level": friction_level,
                           "resolution_level": resolution_level})

    @classmethod
    def from_metadata(cls, meta: dict) -> "Setup":
        """The declared set-up of a trial's metadata (absent keys from the reference of
        its number of joints); the arm is that reference's (Table I for two joints; a real
        trial's arm is unknown), zeros when there is no reference of n joints."""
        n = int(meta.get("n_dof", 2))
        known = reference_arm_of(n)  # None: no built-in reference of n joints
        arm = known or "2dof"
        r = ref.reference(arm)
        blocks = {"robot": ref.robot(arm) if known else {},
                  "friction": ref.friction_level(0, n, arm),
                  "sensors": ref.sensor_level(0),
                  "controller": ref.controller("reference", arm) if known else {}}
        for key, default in blocks.items():
            default.update(copy.deepcopy(meta.get(key, {})))
        if "tuning" not in meta.get("controller", {}):
            blocks["controller"]["tuning"] = _tuning_of(blocks["controller"], n)
        return cls(n_dof=n, fs=float(meta.get("fs", 1.0 / r["timing"]["control_period_s"])),
                   posture_deg=list(meta.get("posture_deg", r["human_arm"]["posture_deg"])),
                   arm=ref.arm_matrices(arm) if known else
                   tuple(np.zeros((n, n)) for _ in range(3)), **blocks)

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
        """The declared set-up as log-format.md metadata keys (no trial-specific keys).
        The sampler reads tau_h before each sample's command acts: ``sensors`` declares
        ``torque_sampling = "left_limit"`` (log-format.md, "Conventions a lab states")."""
        return {"format": FORMAT, "fs": self.fs, "n_dof": self.n_dof,
                "posture_deg": list(self.posture_deg),
                "controller": copy.deepcopy(self.controller),
                "sensors": dict(copy.deepcopy(self.sensors), torque_sampling="left_limit"),
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
        for key, value in self.robot.items():
            if _ROBOT_SCALAR.fullmatch(key):
                p[f"robot.{key}"] = float(value)
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
