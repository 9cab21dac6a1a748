"""The variable table of the ArmExoPlant FMU: the single source of truth.

Every FMI variable of the plant is declared once, here.  The build
(:mod:`fmus.generate`) writes from this table

* ``fmus/ArmExoPlant/variables.h``: the C value-reference enum ``vr_...``, the
  names, causalities and start values the C code uses, and
* ``fmus/ArmExoPlant/modelDescription.xml``,

and ``tests/plant/test_variables.py`` proves that the XML, the C code and these
Python constants agree.  Never edit the generated files by hand.

Naming follows the plant contract (``docs/spec/plant-contract.md``): a nested
configuration dict path joined with ``'.'``, arrays 1-based ``[i]``, matrices
``[i,j]``.  Value references are the positions in :data:`VARIABLES`.

The defaults are the reference configuration (``docs/spec/reference.md``,
friction level 0, every effect of ``docs/spec/effects.md`` off).
"""
from __future__ import annotations

import uuid
from dataclasses import dataclass

__all__ = [
    "Variable",
    "VARIABLES",
    "BY_NAME",
    "VR",
    "UNITS",
    "PARAMETERS",
    "INPUTS",
    "OUTPUTS",
    "MODEL_NAME",
    "GUID",
    "N_JOINTS",
    "FRICTION_LEVELS",
    "friction_parameters",
    "c_identifier",
]

MODEL_NAME = "ArmExoPlant"
N_JOINTS = 2


@dataclass(frozen=True)
class Variable:
    """One real FMI variable.

    Attributes
    ----------
    name : str
        FMI name, e.g. ``"arm.M_h[1,2]"``.
    causality : str
        ``"parameter"``, ``"input"`` or ``"output"``.
    unit : str
        Unit name (declared in :data:`UNITS`), ``""`` for dimensionless.
    description : str
        Short description for the model description.
    start : float or None
        Start value; parameters and inputs have one, outputs do not.
    min : float or None
        Lower bound written to the XML (the C code checks the physics itself).
    """

    name: str
    causality: str
    unit: str
    description: str
    start: float | None = None
    min: float | None = None

    @property
    def variability(self) -> str:
        return "fixed" if self.causality == "parameter" else "continuous"

    @property
    def vr(self) -> int:
        return VR[self.name]


