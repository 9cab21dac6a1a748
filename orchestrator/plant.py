"""Loading a plant FMU, checking the plant contract, and fast FMI access for the master.

FMI 2.0 and FMI 3.0 Co-Simulation plants are driven (docs/spec/plant-contract.md). Every FMI
call of the slow path goes through fmpy's ``FMU2Slave`` / ``FMU3Slave`` (which raise on a
status above Warning; :func:`_fmi` turns that into :class:`FMUCallError` naming the
function). The per-sample path (:class:`PlantIO`) calls the get/set/doStep functions through
ctypes prototypes of its own with preallocated value-reference and value arrays, checking the
status itself: fmpy's wrappers build new ctypes arrays and go through a Python logging shim on
every call, which costs more than the controller.

The master's view of a plant is in SI units (rad, N m, rad/s): a plant that declares another
unit with a conversion its model description states is converted (:class:`Contract` holds
the factors and offsets).
"""

from __future__ import annotations

import ctypes
import difflib
import functools
import math
import os
import re
import stat
import warnings
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import fmpy
from fmpy.fmi2 import (FMU2Slave, calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, free)
from fmpy.fmi3 import FMU3Slave
from fmpy.model_description import ValidationError

from trialformat.tempdirs import own_temp_dir, release_temp_dir

from .errors import (ContractError, FMUCallError, ParameterError, PlantFileError, PlantWarning,
                     RateError)

_STATUS = {0: "OK", 1: "Warning", 2: "Discard", 3: "Error", 4: "Fatal", 5: "Pending"}
#: contract variables: name -> (causality, expected unit, required)
CONTRACT = {"theta": ("output", "rad", True), "tau_h": ("output", "N.m", True),
            "tau_m": ("input", "N.m", True), "omega": ("output", "rad/s", False)}
_UNIT_SPELLINGS = {"N.m": {"N.m", "N m", "Nm", "N*m"}, "rad": {"rad"},
                   "rad/s": {"rad/s", "rad.s-1"}}
#: SI base-unit exponents of the contract units (FMI BaseUnit attributes; rad counted)
_DIMENSIONS = {"rad": {"rad": 1}, "N.m": {"kg": 1, "m": 2, "s": -2}, "rad/s": {"rad": 1, "s": -1}}
_BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
#: FMI type of a real variable per FMI major version
_REAL_TYPE = {2: "Real", 3: "Float64"}
#: a plant starts at its posture, at rest [rad, rad/s]
START_STATE_TOLERANCE = 1e-9
#: limits of an FMU archive extracted by :func:`extract_fmu` (a zip bomb is refused)
MAX_FMU_BYTES = 1 << 30
MAX_FMU_ENTRIES = 10_000
#: set-up parameters that change the physics when nonzero: a plant that lacks them cannot
#: simulate such a set-up (refused by name instead of ignored)
_NONZERO_NEEDS_PARAMETER = re.compile(r"friction\.(Fc|Fs|sigma2)\[\d+\]")


def read_model_description(path: Path):
    """fmpy's model description; a validation complaint that does not stop reading (model
    structure, units...) is a :class:`PlantWarning`, not a refusal."""
    if not path.is_file():
        raise PlantFileError(f"{path}: plant FMU not found")
    if not zipfile.is_zipfile(path):
        raise PlantFileError(f"{path}: not an FMU (not a ZIP archive)")
    with zipfile.ZipFile(path) as zf:
        if "modelDescription.xml" not in zf.namelist():
            raise PlantFileError(f"{path}: not an FMU (no modelDescription.xml in the archive)")
    try:
        return fmpy.read_model_description(str(path), validate=True,
                                           validate_model_structure=True)
    except ValidationError as exc:
        complaint = "; ".join(exc.problems)
    except Exception as exc:  # fmpy raises bare Exception for unparsable descriptions
        raise PlantFileError(f"{path}: modelDescription.xml cannot be read: {exc}") from None
    try:
        md = fmpy.read_model_description(str(path), validate=False)
    except Exception as exc:
        raise PlantFileError(f"{path}: modelDescription.xml cannot be read: {exc}") from None
    warnings.warn(f"{path.name}: model description complaints (simulating anyway): "
                  f"{complaint}", PlantWarning, stacklevel=3)
    return md


@dataclass(frozen=True)
class Contract:
    """What the master needs of a plant that keeps the contract.

    Attributes
    ----------
    n_dof : int
        Number of joints (number of ``theta[j]`` outputs).
    vr_tau_m, vr_theta, vr_tau_h, vr_omega : tuple of int
        Value references in joint order (``vr_omega`` empty when the plant has none).
    fmi_version : int
        2 or 3.
    to_si_outputs : tuple of (factor, offset) or None
        SI value = factor * plant value + offset for ``theta..., tau_h...`` (None: all SI).
    to_si_omega : tuple of (factor, offset) or None
        The same for ``omega...``.
    to_si_inputs : tuple of (factor, offset) or None
        The same for ``tau_m...`` (the master sends (SI - offset) / factor).
    fixed_step : float or None [s]
        The communication step of a plant that cannot handle another one
        (``canHandleVariableCommunicationStepSize="false"`` with a DefaultExperiment
        ``stepSize``, or FMI 3.0 ``fixedInternalStepSize``).
    """

    n_dof: int
    vr_tau_m: tuple
    vr_theta: tuple
    vr_tau_h: tuple
    vr_omega: tuple
    fmi_version: int = 2
    to_si_outputs: tuple | None = None
    to_si_omega: tuple | None = None
    to_si_inputs: tuple | None = None
    fixed_step: float | None = None


