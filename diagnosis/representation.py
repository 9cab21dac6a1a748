"""Re-writing trials as other writers would store them (the validation's item 1).

A representation is how the numbers of a trial's data columns are stored: this project's
``%.17g`` (bit-exact), ``N`` significant digits (``%.{N-1}e``, a DAQ export), fixed
decimals (``%.{N}f``, a spreadsheet), or single precision (``float32`` in a MATLAB
``.mat`` file, or float32 values printed in a CSV). ``t`` is always written exactly, so
that the trial reader of today accepts every variant.
"""

from __future__ import annotations

import copy
import json
import os
import tempfile
from pathlib import Path

import numpy as np

import trialformat as tf

#: every representation the validation draws from (name -> description)
REPRESENTATIONS = {
    "float64": "%.17g CSV (this project's writer, bit-exact)",
    "sig6": "CSV at 6 significant digits",
    "sig7": "CSV at 7 significant digits",
    "sig8": "CSV at 8 significant digits",
    "sig10": "CSV at 10 significant digits",
    "dec6": "CSV with 6 fixed decimals",
    "dec5": "CSV with 5 fixed decimals",
    "float32_mat": "MATLAB .mat with float32 data columns",
    "float32_csv": "CSV of float32 values (%.9g)",
}
#: representations other writers produce (all but the project's own)
FOREIGN = tuple(r for r in REPRESENTATIONS if r != "float64")


def _column_format(rep: str) -> str:
    if rep == "float64":
        return "%.17g"
    if rep.startswith("sig"):
        return f"%.{int(rep[3:]) - 1}e"
    if rep.startswith("dec"):
        return f"%.{int(rep[3:])}f"
    if rep == "float32_csv":
        return "%.9g"
    raise ValueError(f"unknown representation {rep!r}; known: {', '.join(REPRESENTATIONS)}")


def write_represented(stem, trial: tf.Trial, rep: str) -> Path:
    """Write ``trial`` as ``stem.csv`` + ``stem.json`` (or ``stem.mat``) in
    representation ``rep`` (a key of REPRESENTATIONS); ``t`` exact. Atomic per file.

    Returns
    -------
    Path
        The data file written.

    Raises
    ------
    ValueError
        Unknown representation.
    """
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    if rep not in REPRESENTATIONS:
        raise ValueError(f"unknown representation {rep!r}; known: {', '.join(REPRESENTATIONS)}")
    if rep == "float32_mat":
        return _write_mat32(stem, trial)
    signals = trial.signals()  # a position trial carries fewer (log-format.md)
    data = [np.asarray(trial.signal(s), dtype=float) for s in signals]
    if rep == "float32_csv":
        data = [d.astype(np.float32).astype(float) for d in data]
    table = np.hstack([trial.t[:, None]] + data)
    fmt = _column_format(rep)
    row = ",".join(["%.17g"] + [fmt] * (table.shape[1] - 1)) + "\n"
    body = (row * table.shape[0]) % tuple(table.ravel().tolist())
    header = ",".join(["t"] + [f"{s}[{j}]" for s in signals
                               for j in range(1, trial.n_dof + 1)]) + "\n"
    meta = copy.deepcopy(trial.meta)
    meta.setdefault("format", tf.FORMAT)
    _atomic(tf.logs.with_ending(stem, ".json"), json.dumps(meta, indent=2).encode())
    _atomic(tf.logs.with_ending(stem, ".csv"), (header + body).encode())
    return tf.logs.with_ending(stem, ".csv")


def _write_mat32(stem: Path, trial: tf.Trial) -> Path:
    from scipy import io as sio
    path = tf.logs.with_ending(stem, ".mat")
    data = {"t": np.asarray(trial.t, dtype=float)[:, None],
            "meta": json.dumps(trial.meta)}
    data.update({s: np.asarray(trial.signal(s)).astype(np.float32) for s in trial.signals()})
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp.mat")
    os.close(fd)
    try:
        sio.savemat(tmp, data, do_compression=True)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def _atomic(path: Path, payload: bytes) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "wb") as fh:
        fh.write(payload)
    os.replace(tmp, path)


def trial_written(stem) -> bool:
    """True when ``stem`` exists as a complete CSV+JSON pair or as a ``.mat``."""
    stem = Path(stem)
    return tf.trial_exists(stem) or tf.logs.with_ending(stem, ".mat").is_file()
