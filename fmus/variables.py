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
    "DEFAULTS",
    "N_LINKS",
    "Table",
    "table",
    "model_name",
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


_M_H = ((0.187, 0.084), (0.079, 0.060))
_B_H = ((0.651, 0.239), (0.236, 0.407))
_K_H = ((7.967, 3.187), (1.663, 6.901))

#: Reference configuration per number of links n (docs/spec/reference.md for n = 2,
#: docs/spec/reference-3dof.md for n = 3): the defaults of the table of each n.
DEFAULTS = {
    2: {"posture_deg": (62.708, 77.260), "M_h": _M_H, "B_h": _B_H, "K_h": _K_H,
        "links": ((1.5, 0.30, 0.15, 0.0113), (1.0, 0.35, 0.175, 0.0102)),
        "Jm": (0.010, 0.010), "friction_scale": (1.0, 1.0)},
    3: {"posture_deg": (62.708, 77.260, 10.0),
        "M_h": ((0.187, 0.084, 0.012), (0.079, 0.060, 0.010), (0.012, 0.010, 0.006)),
        "B_h": ((0.651, 0.239, 0.020), (0.236, 0.407, 0.030), (0.020, 0.030, 0.060)),
        "K_h": ((7.967, 3.187, 0.300), (1.663, 6.901, 0.600), (0.300, 0.600, 3.000)),
        "links": ((1.5, 0.30, 0.15, 0.0113), (1.0, 0.35, 0.175, 0.0102),
                  (0.6, 0.12, 0.06, 0.0008)),
        "Jm": (0.010, 0.010, 0.004), "friction_scale": (1.0, 1.0, 0.25)},
}
#: Numbers of links the C plant is built for (fmus/build.py).
N_LINKS = tuple(sorted(DEFAULTS))


def model_name(n: int = N_JOINTS) -> str:
    """FMI model name (and model identifier) of the n-link plant: ``ArmExoPlant`` for the
    two-link plant of record, ``ArmExoPlant3`` for three links."""
    _check_n(n)
    return MODEL_NAME if n == 2 else f"{MODEL_NAME}{n}"


def _check_n(n) -> None:
    if n not in DEFAULTS:
        raise ValueError(f"the C plant has n = {', '.join(map(str, N_LINKS))} links, got {n!r}")


def friction_parameters(level: int, n: int = N_JOINTS) -> dict[str, float]:
    """FMU parameter values of reference friction level 0..3 for every joint of the n-link
    plant (joint 3 of the 3-link plant has 0.25 x the level's values, reference-3dof.md)."""
    if level not in range(len(FRICTION_LEVELS)):
        raise ValueError(f"friction level must be 0..3, got {level!r}")
    _check_n(n)
    out = {}
    for key, value in FRICTION_LEVELS[level].items():
        for j, scale in enumerate(DEFAULTS[n]["friction_scale"], 1):
            out[f"friction.{key}[{j}]"] = value * scale
    return out