def fmi_major(md) -> int | None:
    """2 or 3 for an FMI 2.0 / 3.0 model description (any 3.x release), else None."""
    version = str(md.fmiVersion or "")
    if version == "2.0":
        return 2
    if re.fullmatch(r"3\.\d+(\.\d+)?", version):
        return 3
    return None


def check_contract(md, where: str = "plant") -> Contract:
    """Check docs/spec/plant-contract.md; raise ContractError listing every problem.

    The FMI version decides the expected type of the real variables (``Real`` in FMI 2.0,
    ``Float64`` in FMI 3.0). A missing variable is listed with the plant's names that look
    like it (``theta_1``, ``plant.theta[1]``). Units are checked and their conversion to
    the contract's SI units taken from the model description's unit definitions.
    """
    problems = []
    version = fmi_major(md)
    if version is None:
        problems.append(f"FMI version {md.fmiVersion}: this master drives FMI 2.0 and FMI 3.0 "
                        f"Co-Simulation FMUs")
    if md.coSimulation is None:
        problems.append("no Co-Simulation interface (Model Exchange only)")
    real = _REAL_TYPE.get(version, "Real")
    by_name = {v.name: v for v in md.modelVariables}
    units = {u.name: u for u in (md.unitDefinitions or [])}
    indices = sorted(int(m.group(1)) for name in by_name
                     if (m := re.fullmatch(r"theta\[(\d+)\]", name)))
    n = len(indices)
    if n == 0:
        problems.append(f"missing variable theta[1] (output, {real}, rad): a plant needs at least "
                        f"one joint{_near('theta[1]', by_name)}")
    elif indices != list(range(1, n + 1)):
        problems.append(f"theta outputs must be numbered theta[1]..theta[{n}], found "
                        f"{', '.join(f'theta[{i}]' for i in indices)}")
    vrs = {key: [] for key in CONTRACT}
    to_si = {key: [] for key in CONTRACT}
    for key, (causality, unit, required) in CONTRACT.items():
        for j in range(1, n + 1):
            name = f"{key}[{j}]"
            var = by_name.get(name)
            if var is None:
                if required:
                    problems.append(f"missing variable {name} ({causality}, {real}, {unit})"
                                    f"{_near(name, by_name)}")
                continue
            var_problems, conversion = _variable_problems(var, causality, unit, real, units)
            problems += var_problems
            vrs[key].append(var.valueReference)
            to_si[key].append(conversion)
    if vrs["omega"] and len(vrs["omega"]) != n:
        problems.append(f"omega is optional but must be given for all {n} joints or none")
    fixed_step, step_problem = _fixed_step(md)
    if step_problem:
        problems.append(step_problem)
    clocks = [v.name for v in md.modelVariables if v.type == "Clock"]
    clocked = [v.name for v in md.modelVariables if getattr(v, "clocks", None)]
    if clocks or clocked:
        problems.append("FMI 3.0 clocks are not driven by this master (it steps in "
                        "Co-Simulation without events): "
                        + "; ".join(filter(None, [
                            f"clock(s) {', '.join(clocks[:6])}" if clocks else "",
                            f"clocked variable(s) {', '.join(clocked[:6])}" if clocked else ""])))
    identifier = md.coSimulation.modelIdentifier if md.coSimulation is not None else None
    if md.coSimulation is not None:
        bad = identifier_problem(identifier)
        if bad:
            problems.append(bad)
    if problems:
        raise ContractError(f"{where} breaks the plant contract (docs/spec/plant-contract.md), "
                            f"{len(problems)} problem(s):\n  - " + "\n  - ".join(problems))
    return Contract(n_dof=n, vr_tau_m=tuple(vrs["tau_m"]), vr_theta=tuple(vrs["theta"]),
                    vr_tau_h=tuple(vrs["tau_h"]), vr_omega=tuple(vrs["omega"]),
                    fmi_version=version,
                    to_si_outputs=_conversions(to_si["theta"] + to_si["tau_h"]),
                    to_si_omega=_conversions(to_si["omega"]),
                    to_si_inputs=_conversions(to_si["tau_m"]), fixed_step=fixed_step)


def identifier_problem(identifier) -> str | None:
    """Why a ``modelIdentifier`` cannot name the FMU's binary (it becomes a file name
    inside the extracted archive: no path separators, no ``..``), or None."""
    if not identifier or not isinstance(identifier, str):
        return f"modelIdentifier {identifier!r} is empty"
    if re.search(r"[/\\:\x00]", identifier) or ".." in identifier or identifier != identifier.strip():
        return (f"modelIdentifier {identifier!r} is not a plain name (path separators, "
                f"'..', ':' or surrounding blanks): it names the binary inside the archive")
    return None


def _norm(name: str) -> str:
    return re.sub(r"[^0-9a-z]", "", name.lower())