# Unit name -> exponents of the SI base units and rad, plus factor (for deg).
UNITS: dict[str, dict[str, float]] = {
    "s": {"s": 1},
    "rad": {"rad": 1},
    "deg": {"rad": 1, "factor": 0.017453292519943295},
    "rad/s": {"rad": 1, "s": -1},
    "kg": {"kg": 1},
    "m": {"m": 1},
    "kg.m2": {"kg": 1, "m": 2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N.m/rad": {"kg": 1, "m": 2, "s": -2, "rad": -1},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},
}

FRICTION_LEVELS = (
    {"Fc": 0.0, "Fs": 0.0, "sigma2": 0.0},
    {"Fc": 0.10, "Fs": 0.15, "sigma2": 0.02},
    {"Fc": 0.20, "Fs": 0.30, "sigma2": 0.04},
    {"Fc": 0.40, "Fs": 0.60, "sigma2": 0.08},
)


def friction_parameters(level: int) -> dict[str, float]:
    """FMU parameter values of reference friction level 0..3 (both joints)."""
    if level not in range(len(FRICTION_LEVELS)):
        raise ValueError(f"friction level must be 0..3, got {level!r}")
    out = {}
    for key, value in FRICTION_LEVELS[level].items():
        for j in (1, 2):
            out[f"friction.{key}[{j}]"] = value
    return out


_M_H = ((0.187, 0.084), (0.079, 0.060))
_B_H = ((0.651, 0.239), (0.236, 0.407))
_K_H = ((7.967, 3.187), (1.663, 6.901))


def _build() -> list[Variable]:
    v: list[Variable] = []
    P = "parameter"

    def par(name, unit, desc, start, vmin=None):
        v.append(Variable(name, P, unit, desc, float(start), vmin))

    par("rk4_step", "s", "Fixed step of the internal classical RK4 solver", 1e-5, 0.0)
    for j, q0 in enumerate((62.708, 77.260), 1):
        par(f"posture_deg[{j}]", "deg", f"Posture (absolute joint angle) of joint {j}", q0)
    for key, mat, unit, what in (
        ("M_h", _M_H, "kg.m2", "inertia"),
        ("B_h", _B_H, "N.m.s/rad", "damping"),
        ("K_h", _K_H, "N.m/rad", "stiffness"),
    ):
        for i in (1, 2):
            for j in (1, 2):
                par(f"arm.{key}[{i},{j}]", unit, f"Human arm {what} matrix element ({i},{j}), used as printed", mat[i - 1][j - 1])
    robot = (
        ("m1", "kg", "Mass of link 1", 1.5),
        ("L1", "m", "Length of link 1", 0.30),
        ("lc1", "m", "Distance joint 1 to centre of mass of link 1", 0.15),
        ("I1", "kg.m2", "Inertia of link 1 about its centre of mass", 0.0113),
        ("m2", "kg", "Mass of link 2", 1.0),
        ("L2", "m", "Length of link 2", 0.35),
        ("lc2", "m", "Distance joint 2 to centre of mass of link 2", 0.175),
        ("I2", "kg.m2", "Inertia of link 2 about its centre of mass", 0.0102),
    )
    for name, unit, desc, start in robot:
        par(f"robot.{name}", unit, desc, start, 0.0)
    for j in (1, 2):
        par(f"robot.Jm[{j}]", "kg.m2", f"Reflected motor/transmission inertia of joint {j}", 0.010, 0.0)
    for key, unit, desc in (
        ("Fc", "N.m", "LuGre Coulomb friction torque"),
        ("Fs", "N.m", "LuGre static (stiction) friction torque"),
        ("sigma2", "N.m.s/rad", "LuGre viscous friction coefficient"),
    ):
        for j in (1, 2):
            par(f"friction.{key}[{j}]", unit, f"{desc}, joint {j} (0 with Fc, Fs: no friction)", 0.0, 0.0)
    par("friction.sigma0", "N.m/rad", "LuGre bristle stiffness", 1.0e3, 0.0)
    par("friction.sigma1", "N.m.s/rad", "LuGre bristle damping", 1.0, 0.0)
    par("friction.ws", "rad/s", "LuGre Stribeck velocity", 0.01, 0.0)
    par("actuator_lag.time_constant_s", "s", "Actuator first-order lag time constant (0: off)", 0.0, 0.0)
    for key, unit, desc in (
        ("k_t", "N.m/rad", "Transmission stiffness motor-link (0: rigid, off)"),
        ("c_t", "N.m.s/rad", "Transmission damping motor-link"),
    ):
        for j in (1, 2):
            par(f"transmission_compliance.{key}[{j}]", unit, f"{desc}, joint {j}", 0.0, 0.0)
    for key, unit, desc in (
        ("k_s", "N.m/rad", "Cuff (interface) stiffness robot-arm (0: rigid, off)"),
        ("c_s", "N.m.s/rad", "Cuff (interface) damping robot-arm"),
    ):
        for j in (1, 2):
            par(f"interface_compliance.{key}[{j}]", unit, f"{desc}, joint {j}", 0.0, 0.0)
    par("gravity.tilt_deg", "deg", "Tilt of the robot plane from horizontal about the base x axis (0: off)", 0.0)
    par("inertia_mismatch.scale", "", "Scale of the robot's a1, a2, a3 (1: off)", 1.0, 0.0)
    par("torque_sensor_lag.time_constant_s", "s", "Torque sensor first-order lag time constant (0: off)", 0.0, 0.0)

    for j in (1, 2):
        v.append(Variable(f"tau_m[{j}]", "input", "N.m", f"Actuator torque command, joint {j}", 0.0))
    outputs = (
        ("theta", "rad", "Joint angle at the encoder, deviation from the posture"),
        ("tau_h", "N.m", "Torque robot -> arm at the torque sensor"),
        ("omega", "rad/s", "Joint velocity at the encoder"),
        ("tau_f", "N.m", "LuGre friction torque"),
        ("tau_act", "N.m", "Torque applied by the actuator"),
        ("z", "rad", "LuGre bristle deflection"),
        ("theta_link", "rad", "Link-side joint angle (deviation)"),
        ("theta_arm", "rad", "Human arm joint angle (deviation)"),
    )
    for name, unit, desc in outputs:
        for j in (1, 2):
            v.append(Variable(f"{name}[{j}]", "output", unit, f"{desc}, joint {j}"))
    return v


VARIABLES: tuple[Variable, ...] = tuple(_build())
#: name -> value reference
VR: dict[str, int] = {var.name: i for i, var in enumerate(VARIABLES)}
BY_NAME: dict[str, Variable] = {var.name: var for var in VARIABLES}
PARAMETERS = tuple(v.name for v in VARIABLES if v.causality == "parameter")
INPUTS = tuple(v.name for v in VARIABLES if v.causality == "input")
OUTPUTS = tuple(v.name for v in VARIABLES if v.causality == "output")
#: Derived from the table, so it changes whenever the table changes.
GUID = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, MODEL_NAME + repr(VARIABLES))) + "}"


def c_identifier(name: str) -> str:
    """C enum name of a variable: ``arm.M_h[1,2]`` -> ``vr_arm_M_h_1_2``."""
    out = name.replace(".", "_").replace("[", "_").replace(",", "_").replace("]", "")
    return "vr_" + out
