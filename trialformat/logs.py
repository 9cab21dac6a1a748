"""Reading and writing trials in the interchange format of docs/spec/log-format.md.

A trial is ``NAME.csv`` (one row per sample) plus ``NAME.json`` (metadata). Writing is
atomic: both files are written under temporary names and renamed, the JSON last, so a
trial whose JSON exists is complete. Readers refuse what the format forbids with a
:class:`TrialFormatError` naming the file and the row, column or key.
"""

from __future__ import annotations

import copy
import json
import os
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import reference as ref
from .errors import TrialFormatError

FORMAT = "arm-impedance-trial/1"
SIGNALS = ("tau_delta", "theta", "tau_h", "tau_m")
MIN_SAMPLES = 8192  # one spectral segment (Table IV)


@dataclass
class Trial:
    """One experiment recorded at the control rate.

    Attributes
    ----------
    meta : dict
        Metadata (log-format.md keys); absent keys filled from the reference.
    t : ndarray [s], shape (N,)
    tau_delta, theta, tau_h, tau_m : ndarray, shape (N, n)
        Perturbation [N m], measured angle [rad], measured interaction torque [N m],
        motor torque command [N m]; column j-1 is joint j.
    extra : dict of ndarray
        Extra columns, by header name.
    name : str
        File stem (``NAME``), empty for a trial not read from disk.
    filled_defaults : list of str
        Metadata keys the reader filled from the reference configuration.
    """

    meta: dict
    t: np.ndarray
    tau_delta: np.ndarray
    theta: np.ndarray
    tau_h: np.ndarray
    tau_m: np.ndarray
    extra: dict = field(default_factory=dict)
    name: str = ""
    filled_defaults: list = field(default_factory=list)

    @property
    def n_dof(self) -> int:
        return int(self.meta["n_dof"])

    @property
    def fs(self) -> float:
        return float(self.meta["fs"])

    @property
    def perturbed_dof(self) -> int | None:
        """1-based perturbed joint, or None when all joints are perturbed at once."""
        k = self.meta.get("perturbed_dof")
        return None if k is None else int(k)

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    def signal(self, name: str) -> np.ndarray:
        """One of ``tau_delta``, ``theta``, ``tau_h``, ``tau_m`` as an (N, n) array."""
        if name not in SIGNALS:
            raise KeyError(f"unknown signal {name!r}; expected one of {SIGNALS}")
        return getattr(self, name)


def default_metadata(n_dof: int = 2) -> dict:
    """Metadata of the reference set-up (friction level 0, ideal sensors)."""
    r = ref.reference()
    return {
        "format": FORMAT,
        "fs": 1.0 / r["timing"]["control_period_s"],
        "n_dof": n_dof,
        "perturbed_dof": 1,
        "posture_deg": r["human_arm"]["posture_deg"],
        "perturbation": {"level": 3, "peak": ref.perturbation_peak(3), "seed": 0,
                         "cutoff_hz": r["perturbation"]["cutoff_hz"],
                         "order": r["perturbation"]["butterworth_order"]},
        "controller": ref.controller("reference"),
        "sensors": ref.sensor_level(0),
        "robot": ref.robot(),
        "friction": ref.friction_level(0, n_dof),
        "source": "",
    }


def column_names(n_dof: int) -> list[str]:
    """CSV header for n joints: ``t`` then each signal's ``[1]..[n]`` columns."""
    return ["t"] + [f"{s}[{j}]" for s in SIGNALS for j in range(1, n_dof + 1)]


# ----------------------------------------------------------------------------- writing


def write_trial(stem: str | os.PathLike, trial: Trial) -> Path:
    """Write ``stem.csv`` and ``stem.json`` atomically; return the CSV path.

    Values are written with 17 significant digits, so a trial read back is bit-identical.
    """
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    n = trial.n_dof
    header = column_names(n) + list(trial.extra)
    cols = [trial.t[:, None]] + [trial.signal(s).reshape(-1, n) for s in SIGNALS]
    cols += [np.asarray(v, dtype=float)[:, None] for v in trial.extra.values()]
    table = np.hstack(cols)
    meta = copy.deepcopy(trial.meta)
    meta.setdefault("format", FORMAT)
    csv_path, json_path = stem.with_suffix(".csv"), stem.with_suffix(".json")
    _atomic_write(csv_path, lambda fh: fh.write(_format_csv(header, table)))
    _atomic_write(json_path, lambda fh: fh.write(json.dumps(meta, indent=2).encode()))
    return csv_path