def _near(name: str, by_name: dict) -> str:
    """'; near: ...' listing the plant's names that look like ``name``, or ''."""
    key, base = _norm(name), name.split("[")[0]
    # prefixed (plant.theta[1]), spelled otherwise (theta_1, theta(1)), or one array variable
    # (theta: FMI 3.0 arrays are refused, the contract names scalars)
    near = [v for v in by_name if v.endswith("." + name) or _norm(v) == key or v == base]
    near += [v for v in difflib.get_close_matches(name, list(by_name), n=3, cutoff=0.8)
             if v not in near]
    return f"; the plant has {', '.join(near[:3])} (the contract names arrays name[j], " \
           f"1-based, at the top level)" if near else ""


def _variable_problems(var, causality: str, unit: str, real: str, units: dict):
    """(problems, (factor, offset) to SI) of one contract variable."""
    problems = []
    if var.type != real:
        problems.append(f"{var.name}: type {var.type}, expected {real}")
    if var.causality != causality:
        problems.append(f"{var.name}: causality {var.causality!r}, expected {causality!r}")
    declared = var.unit or (var.declaredType.unit if var.declaredType is not None else None)
    if not declared or declared in _UNIT_SPELLINGS[unit]:
        return problems, (1.0, 0.0)
    definition = units.get(declared)
    base = definition.baseUnit if definition is not None else None
    if base is None:
        problems.append(f"{var.name}: unit {declared!r} has no BaseUnit in the model "
                        f"description's UnitDefinitions, so it cannot be converted to {unit!r}")
        return problems, (1.0, 0.0)
    exponents = {b: getattr(base, b) for b in _BASE if getattr(base, b)}
    if exponents != _DIMENSIONS[unit]:
        have = " ".join(f"{b}={e}" for b, e in exponents.items()) or "dimensionless"
        problems.append(f"{var.name}: unit {declared!r} ({have}) cannot be converted to "
                        f"{unit!r}")
    return problems, (float(base.factor), float(base.offset))


def _conversions(pairs: list):
    """The pairs, or None when every one is the identity (nothing to convert)."""
    return None if all(p == (1.0, 0.0) for p in pairs) else tuple(pairs)


def _fixed_step(md):
    """(fixed communication step or None, problem or None)."""
    cs = md.coSimulation
    if cs is None or cs.canHandleVariableCommunicationStepSize:
        return None, None
    step = getattr(cs, "fixedInternalStepSize", None)
    if md.defaultExperiment is not None and md.defaultExperiment.stepSize is not None:
        step = md.defaultExperiment.stepSize
    if step is None:
        return None, None  # constant steps only: the master never varies its step anyway
    try:
        step = float(step)
    except (TypeError, ValueError):
        return None, f"DefaultExperiment stepSize {step!r} is not a number"
    if not (step > 0 and math.isfinite(step)):
        return None, f"DefaultExperiment stepSize {step!r} must be > 0"
    return step, None