def _build(n: int = N_JOINTS) -> list[Variable]:
    v: list[Variable] = []
    P = "parameter"
    cfg = DEFAULTS[n]
    joints = range(1, n + 1)

    def par(name, unit, desc, start, vmin=None):
        v.append(Variable(name, P, unit, desc, float(start), vmin))

    par("rk4_step", "s", "Fixed step of the internal classical RK4 solver", 1e-5, 0.0)
    for j, q0 in enumerate(cfg["posture_deg"], 1):
        par(f"posture_deg[{j}]", "deg", f"Posture (absolute joint angle) of joint {j}", q0)
    for key, unit, what in (("M_h", "kg.m2", "inertia"), ("B_h", "N.m.s/rad", "damping"),
                            ("K_h", "N.m/rad", "stiffness")):
        mat = cfg[key]
        for i in joints:
            for j in joints:
                par(f"arm.{key}[{i},{j}]", unit, f"Human arm {what} matrix element ({i},{j}), used as printed", mat[i - 1][j - 1])
    for i, (m, L, lc, inertia) in enumerate(cfg["links"], 1):
        for name, unit, desc, start in (
            (f"m{i}", "kg", f"Mass of link {i}", m),
            (f"L{i}", "m", f"Length of link {i}", L),
            (f"lc{i}", "m", f"Distance joint {i} to centre of mass of link {i}", lc),
            (f"I{i}", "kg.m2", f"Inertia of link {i} about its centre of mass", inertia),
        ):
            par(f"robot.{name}", unit, desc, start, 0.0)
    for j in joints:
        par(f"robot.Jm[{j}]", "kg.m2", f"Reflected motor/transmission inertia of joint {j}", cfg["Jm"][j - 1], 0.0)
    for key, unit, desc in (
        ("Fc", "N.m", "LuGre Coulomb friction torque"),
        ("Fs", "N.m", "LuGre static (stiction) friction torque"),
        ("sigma2", "N.m.s/rad", "LuGre viscous friction coefficient"),
    ):
        for j in joints:
            par(f"friction.{key}[{j}]", unit, f"{desc}, joint {j} (0 with Fc, Fs: no friction)", 0.0, 0.0)
    par("friction.sigma0", "N.m/rad", "LuGre bristle stiffness", 1.0e3, 0.0)
    par("friction.sigma1", "N.m.s/rad", "LuGre bristle damping", 1.0, 0.0)
    par("friction.ws", "rad/s", "LuGre Stribeck velocity", 0.01, 0.0)
    par("actuator_lag.time_constant_s", "s", "Actuator first-order lag time constant (0: off)", 0.0, 0.0)
    for key, unit, desc in (
        ("k_t", "N.m/rad", "Transmission stiffness motor-link (0: rigid, off)"),
        ("c_t", "N.m.s/rad", "Transmission damping motor-link"),
    ):
        for j in joints:
            par(f"transmission_compliance.{key}[{j}]", unit, f"{desc}, joint {j}", 0.0, 0.0)
    for key, unit, desc in (
        ("k_s", "N.m/rad", "Cuff (interface) stiffness robot-arm (0: rigid, off)"),
        ("c_s", "N.m.s/rad", "Cuff (interface) damping robot-arm"),
    ):
        for j in joints:
            par(f"interface_compliance.{key}[{j}]", unit, f"{desc}, joint {j}", 0.0, 0.0)
    par("gravity.tilt_deg", "deg", "Tilt of the robot plane from horizontal about the base x axis (0: off)", 0.0)
    par("inertia_mismatch.scale", "", "Scale of the robot's a1, a2, a3 (1: off)" if n == 2
        else "Scale of the robot's link inertia coefficients d_ab (1: off)", 1.0, 0.0)
    par("torque_sensor_lag.time_constant_s", "s", "Torque sensor first-order lag time constant (0: off)", 0.0, 0.0)

    for j in joints:
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
        for j in joints:
            v.append(Variable(f"{name}[{j}]", "output", unit, f"{desc}, joint {j}"))
    return v


@dataclass(frozen=True)
class Table:
    """The variable table of the n-link plant (what this module exports for n = 2).

    Attributes: ``n``, ``model_name``, ``variables`` (tuple of :class:`Variable`, value
    reference = position), ``vr`` (name -> value reference), ``by_name``, ``parameters``,
    ``inputs``, ``outputs`` (names), ``guid`` (derived from the table).
    """

    n: int
    model_name: str
    variables: tuple
    vr: dict
    by_name: dict
    parameters: tuple
    inputs: tuple
    outputs: tuple
    guid: str


_TABLES: dict = {}


def table(n: int = N_JOINTS) -> Table:
    """The variable table of the n-link plant (n in :data:`N_LINKS`).

    Raises
    ------
    ValueError
        No C plant for that n.
    """
    _check_n(n)
    if n not in _TABLES:
        variables = tuple(_build(n))
        name = model_name(n)
        _TABLES[n] = Table(
            n=n, model_name=name, variables=variables,
            vr={var.name: i for i, var in enumerate(variables)},
            by_name={var.name: var for var in variables},
            parameters=tuple(x.name for x in variables if x.causality == "parameter"),
            inputs=tuple(x.name for x in variables if x.causality == "input"),
            outputs=tuple(x.name for x in variables if x.causality == "output"),
            # the two-link GUID keeps its historical seed (MODEL_NAME + repr(table))
            guid="{" + str(uuid.uuid5(uuid.NAMESPACE_URL, name + repr(variables))) + "}")
    return _TABLES[n]


_T2 = table(2)
VARIABLES: tuple[Variable, ...] = _T2.variables
#: name -> value reference
VR: dict[str, int] = _T2.vr
BY_NAME: dict[str, Variable] = _T2.by_name
PARAMETERS = _T2.parameters
INPUTS = _T2.inputs
OUTPUTS = _T2.outputs
#: Derived from the table, so it changes whenever the table changes.
GUID = _T2.guid


def c_identifier(name: str) -> str:
    """C enum name of a variable: ``arm.M_h[1,2]`` -> ``vr_arm_M_h_1_2``."""
    out = name.replace(".", "_").replace("[", "_").replace(",", "_").replace("]", "")
    return "vr_" + out
