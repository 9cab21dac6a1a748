"""Trials in MATLAB ``.mat`` files, v4 to v7 (scipy.io) and v7.3 (HDF5, h5py).

``NAME.mat`` holds the variables ``t`` (N samples, row or column), ``theta``, ``tau_h``
and, for a torque perturbation, ``tau_delta`` and ``tau_m`` (N x n, one column per joint;
a 1-joint trial may be a vector), optionally ``theta_ref`` (position perturbation), and
the metadata ``meta``: a char array holding the JSON text of log-format.md, or a struct
with the same fields. Without ``meta``, the metadata is read from ``NAME.json`` beside the
file. Single precision (``single``) variables are accepted. The reader refuses what
log-format.md tells a reader to refuse, naming the file and the variable or key.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
from scipy import io as sio

from .errors import MatFileError
from .logs import MIN_SAMPLES, SIGNALS, Trial, _convention, complete_metadata, finish_trial

OPTIONAL = ("tau_delta", "tau_m", "theta_ref")


def write_trial_mat(path, trial: Trial, *, meta_as: str = "json", version: str = "5"):
    """Write a trial as ``NAME.mat`` (v5 by scipy.io) with the metadata as JSON or a struct.

    Parameters
    ----------
    path : str or os.PathLike
        Target ``.mat`` path.
    trial : trialformat.Trial
    meta_as : {"json", "struct"}
        Store ``meta`` as a JSON char array or as a MATLAB struct.
    version : {"5", "4"}
        scipy.io's format; v4 holds no struct (use ``meta_as="json"``).

    The signals are stored in the conventions the metadata declare (``sensors.torque_sign``
    -1: ``tau_h`` negated; ``angles: "absolute"``: ``theta``, ``theta_ref`` plus the posture),
    like :func:`trialformat.write_trial`, so a trial read back has the same arrays.
    """
    path = Path(path)
    if path.suffix.lower() != ".mat":
        path = path.with_name(path.name + ".mat")
    data = {"t": trial.t[:, None]}
    # stored in the file's conventions, as write_trial does: the torque_sign and angles the
    # metadata declare are undone, so that read_trial_mat returns the trial's arrays
    stored = _convention(trial.meta, trial, inverse=True)
    data.update({s: np.asarray(stored.get(s, trial.signal(s)), dtype=float)
                 for s in trial.signals()})
    if meta_as == "json":
        data["meta"] = json.dumps(trial.meta)
    elif meta_as == "struct":
        data["meta"] = _struct_safe(trial.meta)
    else:
        raise MatFileError(f"meta_as must be 'json' or 'struct', got {meta_as!r}")
    sio.savemat(path, data, do_compression=version == "5", format=version)
    return path


def read_trial_mat(path, *, min_samples: int = MIN_SAMPLES) -> Trial:
    """Read one trial from ``NAME.mat`` (metadata inside, or in ``NAME.json`` beside).

    The variables may be at the top level, or the fields of one struct (MATLAB users
    save ``S.t``, ``S.theta``... so); a struct array of trials is read by
    :func:`read_trials_mat` and refused here, naming the struct.

    Raises
    ------
    MatFileError
        The file does not load, a variable is missing or has the wrong shape, or the
        metadata does not parse.
    trialformat.TrialFormatError
        The content breaks log-format.md (non-finite values, bad t, fs, perturbed_dof...).
    """
    path, variable = split_variable(path)
    if variable is not None:
        return _nldat(path, variable, min_samples)[0]
    data = _load(path, nldat_ok=True)
    found = [] if data is None else _trial_variables(path, data)
    if not found:  # NLID nldat objects, or a refusal listing the variables and classes
        trials = _nldat(path, None, min_samples, loaded=data)
        if len(trials) > 1:
            names = ", ".join(t.name for t in trials)
            raise MatFileError(f"{path}: holds {len(trials)} nldat recordings ({names}); "
                               f"read them all with read_trials, or one as "
                               f"{path.name}:{trials[0].name}")
        return trials[0]
    if len(found) > 1:
        raise MatFileError(f"{path}: struct array '{found[0][0].split('(')[0]}' holds "
                           f"{len(found)} trials; read the file with read_trials (armimp "
                           f"estimate and figures do) or save one trial per file")
    label, data = found[0]
    return _trial_from(path, label, data, path.stem, min_samples)


def read_trials_mat(path, *, min_samples: int = MIN_SAMPLES) -> list[Trial]:
    """Every trial of ``NAME.mat``: one (top-level variables or one struct), one per
    element of a struct array ``S`` (named ``NAME.S(i)``, 1-based as in MATLAB), or one
    per NLID ``nldat`` object (trialformat.nlid); ``FILE.mat:VAR`` reads one object.

    Raises as :func:`read_trial_mat`, naming the struct element; a file that is none of
    these layouts is refused with the list of the variables and classes it holds.
    """
    path, variable = split_variable(path)
    if variable is not None:
        return _nldat(path, variable, min_samples)
    data = _load(path, nldat_ok=True)
    found = [] if data is None else _trial_variables(path, data)
    if not found:
        return _nldat(path, None, min_samples, loaded=data)
    if len(found) == 1:
        label, data = found[0]
        return [_trial_from(path, label, data, path.stem, min_samples)]
    return [_trial_from(path, label, data, f"{path.stem}.{label}", min_samples)
            for label, data in found]


def _trial_from(path, label, data, name, min_samples) -> Trial:
    where = path if label is None else f"{path} struct '{label}'"
    meta = _metadata(path, data, where)
    filled = complete_metadata(meta, where)
    n = meta["n_dof"]
    arrays = {"t": _vector(where, data, "t")}
    position = (meta.get("perturbation") or {}).get("kind") == "position"
    wanted = [s for s in SIGNALS + ("theta_ref",)
              if s in data or not (s in OPTIONAL and (position or s == "theta_ref"))]
    declared = (f"n_dof {n} (the default: no n_dof in the metadata)" if "n_dof" in filled
                else f"the metadata's n_dof: {n}")
    _check_lengths(where, data, arrays["t"].size, [s for s in wanted if s in data], n)
    for s in wanted:
        arrays[s] = _matrix(where, data, s, arrays["t"].size, n, declared)
    return finish_trial(meta, arrays, name, filled, where, min_samples=min_samples)


def _trial_variables(path: Path, data: dict) -> list:
    """``[(label, variables)]``: ``[(None, data)]`` for top-level variables, else the one
    struct (``label`` its name) or the elements of the one struct array (``S(1)``...)
    holding a field ``t``; ``[]`` when there is none (structs without ``t`` are refused
    naming their fields)."""
    user = {k: v for k, v in data.items() if not k.startswith("__")}
    if "t" in user:
        return [(None, user)]

    def elements(value):
        if isinstance(value, dict):
            return [value]
        if isinstance(value, (list, np.ndarray)) and len(value) and \
                all(isinstance(v, dict) for v in value):
            return list(value)
        return []

    _refuse_struct_grids(path, user)
    structs = {k: elements(v) for k, v in user.items() if elements(v)}
    holding = {k: v for k, v in structs.items() if all("t" in e for e in v)}
    if len(holding) == 1:
        name, items = next(iter(holding.items()))
        if len(items) == 1:
            return [(name, items[0])]
        return [(f"{name}({i})", e) for i, e in enumerate(items, start=1)]
    if len(holding) > 1:
        raise MatFileError(f"{path}: structs {sorted(holding)} each hold a trial; save one "
                           f"trial (or one struct array of trials) per file")
    if structs:
        descr = "; ".join(
            f"struct{' array' if len(v) > 1 else ''} '{k}' with fields "
            f"{', '.join(sorted(set().union(*(e.keys() for e in v))))}"
            for k, v in structs.items())
        raise MatFileError(f"{path}: no variable 't' at the top level, and no struct with "
                           f"a field 't' ({descr}); a trial needs t, theta, tau_h (and "
                           f"tau_delta, tau_m) as variables or as the fields of one struct")
    return []  # the caller tries NLID objects, else refuses listing variables and classes


def _refuse_struct_grids(path, user: dict) -> None:
    """A struct array of more than one row and column (``S(2,2)``: scipy leaves it as an
    array of structs) is refused naming its size, its fields and the layouts accepted."""
    for k, v in user.items():
        if not (isinstance(v, np.ndarray) and v.dtype == object and v.ndim >= 2
                and sum(d > 1 for d in v.shape) > 1):
            continue
        items = list(v.flat)
        if not all(isinstance(e, (dict, sio.matlab.mat_struct)) for e in items):
            continue
        fields = sorted(set().union(*(e.keys() if isinstance(e, dict) else e._fieldnames
                                      for e in items)))
        shape = "x".join(map(str, v.shape))
        raise MatFileError(
            f"{path}: struct array '{k}' is {shape} ({len(items)} elements with fields "
            f"{', '.join(fields)}); accepted are the variables t, theta, tau_h (...) and "
            f"meta at the top level, one struct holding them, or a 1-by-N (or N-by-1) "
            f"struct array of such structs (one trial each): save {k}(:)' from MATLAB "
            f"(\"{k} = {k}(:)'; save(...)\") to read its {len(items)} trials")


def split_variable(path):
    """``("FILE.mat", "VAR")`` for ``FILE.mat:VAR``, else ``(path, None)``."""
    text = str(path)
    head, sep, var = text.rpartition(":")
    if sep and head.lower().endswith(".mat") and var and "/" not in var and "\\" not in var:
        return Path(head), var
    return Path(path), None


def _nldat(path, variable, min_samples, loaded=None) -> list:
    """Trials of the nldat objects of ``path``; refuses, listing the file's variables and
    their classes, a file that holds none (and no ``t`` of the plain layout)."""
    from . import nlid
    if not path.is_file():
        raise MatFileError(f"{path}: file missing")
    inv = nlid.inventory(path)
    if nlid.holds_nldat(inv):
        return nlid.read_nldat_trials(path, variable=variable, min_samples=min_samples)
    if variable is not None:
        raise MatFileError(f"{path}: no nldat variable {variable!r}; it holds "
                           f"{nlid.describe_inventory(inv)}")
    listing = nlid.describe_inventory(inv) if inv else (
        ", ".join(f"{k} ({type(v).__name__})" for k, v in (loaded or {}).items()
                  if not k.startswith("__")) or "(no variable)")
    raise MatFileError(
        f"{path}: neither a trial (variables t, theta, tau_h, ... and meta: docs/estimation.md, "
        f"'The .mat layout') nor NLID nldat objects; it holds: {listing}")


def _load(path: Path, *, nldat_ok: bool = False) -> dict | None:
    """The variables of the file; with ``nldat_ok``, None where scipy/h5py cannot read it
    (the caller then tries the NLID reader, which lists what the file holds)."""
    if not path.is_file():
        raise MatFileError(f"{path}: file missing")
    if _is_hdf5(path):  # v7.3
        return _load_hdf5(path)
    try:
        import warnings
        with warnings.catch_warnings():  # MCOS objects (nldat) make scipy warn of "None"
            warnings.simplefilter("ignore", sio.matlab.MatReadWarning)
            data = sio.loadmat(path, simplify_cells=True)
    except (ValueError, OSError, TypeError, NotImplementedError,
            sio.matlab.MatReadError) as exc:
        if nldat_ok:
            from . import nlid
            inv = nlid.inventory(path)
            if nlid.holds_nldat(inv):
                return None
            if inv:
                raise MatFileError(f"{path}: scipy cannot read it ({exc}); it holds "
                                   f"{nlid.describe_inventory(inv)}") from None
        raise MatFileError(f"{path}: not a readable MATLAB file (v4-v7.3): {exc}") from None
    if nldat_ok and "None" in data and "t" not in data:
        return None  # opaque class objects only
    return data


def _is_hdf5(path: Path) -> bool:
    import h5py
    return h5py.is_hdf5(path)


def _load_hdf5(path: Path) -> dict:
    """A v7.3 file as loadmat(simplify_cells=True) would give it (MATLAB is column-major)."""
    import h5py
    try:
        with h5py.File(path, "r") as fh:
            return {k: _h5_value(fh[k], f"{path} variable '{k}'") for k in fh
                    if not k.startswith("#")}
    except OSError as exc:
        raise MatFileError(f"{path}: not a readable MATLAB v7.3 file: {exc}") from None


def _h5_value(node, where):
    import h5py
    cls = node.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    if isinstance(node, h5py.Group):
        return {k: _h5_value(node[k], f"{where}.{k}") for k in node if not k.startswith("#")}
    if node.attrs.get("MATLAB_empty", 0):
        return np.zeros((0, 0))
    value = node[()]
    if cls == "char":
        return "".join(chr(c) for c in np.asarray(value).T.ravel())
    if cls == "cell" or value.dtype == object:
        return _h5_cell(node, value, where)
    arr = np.asarray(value).T
    if arr.size == 1:
        return arr.item()
    return arr.squeeze() if 1 in arr.shape and arr.ndim == 2 else arr


def _h5_cell(node, value, where):
    """A cell array of numbers (hdf5storage writes a Python list so) as a numeric array.

    Each element must be a real number; anything else (text, nested cells, arrays) is
    refused naming the variable.
    """
    import h5py
    refs = np.asarray(value).T
    items = []
    for ref in refs.ravel():
        item = node.file[ref] if isinstance(ref, h5py.Reference) else None
        item = None if item is None or isinstance(item, h5py.Group) else \
            _h5_value(item, where) if item.attrs.get("MATLAB_class", b"") != b"cell" else None
        if not isinstance(item, (int, float)) or isinstance(item, bool):
            raise MatFileError(f"{where}: cell arrays are read only when every element is "
                               f"one number; store numbers, a struct or JSON text")
        items.append(float(item))
    arr = np.asarray(items).reshape(refs.shape)
    if arr.size == 1:
        return arr.item()
    return arr.squeeze() if 1 in arr.shape and arr.ndim == 2 else arr


def _metadata(path, data, holder=None) -> dict:
    raw = data.get("meta")
    holder = path if holder is None else holder
    if raw is None:
        json_path = path.with_name(path.stem + ".json")
        if not json_path.is_file():
            raise MatFileError(f"{holder}: no variable 'meta' and no {json_path.name} "
                               f"beside the file")
        raw = json_path.read_text(encoding="utf-8-sig")
        where = json_path
    else:
        where = f"{holder} variable 'meta'"
        beside = path.with_name(path.stem + ".json")
        csv_twin = any(path.with_name(path.stem + e).is_file() for e in (".csv", ".csv.gz"))
        if beside.is_file() and not csv_twin:  # never silently ignored (issue 22); with
            # a NAME.csv there, the JSON is that trial's
            raise MatFileError(f"{beside}: not read, {holder} holds its own metadata "
                               f"(variable 'meta'); merge its keys into 'meta', or remove "
                               f"or rename {beside.name}")
    if isinstance(raw, dict):
        return _from_struct(raw)
    if isinstance(raw, np.ndarray) and raw.dtype.kind == "U":
        raw = "".join(raw.ravel())
    if not isinstance(raw, str):
        raise MatFileError(f"{where}: must be JSON text or a struct, got {type(raw).__name__}")
    try:
        meta = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise MatFileError(f"{where}: JSON does not parse: {exc}") from None
    if not isinstance(meta, dict):
        raise MatFileError(f"{where}: metadata must be a JSON object")
    return meta


def _vector(path, data, name) -> np.ndarray:
    if name not in data:
        raise MatFileError(f"{path}: variable '{name}' missing; the file holds "
                           f"{_holds(data)}")
    arr = _numeric(path, data[name], name)
    if arr.ndim > 2 or (arr.ndim == 2 and min(arr.shape) != 1):
        raise MatFileError(f"{path}: variable '{name}' must be a vector, has shape {arr.shape}")
    return arr.ravel()


def _rows(arr: np.ndarray, n: int):
    """Samples of a signal variable: its length as a vector, its rows as N x n, its columns
    as n x N (transposed); None for another shape (refused by :func:`_matrix`)."""
    if arr.ndim == 1:
        return arr.size
    if arr.ndim == 2 and arr.shape[1] == n:
        return arr.shape[0]
    if arr.ndim == 2 and arr.shape[0] == n:
        return arr.shape[1]
    if arr.ndim == 2 and 1 in arr.shape:  # a row or column vector where n > 1 columns
        return max(arr.shape)
    return None


def _check_lengths(where, data, n_samples, names, n) -> None:
    """Refuse signals whose number of samples differs from t's, naming every variable's
    length (not the first signal, when t is the short one)."""
    lengths = {s: _rows(_numeric(where, data[s], s), n) for s in names}
    lengths = {s: m for s, m in lengths.items() if m is not None}
    if all(m == n_samples for m in lengths.values()):
        return
    groups: dict = {}
    for s, m in lengths.items():
        groups.setdefault(m, []).append(s)
    if len(groups) == 1:
        (m, names_m), = groups.items()
        raise MatFileError(f"{where}: t has {n_samples} samples but {', '.join(names_m)} "
                           f"{'has' if len(names_m) == 1 else 'have'} {m} rows; every variable "
                           f"needs one row per sample of t (t is {abs(m - n_samples)} "
                           f"sample{'s' if abs(m - n_samples) != 1 else ''} "
                           f"{'short' if m > n_samples else 'long'})")
    text = "; ".join(f"{', '.join(v)} {m} rows" for m, v in sorted(groups.items()))
    raise MatFileError(f"{where}: variables disagree in length: t {n_samples} samples; "
                       f"{text}; every variable needs one row per sample of t")


def _matrix(path, data, name, n_samples, n, declared=None) -> np.ndarray:
    declared = declared or f"n_dof {n}"
    if name not in data:
        raise MatFileError(f"{path}: variable '{name}' missing (expected {n_samples} x {n}); "
                           f"the file holds {_holds(data)}")
    arr = _numeric(path, data[name], name)
    if arr.ndim == 1 and n == 1:
        arr = arr[:, None]
    if arr.shape == (n_samples, n):
        return arr
    if n > 1 and (arr.ndim == 1 or (arr.ndim == 2 and 1 in arr.shape)):
        raise MatFileError(f"{path}: variable '{name}' has shape {arr.shape}: 1 column where "
                           f"{declared} needs {n}, one per joint; save it as "
                           f"{n_samples} x {n} (or declare the joints in n_dof)")
    if arr.shape == (n, n_samples):
        raise MatFileError(f"{path}: variable '{name}' has shape {arr.shape}: one row per "
                           f"joint; save it transposed, {n_samples} x {n} (one column per "
                           f"joint, {declared})")
    raise MatFileError(f"{path}: variable '{name}' has shape {arr.shape}, expected "
                       f"({n_samples}, {n}) for {declared}")


def _holds(data) -> str:
    """``t (60000 float64), meta (str)``: the variables as loaded, for a refusal."""
    out = []
    for k, v in data.items():
        if k.startswith("__"):
            continue
        if isinstance(v, np.ndarray):
            out.append(f"{k} ({'x'.join(map(str, v.shape)) or 'scalar'} {v.dtype})")
        else:
            out.append(f"{k} ({type(v).__name__})")
    return ", ".join(out) or "no variable"


def _numeric(path, value, name) -> np.ndarray:
    try:
        arr = np.asarray(value)
        if arr.dtype.kind not in "biuf":
            raise TypeError
        return arr.astype(float)  # single precision widened exactly
    except (TypeError, ValueError):
        raise MatFileError(f"{path}: variable '{name}' is not numeric") from None


def _struct_safe(value):
    """Metadata for savemat: None becomes an empty array (MATLAB has no null)."""
    if isinstance(value, dict):
        return {k: _struct_safe(v) for k, v in value.items()}
    if value is None:
        return np.zeros((0, 0))
    return value


def _from_struct(value):
    """Back from a loaded struct: arrays to lists, empty arrays to None, 1x1 to scalars."""
    if isinstance(value, dict):
        return {k: _from_struct(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        if value.size == 0:
            return None
        if value.dtype.kind == "U":
            return "".join(value.ravel())
        return _from_struct(value.tolist())
    if isinstance(value, list):
        return [_from_struct(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def is_mat(path: str | os.PathLike) -> bool:
    return Path(path).suffix.lower() == ".mat"