class PlantIO:
    """Fast per-sample access to a running FMI 2.0 or 3.0 slave (ctypes, preallocated arrays).

    The master calls three pre-bound functions: ``read()`` fills :attr:`val_out` with the
    outputs, ``write()`` sends :attr:`val_in`, ``step(t, h, 1)`` makes one communication
    step; each returns the FMI status (0 OK ... 4 Fatal, equal in FMI 2.0 and 3.0). For FMI
    2.0 they are the library's functions with their leading arguments bound (no Python frame
    in between).

    Parameters
    ----------
    dll : ctypes.CDLL
        The FMU's shared library.
    component : int
        The fmi2Component / fmi3Instance.
    vr_inputs, vr_outputs : sequence of int
        Value references of the inputs set and the outputs read each sample.
    fmi_version : {2, 3}
    to_si_outputs, to_si_inputs : tuple of (factor, offset) or None
        Unit conversions (see :class:`Contract`); None: the values are SI.
    """

    def __init__(self, dll, component, vr_inputs, vr_outputs, fmi_version=2, *,
                 to_si_outputs=None, to_si_inputs=None):
        vr_p, dbl_p = ctypes.POINTER(ctypes.c_uint), ctypes.POINTER(ctypes.c_double)
        self.fmi_version = fmi_version
        self.component = ctypes.c_void_p(component)
        self.n_in, self.n_out = len(vr_inputs), len(vr_outputs)
        self.vr_in = (ctypes.c_uint * self.n_in)(*vr_inputs)
        self.vr_out = (ctypes.c_uint * self.n_out)(*vr_outputs)
        self.val_in = (ctypes.c_double * self.n_in)()
        self.val_out = (ctypes.c_double * self.n_out)()
        self.to_si_outputs, self.to_si_inputs = to_si_outputs, to_si_inputs
        comp = self.component
        if fmi_version == 2:
            real_io = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, vr_p, ctypes.c_size_t, dbl_p)
            do_step = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double,
                                       ctypes.c_double, ctypes.c_int)
            self.set_real = real_io(("fmi2SetReal", dll))
            self.get_real = real_io(("fmi2GetReal", dll))
            self.do_step_raw = do_step(("fmi2DoStep", dll))
            self.read = functools.partial(self.get_real, comp, self.vr_out, self.n_out, self.val_out)
            self.write = functools.partial(self.set_real, comp, self.vr_in, self.n_in, self.val_in)
            self.step = functools.partial(self.do_step_raw, comp)
            self.names = ("fmi2GetReal", "fmi2SetReal", "fmi2DoStep")
            return
        real_io = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, vr_p, ctypes.c_size_t, dbl_p,
                                   ctypes.c_size_t)
        # the four out-pointers are passed as plain addresses (cheaper than byref per call)
        ptr = ctypes.c_void_p
        do_step = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double,
                                   ctypes.c_bool, ptr, ptr, ptr, ptr)
        self.set_real = real_io(("fmi3SetFloat64", dll))
        self.get_real = real_io(("fmi3GetFloat64", dll))
        self.do_step_raw = do_step(("fmi3DoStep", dll))
        self.read = functools.partial(self.get_real, comp, self.vr_out, self.n_out, self.val_out,
                                      self.n_out)
        self.write = functools.partial(self.set_real, comp, self.vr_in, self.n_in, self.val_in,
                                       self.n_in)
        flags = [ctypes.c_bool() for _ in range(3)]
        last = ctypes.c_double()
        p1, p2, p3 = (ctypes.addressof(f) for f in flags)
        p4 = ctypes.addressof(last)
        self._step_out = (flags, last)  # keep the out-values alive
        raw, c = self.do_step_raw, component

        def step(t, h, no_set_prior):
            return raw(c, t, h, no_set_prior, p1, p2, p3, p4)

        self.step = step
        self.names = ("fmi3GetFloat64", "fmi3SetFloat64", "fmi3DoStep")

    def set_inputs(self, values) -> None:
        """Set the inputs [N m] (sequence of float, input order; converted to plant units)."""
        val = self.val_in
        conv = self.to_si_inputs
        for i, v in enumerate(values):
            val[i] = v if conv is None else (v - conv[i][1]) / conv[i][0]
        status = self.write()
        if status > 1:
            raise FMUCallError(f"{self.names[1]} returned {_STATUS.get(status, status)} "
                               f"setting inputs {list(values)}")

    def get_outputs(self) -> list:
        """The outputs (output order, SI units) as a list of float."""
        status = self.read()
        if status > 1:
            raise FMUCallError(f"{self.names[0]} returned {_STATUS.get(status, status)}")
        out = self.val_out[:]
        conv = self.to_si_outputs
        return out if conv is None else [f * x + o for x, (f, o) in zip(out, conv)]

    def do_step(self, t: float, h: float) -> None:
        """One communication step from t [s] over h [s]; Discard is refused (fixed step)."""
        status = self.step(t, h, 1)
        if status > 1:
            raise step_error(status, t, h, self.names[2])

    def output_converter(self, sample):
        """``sample(n, outputs)`` fed with SI outputs: ``sample`` itself when the plant is SI."""
        conv = self.to_si_outputs
        if conv is None:
            return sample
        return lambda n, outputs: sample(n, [f * x + o for x, (f, o) in zip(outputs, conv)])

    def input_converter(self, push):
        """``push(command) -> applied`` followed by the conversion to plant units (``push``
        None: no delay); None when neither applies."""
        conv = self.to_si_inputs
        if conv is None:
            return push
        to_plant = [(1.0 / f, -o / f) for f, o in conv]
        if push is None:
            return lambda tau: [a * x + b for x, (a, b) in zip(tau, to_plant)]
        return lambda tau: [a * x + b for x, (a, b) in zip(push(tau), to_plant)]


def step_error(status: int, t: float, h: float, name: str = "fmi2DoStep") -> FMUCallError:
    """The exception for a failed doStep (Discard included: this master never retries
    a step with a smaller size, so a discarded step ends the trial)."""
    return FMUCallError(f"{name}(t={t!r} s, h={h!r} s) returned "
                        f"{_STATUS.get(status, status)}")


class PlantLog:
    """The plant's log messages, kept instead of printed: an FMI call that fails raises an
    exception that carries them (a plant refused inside a search prints nothing).

    ``messages`` holds the last ``size`` messages as ``"[STATUS] text"``; the FMI 2.0
    logger is variadic, so fmpy's native proxy formats the text before it reaches Python.
    """

    _LABELS = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")

    def __init__(self, size: int = 8):
        from collections import deque
        self.messages = deque(maxlen=size)
        self._fmi2 = None
        self._fmi3 = None

    def _keep(self, status, message) -> None:
        label = self._LABELS[status] if 0 <= status < len(self._LABELS) else str(status)
        text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
        self.messages.append(f"[{label}] {text}")

    def fmi2_callbacks(self):
        """fmi2CallbackFunctions whose logger keeps the messages (kept alive by self)."""
        if self._fmi2 is None:
            cb = fmi2CallbackFunctions()
            cb.logger = fmi2CallbackLoggerTYPE(
                lambda env, name, status, category, message: self._keep(status, message))
            cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            from fmpy.logging import addLoggerProxy
            addLoggerProxy(ctypes.byref(cb))
            self._fmi2 = cb
        return self._fmi2

    def fmi3_logger(self):
        """The FMI 3.0 logMessage callback (plain text, no formatting)."""
        if self._fmi3 is None:
            self._fmi3 = lambda env, status, category, message: self._keep(status, message)
        return self._fmi3

    def explain(self, exc: Exception) -> FMUCallError:
        """``exc`` as an FMUCallError that ends with the plant's messages since the last
        call of this method (the messages are then cleared)."""
        text = str(exc)
        if self.messages:
            text += " -- the plant logged: " + " | ".join(self.messages)
            self.messages.clear()
        return FMUCallError(text)


