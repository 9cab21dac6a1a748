"""Trials in MATLAB ``.mat`` files (layout in docs/estimation.md).

``NAME.mat`` holds the variables ``t`` (N samples, row or column), ``tau_delta``,
``theta``, ``tau_h``, ``tau_m`` (N x n, one column per joint; a 1-joint trial may be a
vector) and the metadata ``meta``: a char array holding the JSON text of log-format.md, or
a struct with the same fields. Without ``meta``, the metadata is read from ``NAME.json``
beside the file. Versions 4, 5 and 7 (not 7.3/HDF5) are read, by ``scipy.io.loadmat``.
The reader refuses what log-format.md tells a reader to refuse, naming the file and the
variable or key.
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path

import numpy as np
from scipy import io as sio

import trialformat as tf
from trialformat.logs import complete_metadata

from .errors import MatFileError


def write_trial_mat(path, trial, *, meta_as="json"):
    """Write a trial as ``NAME.mat`` with the metadata as JSON text (or a struct).

    Parameters
    ----------
    path : str or os.PathLike
        Target ``.mat`` path.
    trial : trialformat.Trial
    meta_as : {"json", "struct"}
        Store ``meta`` as a JSON char array or as a MATLAB struct.
    """
    path = Path(path).with_suffix(".mat")
    data = {"t": trial.t[:, None]}
    data.update({s: trial.signal(s) for s in tf.SIGNALS})
    if meta_as == "json":
        data["meta"] = json.dumps(trial.meta)
    elif meta_as == "struct":
        data["meta"] = _struct_safe(trial.meta)
    else:
        raise MatFileError(f"meta_as must be 'json' or 'struct', got {meta_as!r}")
    sio.savemat(path, data, do_compression=True)
    return path


def read_trial_mat(path, *, min_samples=tf.MIN_SAMPLES) -> tf.Trial:
    """Read one trial from ``NAME.mat`` (metadata inside, or in ``NAME.json`` beside).

    Raises
    ------
    MatFileError
        The file does not load, a variable is missing or has the wrong shape, or the
        metadata does not parse.
    trialformat.TrialFormatError
        The content breaks log-format.md (non-finite values, bad t, fs, perturbed_dof...).
    """
    path = Path(path)
    try:
        data = sio.loadmat(path, simplify_cells=True)
    except (ValueError, OSError, NotImplementedError, sio.matlab.MatReadError) as exc:
        raise MatFileError(f"{path}: not a readable MATLAB file (v4-v7): {exc}") from None
    meta = _metadata(path, data)
    filled = complete_metadata(meta, path)
    n = meta["n_dof"]
    arrays = {"t": _vector(path, data, "t")}
    for s in tf.SIGNALS:
        arrays[s] = _matrix(path, data, s, arrays["t"].size, n)
    trial = tf.Trial(meta=meta, name=path.stem, filled_defaults=filled, **arrays)
    tf.check_trial(trial, path, min_samples=min_samples)
    if filled:
        warnings.warn(f"{path.name}: metadata keys absent, filled from the reference "
                      f"configuration: {', '.join(filled)}", stacklevel=2)
    return trial


def _metadata(path, data) -> dict:
    raw = data.get("meta")
    if raw is None:
        json_path = path.with_suffix(".json")
        if not json_path.is_file():
            raise MatFileError(f"{path}: no variable 'meta' and no {json_path.name} beside it")
        raw = json_path.read_text(encoding="utf-8")
        where = json_path
    else:
        where = f"{path} variable 'meta'"
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
        raise MatFileError(f"{path}: variable '{name}' missing")
    arr = np.asarray(data[name], dtype=float)
    if arr.ndim > 2 or (arr.ndim == 2 and min(arr.shape) != 1):
        raise MatFileError(f"{path}: variable '{name}' must be a vector, has shape {arr.shape}")
    return arr.ravel()


def _matrix(path, data, name, n_samples, n) -> np.ndarray:
    if name not in data:
        raise MatFileError(f"{path}: variable '{name}' missing (expected {n_samples} x {n})")
    try:
        arr = np.asarray(data[name], dtype=float)
    except (TypeError, ValueError):
        raise MatFileError(f"{path}: variable '{name}' is not numeric") from None
    if arr.ndim == 1 and n == 1:
        arr = arr[:, None]
    if arr.shape != (n_samples, n):
        raise MatFileError(f"{path}: variable '{name}' has shape {arr.shape}, expected "
                           f"({n_samples}, {n}) for n_dof={n}")
    return arr


def _struct_safe(value):
    """Metadata for savemat: None becomes an empty array (MATLAB has no null)."""
    if isinstance(value, dict):
        return {k: _struct_safe(v) for k, v in value.items()}
    if value is None:
        return np.zeros((0, 0))
    return value


def _from_struct(value):
    """Back from loadmat(simplify_cells=True): arrays to lists, empty arrays to None."""
    if isinstance(value, dict):
        return {k: _from_struct(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return None if value.size == 0 else _from_struct(value.tolist())
    if isinstance(value, list):
        return [_from_struct(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def is_mat(path: str | os.PathLike) -> bool:
    return Path(path).suffix.lower() == ".mat"