def _format_csv(header: list[str], table: np.ndarray) -> bytes:
    # One % over the whole table: about twice as fast as np.savetxt's per-row loop.
    row = ",".join(["%.17g"] * table.shape[1]) + "\n"
    body = (row * table.shape[0]) % tuple(table.ravel().tolist())
    return (",".join(header) + "\n" + body).encode()


def _atomic_write(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def trial_exists(stem: str | os.PathLike) -> bool:
    """True when both files of a completely written trial are present."""
    stem = Path(stem)
    return stem.with_suffix(".json").is_file() and stem.with_suffix(".csv").is_file()


# ----------------------------------------------------------------------------- reading


def read_trial(path: str | os.PathLike, *, min_samples: int = MIN_SAMPLES) -> Trial:
    """Read one trial from ``NAME.csv`` (or ``NAME.json``, or the stem).

    Raises
    ------
    TrialFormatError
        On anything log-format.md tells a reader to refuse; the message names the file.
    """
    stem = Path(path)
    if stem.suffix in (".csv", ".json"):
        stem = stem.with_suffix("")
    csv_path, json_path = stem.with_suffix(".csv"), stem.with_suffix(".json")
    meta, filled = _read_metadata(json_path)
    header, table = _read_table(csv_path)
    arrays = _split_columns(csv_path, header, table, meta["n_dof"])
    trial = Trial(meta=meta, name=stem.name, filled_defaults=filled, **arrays)
    check_trial(trial, csv_path, min_samples=min_samples)
    if filled:
        warnings.warn(f"{json_path.name}: metadata keys absent, filled from the reference "
                      f"configuration: {', '.join(filled)}", stacklevel=2)
    return trial


def read_trials(source, *, min_samples: int = MIN_SAMPLES) -> list[Trial]:
    """Read every trial of a folder (each ``*.csv`` with its ``.json``) or a list of paths."""
    if isinstance(source, (str, os.PathLike)) and Path(source).is_dir():
        paths = sorted(p for p in Path(source).glob("*.csv"))
        if not paths:
            raise TrialFormatError(f"{source}: folder holds no trial (no NAME.csv)")
    elif isinstance(source, (str, os.PathLike)):
        paths = [Path(source)]
    else:
        paths = [Path(p) for p in source]
        if not paths:
            raise TrialFormatError("no trial given (empty list of paths)")
    return [read_trial(p, min_samples=min_samples) for p in paths]


def _read_metadata(json_path: Path) -> tuple[dict, list[str]]:
    if not json_path.is_file():
        raise TrialFormatError(f"{json_path}: metadata file missing (every NAME.csv needs "
                               f"its NAME.json)")
    try:
        with open(json_path, encoding="utf-8") as fh:
            meta = json.load(fh)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise TrialFormatError(f"{json_path}: JSON does not parse: {exc}") from None
    if not isinstance(meta, dict):
        raise TrialFormatError(f"{json_path}: metadata must be a JSON object")
    return meta, complete_metadata(meta, json_path)


def complete_metadata(meta: dict, where) -> list[str]:
    """Check the metadata keys and fill absent ones from the reference, in place.

    Shared by the readers of other containers (e.g. estimation's ``.mat`` reader).
    Returns the keys filled; raises TrialFormatError naming ``where``.
    """
    json_path = where
    n_dof = meta.get("n_dof", 2)
    if not isinstance(n_dof, int) or isinstance(n_dof, bool) or n_dof < 1:
        raise TrialFormatError(f"{json_path}: key 'n_dof' must be a positive integer, "
                               f"got {n_dof!r}")
    defaults = default_metadata(n_dof)
    defaults["perturbed_dof"] = None
    filled = []
    for key, value in defaults.items():
        if key not in meta:
            meta[key] = value
            if key not in ("format", "source"):
                filled.append(key)
        elif isinstance(value, dict) and isinstance(meta[key], dict):
            for sub, sub_value in value.items():
                if sub not in meta[key]:
                    meta[key][sub] = sub_value
                    filled.append(f"{key}.{sub}")
    k = meta["perturbed_dof"]
    if k is not None and (not isinstance(k, int) or isinstance(k, bool) or not 1 <= k <= n_dof):
        raise TrialFormatError(f"{json_path}: key 'perturbed_dof' must be null or an integer "
                               f"in 1..{n_dof}, got {k!r}")
    fs = meta["fs"]
    if not isinstance(fs, (int, float)) or not np.isfinite(fs) or fs <= 0:
        raise TrialFormatError(f"{json_path}: key 'fs' must be a positive number, got {fs!r}")
    return filled


def _read_table(csv_path: Path) -> tuple[list[str], np.ndarray]:
    if not csv_path.is_file():
        raise TrialFormatError(f"{csv_path}: data file missing")
    with open(csv_path, encoding="utf-8") as fh:
        header = [h.strip() for h in fh.readline().strip().split(",")]
        try:
            table = np.loadtxt(fh, delimiter=",", dtype=float, ndmin=2)
        except ValueError as exc:
            raise TrialFormatError(f"{csv_path}: non-numeric value ({_row_hint(exc)})") from None
    if table.size and table.shape[1] != len(header):
        raise TrialFormatError(f"{csv_path}: {table.shape[1]} values per row but "
                               f"{len(header)} header columns")
    bad = ~np.isfinite(table)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise TrialFormatError(f"{csv_path}: non-finite value {table[row, col]!r} in column "
                               f"'{header[col]}' at data row {row + 1}")
    return header, table


def _row_hint(exc: ValueError) -> str:
    # numpy's message names the row ("... at row 12, column 3"); keep it, it is the location.
    return str(exc).strip().splitlines()[-1]


def _split_columns(csv_path: Path, header: list[str], table: np.ndarray, n: int) -> dict:
    index = {name: i for i, name in enumerate(header)}
    missing = [c for c in column_names(n) if c not in index]
    if missing:
        raise TrialFormatError(f"{csv_path}: missing columns for the declared "
                               f"n_dof={n}: {', '.join(missing)}")
    arrays = {"t": table[:, index["t"]].copy()}
    for s in SIGNALS:
        arrays[s] = table[:, [index[f"{s}[{j}]"] for j in range(1, n + 1)]].copy()
    known = set(column_names(n))
    arrays["extra"] = {h: table[:, i].copy() for h, i in index.items() if h not in known}
    return arrays


def check_trial(trial: Trial, where, *, min_samples: int = MIN_SAMPLES) -> None:
    """Check a trial's arrays against its metadata; raise TrialFormatError naming ``where``."""
    t, fs, n = trial.t, trial.fs, trial.n_dof
    if t.shape[0] < min_samples:
        raise TrialFormatError(f"{where}: {t.shape[0]} samples, fewer than one spectral "
                               f"segment ({min_samples})")
    for s in SIGNALS:
        arr = trial.signal(s)
        if arr.shape != (t.shape[0], n):
            raise TrialFormatError(f"{where}: signal {s} has shape {arr.shape}, expected "
                                   f"({t.shape[0]}, {n})")
        bad = ~np.isfinite(arr)
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise TrialFormatError(f"{where}: non-finite value in column '{s}[{col + 1}]' "
                                   f"at data row {row + 1}")
    dt = np.diff(t)
    if t[0] != 0.0 and abs(t[0]) > 0.5 / fs:
        raise TrialFormatError(f"{where}: column 't' must start at 0, starts at {t[0]!r}")
    if (dt <= 0).any():
        row = int(np.argmax(dt <= 0)) + 2
        raise TrialFormatError(f"{where}: column 't' is not increasing at data row {row}")
    expected = 1.0 / fs
    off = np.abs(dt - expected) > 1e-6 * expected + 1e-9
    if off.any():
        row = int(np.argmax(off)) + 2
        spread = dt.max() - dt.min()
        if spread > 1e-6 * expected + 1e-9:
            raise TrialFormatError(f"{where}: column 't' is not uniform (step {dt[row - 2]!r} "
                                   f"at data row {row}, expected {expected!r})")
        raise TrialFormatError(f"{where}: key 'fs'={fs!r} disagrees with column 't' "
                               f"(step {dt[0]!r} s, i.e. fs={1.0 / dt[0]!r})")
    k = trial.perturbed_dof
    if k is not None and not np.any(trial.tau_delta[:, k - 1]):
        raise TrialFormatError(f"{where}: column 'tau_delta[{k}]' is identically zero for "
                               f"the perturbed joint {k}")