class Plant:
    """A plant FMU that keeps the contract: loaded once, reset between trials.

    FMI 2.0 and FMI 3.0 Co-Simulation FMUs are driven. An instance is reused through reset
    while reset works and brings the plant back to its start state (theta and omega 0); a
    plant whose reset fails, or returns OK but keeps its state, is re-instantiated for every
    later trial (with a :class:`PlantWarning` naming it). A plant that does not start from
    its start state even when new is refused (:class:`ContractError` naming it).

    Parameters
    ----------
    path : path
        The ``.fmu`` file.
    instance_name : str

    Attributes
    ----------
    path : Path
    contract : Contract
    n_dof : int
    fmi_version : int
        2 or 3.
    model_name, guid, generation_tool : str
    parameters : dict
        Parameter name -> start value (as declared, float for Real).
    extra_inputs : dict
        Inputs outside the contract (e.g. ``motor_enable``) -> start value; the master
        never drives them; ``start(parameters=...)`` sets them like parameters.
    once_per_process : bool
        The plant declares ``canBeInstantiatedOnlyOncePerProcess`` (one instance at a time;
        a grid runs each of its trials in a fresh worker process).
    reinstantiated : int
        How many times a new instance replaced one whose reset did not work.
    log : PlantLog
        The plant's log messages; they end the message of a failing call's FMUCallError.

    Raises
    ------
    PlantFileError
        Not a readable FMU, an archive refused by :func:`extract_fmu`, no binary for this
        platform (one line naming the missing file and the platforms the FMU has), or a
        binary that cannot be loaded; always naming the FMU file.
    ContractError
        The plant breaks the contract (every problem listed; FMI 3.0 clocks and a
        ``modelIdentifier`` that is not a plain name included).
    FMUCallError
        ``fmi2Instantiate`` returned NULL (naming the FMU and ending with its log lines).
    """

    def __init__(self, path, *, instance_name: str = "plant"):
        self.path = Path(path)
        self.model_description = md = read_model_description(self.path)
        self.contract = check_contract(md, where=self.path.name)
        self.fmi_version = self.contract.fmi_version
        self.n_dof = self.contract.n_dof
        self.model_name, self.guid = md.modelName, md.guid
        self.generation_tool = md.generationTool or ""
        self.instance_name = instance_name
        self._variables = {v.name: v for v in md.modelVariables}
        self.parameters = {v.name: _start(v) for v in md.modelVariables
                           if v.causality == "parameter"}
        check_platform_binary(self.path, md)
        self.once_per_process = bool(getattr(md.coSimulation, "canBeInstantiatedOnlyOncePerProcess",
                                             False))
        self.extra_inputs = {v.name: _start(v) for v in md.modelVariables
                             if v.causality == "input" and not _is_contract_input(v.name)}
        self._unzip_dir = str(extract_fmu(self.path))
        self._fmu = None
        self._initialized = False
        self._closed = False
        self._reset_unusable = ""     # why reset cannot be trusted ("" while it can)
        self._warned_inputs = False   # inputs outside the contract left at start: said once
        self.held_inputs = {}         # those of the last start()
        self.reinstantiated = 0
        self.log = PlantLog()
        try:
            self._instantiate()
        except BaseException:
            release_temp_dir(self._unzip_dir)
            raise

    def _fn(self, name: str) -> str:
        return f"fmi{self.fmi_version}{name}"

    def _instantiate(self) -> None:
        """A new instance and its PlantIO; the previous one, if any, is freed first (a plant
        that can be instantiated only once per process has one instance at a time)."""
        md, c = self.model_description, self.contract
        old, self._fmu = self._fmu, None
        if old is not None:
            _free(old, terminate=self._initialized)
        self._initialized = False
        fmu = self._load_binary()
        logger = ({"callbacks": self.log.fmi2_callbacks()} if self.fmi_version == 2
                  else {"logMessage": self.log.fmi3_logger()})
        name = self._fn("InstantiateCoSimulation" if self.fmi_version == 3 else "Instantiate")
        try:
            _fmi(name, fmu.instantiate, loggingOn=False, **logger)
        except FMUCallError:
            raise self.log.explain(FMUCallError(
                f"{self.path.name}: {name} returned NULL (the plant refused to start an "
                f"instance)")) from None
        self._fmu = fmu
        self.io = PlantIO(fmu.dll, fmu.component, c.vr_tau_m, c.vr_theta + c.vr_tau_h,
                          self.fmi_version, to_si_outputs=c.to_si_outputs,
                          to_si_inputs=c.to_si_inputs)

    def _load_binary(self):
        """fmpy's slave on the extracted binary; a library that cannot be loaded (garbage,
        another architecture, a missing FMI function) is a PlantFileError naming the FMU."""
        md = self.model_description
        cls = FMU2Slave if self.fmi_version == 2 else FMU3Slave
        identifier = md.coSimulation.modelIdentifier
        cwd = os.getcwd()  # fmpy changes into the binary's folder and not back on failure
        try:
            return cls(guid=md.guid, unzipDirectory=self._unzip_dir, modelIdentifier=identifier,
                       instanceName=self.instance_name)
        except Exception as exc:  # fmpy raises bare Exception / AttributeError from ctypes
            text = str(exc).replace(self._unzip_dir + os.sep, "").replace(self._unzip_dir, "")
            text = text.splitlines()[0] if text else type(exc).__name__
            raise PlantFileError(f"{self.path.name}: its binary for this platform cannot be "
                                 f"used: {text}") from None
        finally:
            os.chdir(cwd)

    # ------------------------------------------------------------------ lifecycle
    def start(self, parameters: dict | None = None, *, optional: dict | None = None,
              start_time: float = 0.0) -> list:
        """(Re)initialise the plant for a new trial.

        Parameters
        ----------
        parameters : dict
            Name -> value the plant must have (unknown name: :class:`ParameterError`).
        optional : dict
            Name -> value set only where the plant has that parameter (the declared
            set-up: a plant without friction has no ``friction.Fc[1]``).
        start_time : float [s]

        Returns
        -------
        list of str
            The optional names the plant does not have (not set).

        Raises
        ------
        ParameterError, FMUCallError
        ContractError
            The plant does not start from its start state even as a new instance.
        """
        parameters, optional = parameters or {}, optional or {}
        self.check_parameters(parameters)
        skipped = [name for name in optional if name not in self.parameters]
        needed = [name for name in skipped
                  if _NONZERO_NEEDS_PARAMETER.fullmatch(name) and optional[name] != 0.0]
        if needed:
            shown = ", ".join(f"{n} = {optional[n]:g}" for n in needed[:4])
            raise ParameterError(
                f"{self.path.name} has no parameter {', '.join(needed)}: the set-up's "
                f"{shown}{', ...' if len(needed) > 4 else ''} would be ignored silently "
                f"(simulate it at friction level 0, or on a plant with these parameters)")
        values = {k: v for k, v in optional.items() if k in self.parameters}
        values.update(parameters)
        unset = {k: v for k, v in self.extra_inputs.items() if k not in values}
        self.held_inputs = unset  # named again if the loop then diverges
        if unset and not self._warned_inputs:
            self._warned_inputs = True
            warnings.warn(f"{self.path.name}: input(s) outside the contract held at their start "
                          f"values: {', '.join(f'{k} = {v}' for k, v in unset.items())} (set them "
                          f"with --plant-parameter NAME=VALUE / parameters=)", PlantWarning,
                          stacklevel=3)
        while True:
            fresh = self._fresh_instance()
            try:
                self._initialize(values, start_time)
            except FMUCallError as exc:
                raise self.log.explain(exc) from exc
            off = self._start_state_error()
            if off is None:
                return skipped
            if fresh:
                raise ContractError(f"{self.path.name} does not start from its start state: "
                                    f"{off} after initialisation (the contract's theta is the "
                                    f"deviation from the posture and the plant starts at rest)")
            self._distrust_reset(f"{self._fn('Reset')} returned OK but the plant kept its "
                                 f"state ({off} after initialisation)")

    def _fresh_instance(self) -> bool:
        """Reset or re-instantiate as needed; True when the instance is new."""
        if not self._initialized:
            return True
        if not self._reset_unusable:
            try:
                _fmi(self._fn("Reset"), self._fmu.reset)
                return False
            except FMUCallError as exc:
                self._distrust_reset(str(exc).rstrip("."))
                return True
        self._instantiate()
        self.reinstantiated += 1
        return True

    def _distrust_reset(self, why: str) -> None:
        """From now on every trial gets a new instance; say so once."""
        warnings.warn(f"{self.path.name}: {why}; the plant is re-instantiated for every trial "
                      f"from now on", PlantWarning, stacklevel=4)
        self._reset_unusable = why
        self._instantiate()
        self.reinstantiated += 1

    def _initialize(self, values: dict, start_time: float) -> None:
        fmu = self._fmu
        self._initialized = True  # from here on a reset is needed, even if init fails
        if self.fmi_version == 2:
            _fmi("fmi2SetupExperiment", fmu.setupExperiment, startTime=start_time)
            self._set_values(values)
            _fmi("fmi2EnterInitializationMode", fmu.enterInitializationMode)
        else:
            self._set_values(values)
            _fmi("fmi3EnterInitializationMode", fmu.enterInitializationMode, startTime=start_time)
        _fmi(self._fn("ExitInitializationMode"), fmu.exitInitializationMode)

    def _start_state_error(self) -> str | None:
        """None when theta (and omega) are 0 after initialisation, else what they are."""
        c = self.contract
        names = [f"theta[{j}]" for j in range(1, self.n_dof + 1)]
        conv = c.to_si_outputs[:self.n_dof] if c.to_si_outputs else [(1.0, 0.0)] * self.n_dof
        if c.vr_omega:
            names += [f"omega[{j}]" for j in range(1, self.n_dof + 1)]
            conv = list(conv) + list(c.to_si_omega or [(1.0, 0.0)] * self.n_dof)
        values = [f * x + o for x, (f, o) in zip(self.get(names), conv)]
        if all(abs(v) <= START_STATE_TOLERANCE for v in values):
            return None
        return ", ".join(f"{n} = {v:.6g}" for n, v in zip(names, values) if v != 0.0)

    def decimation(self, control_period: float, communication_step: float | None = None) -> int:
        """Communication steps per control period for this plant.

        A plant with a fixed communication step of its own is stepped at that step
        (docs/spec/plant-contract.md); another plant at ``communication_step`` (None: the
        control period).

        Raises
        ------
        RateError
            The step does not divide the control period, or a step other than the plant's
            fixed one was asked for; the message gives both values.
        """
        from .master import decimation

        fixed = self.contract.fixed_step
        if fixed is None:
            return decimation(control_period, communication_step)
        if communication_step is not None and abs(communication_step - fixed) > 1e-9 * fixed:
            raise RateError(f"{self.path.name} steps only at its fixed communication step "
                            f"{fixed!r} s (canHandleVariableCommunicationStepSize=false); "
                            f"{communication_step!r} s was asked for")
        try:
            return decimation(control_period, fixed)
        except RateError:
            raise RateError(f"{self.path.name}: its fixed communication step {fixed!r} s "
                            f"(canHandleVariableCommunicationStepSize=false) does not divide "
                            f"the control period {control_period!r} s (ratio "
                            f"{control_period / fixed:.6g})") from None

    def check_parameters(self, names) -> None:
        """Raise ParameterError for names that are neither parameters of this plant nor its
        inputs outside the contract (:attr:`extra_inputs`, set once before initialisation
        and then held)."""
        unknown = [n for n in names if n not in self.parameters and n not in self.extra_inputs]
        if unknown:
            hint = ""
            if len(unknown) == 1:
                close = [p for p in self.parameters if p.split("[")[0] == unknown[0].split("[")[0]]
                hint = f" (similar: {', '.join(close[:4])})" if close else ""
            what = [n if n not in self._variables
                    else f"{n} (a {self._variables[n].causality}, not a parameter)"
                    for n in unknown]
            raise ParameterError(f"{self.path.name} has no parameter {', '.join(what)}{hint}")

    def _set_values(self, values: dict) -> None:
        by_type = {}
        for name, value in values.items():
            var = self._variables[name]
            by_type.setdefault(var.type, ([], [], []))
            by_type[var.type][0].append(var.valueReference)
            by_type[var.type][1].append(value)
            by_type[var.type][2].append(name)
        fmu = self._fmu
        if self.fmi_version == 2:
            setters = {"Real": fmu.setReal, "Integer": fmu.setInteger, "Boolean": fmu.setBoolean}
        else:
            setters = {"Float64": fmu.setFloat64, "Int32": fmu.setInt32,
                       "Boolean": fmu.setBoolean}
        for vtype, (vrs, vals, names) in by_type.items():
            if vtype not in setters:
                raise ParameterError(f"{self.path.name}: cannot set {vtype} parameters")
            if vtype in ("Integer", "Int32"):
                vals = [int(v) for v in vals]
            if vtype == "Boolean":
                bad = [(n, v) for n, v in zip(names, vals) if v not in (0, 1)]
                if bad:
                    raise ParameterError(f"{self.path.name}: {bad[0][0]} is a Boolean; give 0 or "
                                         f"1, not {bad[0][1]!r}")
                vals = [bool(v) for v in vals]
            _fmi(self._fn(f"Set{vtype}"), setters[vtype], vrs, vals)

    def get(self, names) -> list:
        """Current values of real variables by name, in the plant's units (slow path; for
        checks and info)."""
        vrs = [self._variables[n].valueReference for n in names]
        if self.fmi_version == 2:
            return _fmi("fmi2GetReal", self._fmu.getReal, vrs)
        return _fmi("fmi3GetFloat64", self._fmu.getFloat64, vrs)

    def close(self) -> None:
        """Terminate and free the instance and remove the unpacked FMU."""
        if self._closed:
            return
        self._closed = True
        if self._fmu is not None:
            _free(self._fmu, terminate=self._initialized)
            self._fmu = None
        release_temp_dir(self._unzip_dir)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def describe(self) -> dict:
        """Name, GUID, exporter, joints and parameters (for ``armimp info`` and metadata)."""
        c = self.contract
        return {"file": self.path.name, "model_name": self.model_name, "guid": self.guid,
                "generation_tool": self.generation_tool, "n_dof": self.n_dof,
                "fmi_version": self.model_description.fmiVersion,
                "has_omega": bool(c.vr_omega), "fixed_communication_step_s": c.fixed_step,
                "converted_units": bool(c.to_si_outputs or c.to_si_inputs or c.to_si_omega),
                "once_per_process": self.once_per_process,
                "inputs_outside_contract": dict(self.extra_inputs),
                "parameters": dict(self.parameters)}


