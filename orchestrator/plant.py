"""Loading a plant FMU, checking the plant contract, and fast FMI access for the master.

Every FMI call of the slow path goes through fmpy's ``FMU2Slave`` (which raises on a status
above Warning; :func:`_fmi` turns that into :class:`FMUCallError` naming the function). The
per-sample path (:class:`PlantIO`) calls ``fmi2SetReal``, ``fmi2DoStep`` and
``fmi2GetReal`` through ctypes prototypes of its own with preallocated value-reference and
value arrays, checking the status itself: fmpy's wrappers build new ctypes arrays and go
through a Python logging shim on every call, which costs more than the controller.
"""

from __future__ import annotations

import ctypes
import re
import shutil
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import fmpy
from fmpy.fmi2 import FMU2Slave
from fmpy.model_description import ValidationError

from .errors import ContractError, FMUCallError, ParameterError, PlantFileError, PlantWarning

_STATUS = {0: "OK", 1: "Warning", 2: "Discard", 3: "Error", 4: "Fatal", 5: "Pending"}
#: contract variables: name -> (causality, expected unit, required)
CONTRACT = {"theta": ("output", "rad", True), "tau_h": ("output", "N.m", True),
            "tau_m": ("input", "N.m", True), "omega": ("output", "rad/s", False)}
_UNIT_SPELLINGS = {"N.m": {"N.m", "N m", "Nm", "N*m"}, "rad": {"rad"},
                   "rad/s": {"rad/s", "rad.s-1"}}


@dataclass(frozen=True)
class Contract:
    """What the master needs of a plant that keeps the contract.

    Attributes
    ----------
    n_dof : int
        Number of joints (number of ``theta[j]`` outputs).
    vr_tau_m, vr_theta, vr_tau_h, vr_omega : tuple of int
        Value references in joint order (``vr_omega`` empty when the plant has none).
    """

    n_dof: int
    vr_tau_m: tuple
    vr_theta: tuple
    vr_tau_h: tuple
    vr_omega: tuple


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


def check_contract(md, where: str = "plant") -> Contract:
    """Check docs/spec/plant-contract.md; raise ContractError listing every problem."""
    problems = []
    if md.fmiVersion != "2.0":
        problems.append(f"FMI version {md.fmiVersion}: this master drives FMI 2.0 "
                        f"Co-Simulation FMUs")
    if md.coSimulation is None:
        problems.append("no Co-Simulation interface (Model Exchange only)")
    by_name = {v.name: v for v in md.modelVariables}
    indices = sorted(int(m.group(1)) for name in by_name
                     if (m := re.fullmatch(r"theta\[(\d+)\]", name)))
    n = len(indices)
    if n == 0:
        problems.append("missing variable theta[1] (output, Real, rad): a plant needs at "
                        "least one joint")
    elif indices != list(range(1, n + 1)):
        problems.append(f"theta outputs must be numbered theta[1]..theta[{n}], found "
                        f"{', '.join(f'theta[{i}]' for i in indices)}")
    vrs = {key: [] for key in CONTRACT}
    for key, (causality, unit, required) in CONTRACT.items():
        for j in range(1, max(n, 1) + 1):
            name = f"{key}[{j}]"
            var = by_name.get(name)
            if var is None:
                if required:
                    problems.append(f"missing variable {name} ({causality}, Real, {unit})")
                continue
            problems += _variable_problems(var, causality, unit, where)
            vrs[key].append(var.valueReference)
    if vrs["omega"] and len(vrs["omega"]) != n:
        problems.append(f"omega is optional but must be given for all {n} joints or none")
    if problems:
        raise ContractError(f"{where} breaks the plant contract (docs/spec/plant-contract.md), "
                            f"{len(problems)} problem(s):\n  - " + "\n  - ".join(problems))
    return Contract(n_dof=n, vr_tau_m=tuple(vrs["tau_m"]), vr_theta=tuple(vrs["theta"]),
                    vr_tau_h=tuple(vrs["tau_h"]), vr_omega=tuple(vrs["omega"]))


def _variable_problems(var, causality: str, unit: str, where: str) -> list:
    problems = []
    if var.type != "Real":
        problems.append(f"{var.name}: type {var.type}, expected Real")
    if var.causality != causality:
        problems.append(f"{var.name}: causality {var.causality!r}, expected {causality!r}")
    declared = var.unit or (var.declaredType.unit if var.declaredType is not None else None)
    if declared and declared not in _UNIT_SPELLINGS[unit]:
        warnings.warn(f"{where}: {var.name} declares unit {declared!r}, the contract says "
                      f"{unit!r}; the values are used as they are", PlantWarning, stacklevel=4)
    return problems