def _entry_problem(name: str, info) -> str | None:
    """Why a zip entry may not be extracted, or None."""
    if "\x00" in name:
        return "its name holds a NUL character"
    if "\\" in name:
        return "its name holds a backslash (a Windows path; FMI archives use '/')"
    if name.startswith("/") or re.match(r"[A-Za-z]:", name):
        return "its name is an absolute path"
    if ".." in name.split("/"):
        return "its name holds '..' (it would land outside the extracted folder)"
    if stat.S_ISLNK(info.external_attr >> 16):
        return "it is a symbolic link"
    return None


def extract_fmu(path) -> Path:
    """Extract an FMU archive into a new temporary folder of this process, within limits.

    The folder (``armimp-fmu-<pid>-*`` in the system temporary folder) is removed by
    :func:`trialformat.processes.release_temp_dir`, at the latest when the process exits;
    one left by a killed process is removed by the next extraction.

    Raises
    ------
    PlantFileError
        Naming the FMU file and the entry: more than :data:`MAX_FMU_ENTRIES` entries, more
        than :data:`MAX_FMU_BYTES` bytes uncompressed (declared or actually read), an entry
        name that is absolute, holds a backslash or ``..``, a symbolic link, or a damaged
        archive. Nothing is left behind.
    """
    path = Path(path)
    limit_mib = MAX_FMU_BYTES / 2**20
    try:
        zf = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile) as exc:
        raise PlantFileError(f"{path.name}: cannot open the FMU archive: {exc}") from None
    with zf:
        infos = zf.infolist()
        if len(infos) > MAX_FMU_ENTRIES:
            raise PlantFileError(f"{path.name}: the FMU archive has {len(infos)} entries, more "
                                 f"than the {MAX_FMU_ENTRIES} this master extracts")
        declared = sum(i.file_size for i in infos)
        if declared > MAX_FMU_BYTES:
            raise PlantFileError(f"{path.name}: the FMU archive unpacks to {declared / 2**20:.0f} "
                                 f"MiB, more than the {limit_mib:.0f} MiB this master extracts")
        for info in infos:
            why = _entry_problem(info.filename, info)
            if why:
                raise PlantFileError(f"{path.name}: archive entry {info.filename!r} refused: {why}")
        dest = own_temp_dir("armimp-fmu")
        try:
            written = 0
            for info in infos:
                target = dest.joinpath(*[p for p in info.filename.split("/") if p])
                if info.is_dir():
                    target.mkdir(parents=True, exist_ok=True)
                    continue
                target.parent.mkdir(parents=True, exist_ok=True)
                with zf.open(info) as src, open(target, "wb") as dst:
                    while chunk := src.read(1 << 20):
                        written += len(chunk)
                        if written > MAX_FMU_BYTES:
                            raise PlantFileError(
                                f"{path.name}: archive entry {info.filename!r} refused: the FMU "
                                f"unpacks to more than {limit_mib:.0f} MiB (more than its "
                                f"directory declares)")
                        dst.write(chunk)
        except PlantFileError:
            release_temp_dir(dest)
            raise
        except (OSError, zipfile.BadZipFile, EOFError, RuntimeError, zlib.error) as exc:
            release_temp_dir(dest)
            raise PlantFileError(f"{path.name}: cannot extract the FMU archive: {exc}") from None
        except BaseException:
            release_temp_dir(dest)
            raise
    return dest


def check_platform_binary(path: Path, md) -> None:
    """Refuse, in one line, an FMU without a binary for this platform.

    Raises
    ------
    PlantFileError
        Naming the missing ``binaries/<platform>/<identifier><ext>`` and the platforms the
        FMU has binaries for (and its ``sources/`` when it ships them).
    """
    platform = fmpy.platform if fmi_major(md) == 2 else fmpy.platform_tuple
    expected = (f"binaries/{platform}/{md.coSimulation.modelIdentifier}"
                f"{fmpy.sharedLibraryExtension}")
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    if expected in names:
        return
    have = sorted({n.split("/")[1] for n in names
                   if n.startswith("binaries/") and n.count("/") >= 2 and n.split("/")[2]})
    sources = any(n.startswith("sources/") and not n.endswith("/") for n in names)
    raise PlantFileError(f"{path.name} has no binary for this platform: {expected} is missing; "
                         f"it has binaries for {', '.join(have) if have else 'no platform'}"
                         + ("; it ships sources/ that could be compiled for this platform"
                            if sources else ""))


def _free(fmu, terminate: bool = True) -> None:
    """Terminate and free an instance; an error here must not hide the original one."""
    try:
        if terminate:
            fmu.terminate()
    except Exception:
        pass
    try:
        fmu.freeInstance()
    except Exception:
        pass


def _is_contract_input(name: str) -> bool:
    return re.fullmatch(r"tau_m\[\d+\]", name) is not None


def _start(var):
    if var.start is None:
        return None
    try:
        return float(var.start)
    except ValueError:
        return var.start


def _fmi(name: str, call, *args, **kwargs):
    """Call an fmpy wrapper; a status above Warning becomes FMUCallError naming ``name``."""
    try:
        return call(*args, **kwargs)
    except Exception as exc:
        if isinstance(exc, (FMUCallError, ParameterError)):
            raise
        raise FMUCallError(f"{name} failed: {exc}") from exc