class PlantIO:
    """Fast per-sample access to a running FMI 2.0 slave (ctypes, preallocated arrays).

    Parameters
    ----------
    dll : ctypes.CDLL
        The FMU's shared library.
    component : int
        The fmi2Component of the instance.
    vr_inputs, vr_outputs : sequence of int
        Value references of the inputs set and the outputs read each sample.
    """

    def __init__(self, dll, component, vr_inputs, vr_outputs):
        vr_p, dbl_p = ctypes.POINTER(ctypes.c_uint), ctypes.POINTER(ctypes.c_double)
        real_io = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, vr_p, ctypes.c_size_t, dbl_p)
        do_step = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double,
                                   ctypes.c_double, ctypes.c_int)
        self.set_real = real_io(("fmi2SetReal", dll))
        self.get_real = real_io(("fmi2GetReal", dll))
        self.do_step_raw = do_step(("fmi2DoStep", dll))
        self.component = ctypes.c_void_p(component)
        self.n_in, self.n_out = len(vr_inputs), len(vr_outputs)
        self.vr_in = (ctypes.c_uint * self.n_in)(*vr_inputs)
        self.vr_out = (ctypes.c_uint * self.n_out)(*vr_outputs)
        self.val_in = (ctypes.c_double * self.n_in)()
        self.val_out = (ctypes.c_double * self.n_out)()

    def set_inputs(self, values) -> None:
        """Set the inputs [N m] (sequence of float, input order)."""
        val = self.val_in
        for i, v in enumerate(values):
            val[i] = v
        status = self.set_real(self.component, self.vr_in, self.n_in, val)
        if status > 1:
            raise FMUCallError(f"fmi2SetReal returned {_STATUS.get(status, status)} "
                               f"setting inputs {list(values)}")

    def get_outputs(self) -> list:
        """The outputs (output order) as a list of float."""
        status = self.get_real(self.component, self.vr_out, self.n_out, self.val_out)
        if status > 1:
            raise FMUCallError(f"fmi2GetReal returned {_STATUS.get(status, status)}")
        return self.val_out[:]

    def do_step(self, t: float, h: float) -> None:
        """One communication step from t [s] over h [s]; Discard is refused (fixed step)."""
        status = self.do_step_raw(self.component, t, h, 1)
        if status > 1:
            raise step_error(status, t, h)


def step_error(status: int, t: float, h: float) -> FMUCallError:
    """The exception for a failed fmi2DoStep (Discard included: this master never retries
    a step with a smaller size, so a discarded step ends the trial)."""
    return FMUCallError(f"fmi2DoStep(t={t!r} s, h={h!r} s) returned "
                        f"{_STATUS.get(status, status)}")


class Plant:
    """A plant FMU that keeps the contract: loaded once, reset between trials.

    Parameters
    ----------
    path : path
        The ``.fmu`` file (FMI 2.0 Co-Simulation).
    instance_name : str

    Attributes
    ----------
    path : Path
    contract : Contract
    n_dof : int
    model_name, guid, generation_tool : str
    parameters : dict
        Parameter name -> start value (as declared, float for Real).
    """

    def __init__(self, path, *, instance_name: str = "plant"):
        self.path = Path(path)
        self.model_description = md = read_model_description(self.path)
        self.contract = check_contract(md, where=self.path.name)
        self.n_dof = self.contract.n_dof
        self.model_name, self.guid = md.modelName, md.guid
        self.generation_tool = md.generationTool or ""
        self._variables = {v.name: v for v in md.modelVariables}
        self.parameters = {v.name: _start(v) for v in md.modelVariables
                           if v.causality == "parameter"}
        self._unzip_dir = fmpy.extract(str(self.path))
        try:
            self._fmu = FMU2Slave(guid=md.guid, unzipDirectory=self._unzip_dir,
                                  modelIdentifier=md.coSimulation.modelIdentifier,
                                  instanceName=instance_name)
            _fmi("fmi2Instantiate", self._fmu.instantiate, loggingOn=False)
        except Exception:
            shutil.rmtree(self._unzip_dir, ignore_errors=True)
            raise
        self._initialized = False
        self._closed = False
        c = self.contract
        self.io = PlantIO(self._fmu.dll, self._fmu.component, c.vr_tau_m,
                          c.vr_theta + c.vr_tau_h)

    # ------------------------------------------------------------------ lifecycle
    def start(self, parameters: dict | None = None, *, optional: dict | None = None,
              start_time: float = 0.0) -> list:
        """(Re)initialise the instance for a new trial.

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
        """
        parameters, optional = parameters or {}, optional or {}
        self.check_parameters(parameters)
        skipped = [name for name in optional if name not in self.parameters]
        if self._initialized:
            _fmi("fmi2Reset", self._fmu.reset)
        _fmi("fmi2SetupExperiment", self._fmu.setupExperiment, startTime=start_time)
        values = {k: v for k, v in optional.items() if k in self.parameters}
        values.update(parameters)
        self._set_values(values)
        self._initialized = True  # from here on a reset is needed, even if init fails
        _fmi("fmi2EnterInitializationMode", self._fmu.enterInitializationMode)
        _fmi("fmi2ExitInitializationMode", self._fmu.exitInitializationMode)
        return skipped

    def check_parameters(self, names) -> None:
        """Raise ParameterError for names that are not parameters of this plant."""
        unknown = [n for n in names if n not in self.parameters]
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
            by_type.setdefault(var.type, ([], []))
            by_type[var.type][0].append(var.valueReference)
            by_type[var.type][1].append(value)
        setters = {"Real": self._fmu.setReal, "Integer": self._fmu.setInteger,
                   "Boolean": self._fmu.setBoolean}
        for vtype, (vrs, vals) in by_type.items():
            if vtype not in setters:
                raise ParameterError(f"{self.path.name}: cannot set {vtype} parameters")
            if vtype == "Integer":
                vals = [int(v) for v in vals]
            _fmi(f"fmi2Set{vtype}", setters[vtype], vrs, vals)

    def get(self, names) -> list:
        """Current values of Real variables by name (slow path; for checks and info)."""
        vrs = [self._variables[n].valueReference for n in names]
        return _fmi("fmi2GetReal", self._fmu.getReal, vrs)

    def close(self) -> None:
        """Terminate and free the instance and remove the unpacked FMU."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._initialized:
                self._fmu.terminate()
            self._fmu.freeInstance()
        except Exception:  # freeing a failed instance must not hide the original error
            pass
        shutil.rmtree(self._unzip_dir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def describe(self) -> dict:
        """Name, GUID, exporter, joints and parameters (for ``armimp info`` and metadata)."""
        return {"file": self.path.name, "model_name": self.model_name, "guid": self.guid,
                "generation_tool": self.generation_tool, "n_dof": self.n_dof,
                "has_omega": bool(self.contract.vr_omega), "parameters": dict(self.parameters)}


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
