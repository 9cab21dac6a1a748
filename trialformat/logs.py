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
import shutil
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import reference as ref
from . import csvtable
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
        motor torque command [N m]; column j-1 is joint j. ``tau_delta`` and ``tau_m``
        may be None in a position-perturbation trial.
    theta_ref : ndarray [rad], shape (N, n), or None
        Commanded position reference of a position-perturbation trial, when recorded.
    extra : dict of ndarray
        Extra columns, by header name.
    name : str
        File stem (``NAME``), empty for a trial not read from disk.
    filled_defaults : list of str
        Metadata keys the reader filled from the reference configuration.
    t_stored : ndarray [s], shape (N,), or None
        ``t`` as the file stored it, when that differs from the exact grid ``t`` (printed
        with finite decimals or in single precision); None otherwise.
    """

    meta: dict
    t: np.ndarray
    tau_delta: np.ndarray | None = None
    theta: np.ndarray | None = None
    tau_h: np.ndarray | None = None
    tau_m: np.ndarray | None = None
    extra: dict = field(default_factory=dict)
    name: str = ""
    filled_defaults: list = field(default_factory=list)
    theta_ref: np.ndarray | None = None
    t_stored: np.ndarray | None = None

    @property
    def perturbation_kind(self) -> str:
        """``"torque"`` (default) or ``"position"`` (log-format.md, "Position perturbations")."""
        pert = self.meta.get("perturbation") or {}
        return str(pert.get("kind", "torque"))

    @property
    def n_dof(self) -> int:
        return int(self.meta["n_dof"])

    @property
    def fs(self) -> float:
        return float(self.meta["fs"])

    @property
    def perturbed_dof(self) -> int | None:
        """1-based perturbed joint, or None when all joints are perturbed at once.

        A one-joint trial's perturbed joint is joint 1, declared or not.
        """
        k = self.meta.get("perturbed_dof")
        if k is None and int(self.meta.get("n_dof", 2)) == 1:
            return 1
        return None if k is None else int(k)

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    def signal(self, name: str) -> np.ndarray:
        """One of ``tau_delta``, ``theta``, ``tau_h``, ``tau_m``, ``theta_ref`` as (N, n).

        Raises KeyError for an unknown name or a signal this trial does not carry.
        """
        if name not in SIGNALS + ("theta_ref",):
            raise KeyError(f"unknown signal {name!r}; expected one of {SIGNALS + ('theta_ref',)}")
        value = getattr(self, name)
        if value is None:
            raise KeyError(f"trial {self.name or '(unnamed)'} carries no {name!r} "
                           f"({self.perturbation_kind} perturbation)")
        return value

    def signals(self) -> tuple[str, ...]:
        """Names of the signals this trial carries, in column order."""
        names = [s for s in SIGNALS if getattr(self, s) is not None]
        return tuple(names + (["theta_ref"] if self.theta_ref is not None else []))


#: numbers of joints whose reference set-up (robot, controller, posture) fills absent keys
REFERENCE_JOINTS = (2, 3)


def default_metadata(n_dof: int = 2) -> dict:
    """Metadata of the reference set-up (friction level 0, ideal sensors).

    For a number of joints with no reference set-up (``REFERENCE_JOINTS``; e.g. one
    joint) nothing is borrowed from the two-joint reference: ``posture_deg``, ``robot``
    and ``controller`` are absent (a consumer that needs them refuses, naming the key),
    and the documented defaults are fs = 1000 Hz, ideal sensors (level 0), no friction
    (Fc = Fs = sigma2 = 0 per joint) and a torque perturbation without level or peak
    (log-format.md).
    """
    r = ref.reference()
    if n_dof not in REFERENCE_JOINTS:
        fric = ref.friction_level(0, 2)
        return {
            "format": FORMAT, "fs": 1.0 / r["timing"]["control_period_s"], "n_dof": n_dof,
            "perturbed_dof": 1 if n_dof == 1 else None,
            "perturbation": {"seed": 0, "cutoff_hz": r["perturbation"]["cutoff_hz"],
                             "order": r["perturbation"]["butterworth_order"]},
            "sensors": ref.sensor_level(0),
            "friction": {**{k: [0.0] * n_dof for k in ("Fc", "Fs", "sigma2")},
                         **{k: fric[k] for k in ("sigma0", "sigma1", "ws")}},
            "source": "",
        }
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
    """CSV header of a torque-perturbation trial: ``t`` then each signal's ``[1]..[n]``."""
    return ["t"] + [f"{s}[{j}]" for s in SIGNALS for j in range(1, n_dof + 1)]


def required_columns(meta: dict) -> list[str]:
    """Columns a reader requires for this metadata (position trials need fewer)."""
    n = int(meta["n_dof"])
    if (meta.get("perturbation") or {}).get("kind", "torque") == "position":
        return ["t"] + [f"{s}[{j}]" for s in ("theta", "tau_h") for j in range(1, n + 1)]
    return column_names(n)


# ----------------------------------------------------------------------------- writing


def write_trial(stem: str | os.PathLike, trial: Trial) -> Path:
    """Write ``stem.csv`` and ``stem.json`` atomically; return the CSV path.

    Values are written in their shortest round-trip form, so a trial read back is
    bit-identical;
    the sign and angle conventions the metadata declare are restored on writing. The
    files get the user's umask (as ``open`` would), not the private mode of a temp file.
    """
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    n = trial.n_dof
    header, cols = ["t"], [trial.t[:, None]]
    stored = _convention(trial.meta, trial, inverse=True)
    for s in trial.signals():
        header += [f"{s}[{j}]" for j in range(1, n + 1)]
        cols.append(np.asarray(stored.get(s, trial.signal(s)), dtype=float).reshape(-1, n))
    header += list(trial.extra)
    cols += [np.asarray(v, dtype=float)[:, None] for v in trial.extra.values()]
    table = np.hstack(cols)
    meta = copy.deepcopy(trial.meta)
    meta.setdefault("format", FORMAT)
    csv_path, json_path = stem.with_suffix(".csv"), stem.with_suffix(".json")
    atomic_write(csv_path, lambda fh: fh.write(csvtable.to_text(header, table)))
    atomic_write(json_path, lambda fh: fh.write(json.dumps(meta, indent=2).encode()))
    return csv_path


def atomic_write(path: str | os.PathLike, write) -> None:
    """Write through a temporary file and rename; ``write(fh)`` gets a binary handle.

    The file ends with mode 0666 masked by the process umask.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~current_umask())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def replace_dir(tmp: str | os.PathLike, out: str | os.PathLike) -> None:
    """Put the finished folder ``tmp`` in place of ``out`` (a report written whole or not
    at all): the old folder is moved aside first, then removed."""
    tmp, out = Path(tmp), Path(out)
    if not out.exists():
        os.replace(tmp, out)
        return
    old = out.with_name(f".{out.name}.old")
    shutil.rmtree(old, ignore_errors=True)
    os.replace(out, old)
    os.replace(tmp, out)
    shutil.rmtree(old, ignore_errors=True)


def current_umask() -> int:
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def trial_exists(stem: str | os.PathLike) -> bool:
    """True when both files of a completely written trial are present."""
    stem = Path(stem)
    return stem.with_suffix(".json").is_file() and stem.with_suffix(".csv").is_file()


# ----------------------------------------------------------------------------- reading


def read_trial(path: str | os.PathLike, *, min_samples: int = MIN_SAMPLES) -> Trial:
    """Read one trial: ``NAME.csv`` (+ ``NAME.json``), the stem, or ``NAME.mat``.

    CSV of any common writer is accepted (docs/spec/log-format.md, "Lab data"); ``.mat``
    files are read by :func:`trialformat.matlab.read_trial_mat`. ``t`` is checked against
    ``fs`` at its printed resolution and returned as the exact grid ``arange(N) / fs``.
    ``tau_h`` and ``theta`` come back in the project's conventions (``torque_sign``,
    ``angles`` of the metadata applied).

    Raises
    ------
    TrialFormatError
        On anything log-format.md tells a reader to refuse; the message names the file and
        the 1-based data row, column or key.
    """
    if Path(path).suffix.lower() == ".mat":
        from .matlab import read_trial_mat
        return read_trial_mat(path, min_samples=min_samples)
    stem = Path(path)
    if stem.suffix in (".csv", ".json"):
        stem = stem.with_suffix("")
    csv_path, json_path = stem.with_suffix(".csv"), stem.with_suffix(".json")
    if not (Path(path).exists() or csv_path.exists() or json_path.exists()):
        raise TrialFormatError(f"{path}: no such file or folder")
    meta, filled = _read_metadata(json_path)
    if not csv_path.is_file():
        raise TrialFormatError(f"{csv_path}: data file missing")
    header, delimiter = csvtable.read_header(csv_path)
    arrays = _columns(csv_path, header, delimiter, meta, filled)
    return finish_trial(meta, arrays, stem.name, filled, csv_path, min_samples=min_samples)


def finish_trial(meta: dict, arrays: dict, name: str, filled: list, where, *,
                 min_samples: int = MIN_SAMPLES) -> Trial:
    """Build, check and convert a trial from its arrays (shared by the CSV and .mat readers)."""
    trial = Trial(meta=meta, name=name, filled_defaults=filled, **arrays)
    check_trial(trial, where, min_samples=min_samples)
    exact = np.arange(trial.n_samples) / trial.fs
    if not np.array_equal(trial.t, exact):
        trial.t_stored = trial.t
    trial.t = exact
    for s, value in _convention(meta, trial).items():
        setattr(trial, s, value)
    if filled:
        warnings.warn(f"{Path(str(where)).name}: metadata keys absent, filled from the "
                      f"reference configuration: {', '.join(filled)}", stacklevel=3)
    return trial


def read_trials(source, *, min_samples: int = MIN_SAMPLES) -> list[Trial]:
    """Read every trial of a folder (``*.csv`` and ``*.mat``) or of a list of paths.

    A stem present both as ``NAME.csv`` and ``NAME.mat`` is refused as ambiguous.
    """
    if isinstance(source, (str, os.PathLike)) and Path(source).is_dir():
        csv_paths = sorted(Path(source).glob("*.csv"))
        mat_paths = sorted(Path(source).glob("*.mat"))
        both = sorted({p.stem for p in csv_paths} & {p.stem for p in mat_paths})
        if both:
            raise TrialFormatError(f"{source}: trial(s) {both} present both as .csv and "
                                   f".mat; keep one")
        paths = csv_paths + mat_paths
        if not paths:
            raise TrialFormatError(f"{source}: folder holds no trial (no NAME.csv or "
                                   f"NAME.mat)")
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
        with open(json_path, encoding="utf-8-sig") as fh:
            meta = json.load(fh)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise TrialFormatError(f"{json_path}: JSON does not parse: {exc}") from None
    if not isinstance(meta, dict):
        raise TrialFormatError(f"{json_path}: metadata must be a JSON object")
    return meta, complete_metadata(meta, json_path)


_CHOICES = {("perturbation", "kind"): ("torque", "position"),
            ("sensors", "torque_sampling"): ("left_limit", "instantaneous"),
            ("sensors", "torque_sign"): (1, -1),
            (None, "angles"): ("absolute",)}
_CHOICE_HINTS = {"angles": " (absent: theta is the deviation from posture_deg)"}


def complete_metadata(meta: dict, where) -> list[str]:
    """Check the metadata keys and fill absent ones from the reference, in place.

    Integer keys written as integral floats (``2.0``, MATLAB doubles) become ints; 2.5 is
    refused. Shared by the readers of other containers (``.mat``). Returns the keys
    filled; raises TrialFormatError naming ``where``.
    """
    _integral(meta, "n_dof", where, default=2)
    n_dof = meta.get("n_dof", 2)
    if n_dof < 1:
        raise TrialFormatError(f"{where}: key 'n_dof' must be a positive integer, "
                               f"got {n_dof!r}")
    defaults = default_metadata(n_dof)
    defaults["perturbed_dof"] = None
    if isinstance(meta.get("perturbation"), dict) and \
            meta["perturbation"].get("kind") == "position":
        del defaults["perturbation"]  # the torque perturbation's keys do not apply
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
    _integral(meta, "perturbed_dof", where)
    for sub in ("level", "seed", "order"):
        if isinstance(meta.get("perturbation"), dict):
            _integral(meta["perturbation"], sub, where, prefix="perturbation.")
    if isinstance(meta.get("sensors"), dict):
        _integral(meta["sensors"], "torque_sign", where, prefix="sensors.")
    k = meta["perturbed_dof"]
    if k is not None and not 1 <= k <= n_dof:
        raise TrialFormatError(f"{where}: key 'perturbed_dof' must be null or an integer "
                               f"in 1..{n_dof}, got {k!r}")
    fs = meta["fs"]
    if (not isinstance(fs, (int, float)) or isinstance(fs, bool) or not np.isfinite(fs)
            or fs <= 0):
        raise TrialFormatError(f"{where}: key 'fs' must be a positive number, got "
                               f"{_num(fs) if isinstance(fs, float) else repr(fs)}")
    for (group, key), allowed in _CHOICES.items():
        holder = meta if group is None else meta.get(group)
        if isinstance(holder, dict) and key in holder and holder[key] not in allowed:
            name = key if group is None else f"{group}.{key}"
            raise TrialFormatError(f"{where}: key '{name}' must be one of {list(allowed)}"
                                   f"{_CHOICE_HINTS.get(key, '')}, got {holder[key]!r}")
    if not {"perturbation", "perturbation.cutoff_hz"} & set(filled):
        _check_cutoff(meta, where)  # a filled reference value is not the lab's to fix
    if meta.get("format") != FORMAT:
        warnings.warn(f"{Path(str(where)).name}: unknown format {meta.get('format')!r} "
                      f"(this reader knows {FORMAT!r}); read as {FORMAT}", stacklevel=3)
    return filled


def _check_cutoff(meta: dict, where) -> None:
    """Refuse a ``perturbation.cutoff_hz`` that is not a positive number below fs/2 (it sets
    the default fit band)."""
    pert = meta.get("perturbation")
    if not isinstance(pert, dict) or "cutoff_hz" not in pert:
        return
    c = pert["cutoff_hz"]
    if (not isinstance(c, (int, float)) or isinstance(c, bool) or not np.isfinite(c)
            or c <= 0):
        raise TrialFormatError(f"{where}: key 'perturbation.cutoff_hz' must be a positive "
                               f"number [Hz], got {c!r}")
    if c > meta["fs"] / 2:
        raise TrialFormatError(f"{where}: key 'perturbation.cutoff_hz'={c!r} Hz is above the "
                               f"Nyquist frequency fs/2={_num(meta['fs'] / 2)} Hz")


def _integral(holder: dict, key: str, where, *, default=None, prefix="") -> None:
    """Turn an integral float into an int in place; refuse non-integral values."""
    value = holder.get(key, default)
    if value is None or key not in holder:
        return
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if ok and isinstance(value, float):
        ok = np.isfinite(value) and value == int(value)
    if not ok:
        raise TrialFormatError(f"{where}: key '{prefix}{key}' must be an integer, "
                               f"got {value!r}")
    holder[key] = int(value)


def _columns(csv_path: Path, header: list[str], delimiter: str, meta: dict,
             filled=()) -> dict:
    """The trial's arrays from the CSV, by the columns its metadata declare."""
    n = int(meta["n_dof"])
    said = (f"n_dof={n} (filled from the reference: the JSON declares no n_dof)"
            if "n_dof" in filled else f"the declared n_dof={n}")
    present = set(header)
    missing = [c for c in required_columns(meta) if c not in present]
    if missing:
        raise TrialFormatError(f"{csv_path}: missing columns for {said}: "
                               f"{', '.join(missing)} (header: {', '.join(header)})")
    known = {f"{s}[{j}]" for s in SIGNALS + ("theta_ref",) for j in range(1, n + 1)} | {"t"}
    wanted = [h for h in header if h in known]
    dup = sorted({h for h in wanted if wanted.count(h) > 1})
    if dup:
        raise TrialFormatError(f"{csv_path}: column(s) {', '.join(dup)} appear more than "
                               f"once in the header")
    for s in ("tau_delta", "tau_m"):
        cols = [f"{s}[{j}]" for j in range(1, n + 1)]
        have = [c for c in cols if c in present]
        if have and len(have) != n:
            raise TrialFormatError(f"{csv_path}: missing columns for {said}: "
                                   f"{', '.join(c for c in cols if c not in present)}")
    declared, extra = csvtable.read_columns(csv_path, header, delimiter, wanted)
    arrays = {"t": declared["t"], "extra": extra}
    for s in SIGNALS:
        if f"{s}[1]" in declared:
            arrays[s] = np.column_stack([declared[f"{s}[{j}]"] for j in range(1, n + 1)])
    ref_cols = [f"theta_ref[{j}]" for j in range(1, n + 1)]
    if any(c in declared for c in ref_cols):
        arrays["theta_ref"] = np.column_stack(
            [declared[c] if c in declared else np.zeros_like(declared["t"]) for c in ref_cols])
    return arrays


def _convention(meta: dict, trial: Trial, *, inverse: bool = False) -> dict:
    """Signals converted to (or, inverse, back from) the project's sign and angle convention."""
    out = {}
    sign = (meta.get("sensors") or {}).get("torque_sign", 1)
    if sign == -1 and trial.tau_h is not None:
        out["tau_h"] = -trial.tau_h
    if meta.get("angles") == "absolute":
        offset = np.deg2rad(np.asarray(meta["posture_deg"], dtype=float))
        for s in ("theta", "theta_ref"):
            if getattr(trial, s) is not None:
                out[s] = getattr(trial, s) + (offset if inverse else -offset)
    return out


def check_trial(trial: Trial, where, *, min_samples: int = MIN_SAMPLES) -> None:
    """Check a trial's arrays against its metadata; raise TrialFormatError naming ``where``.

    ``t`` is uniform when every ``|t[i] - i/fs|`` is below half its last printed digit or
    1e-3/fs, or equals ``i/fs`` in single precision (log-format.md, "Lab data").
    """
    t, fs, n = np.asarray(trial.t, dtype=float), trial.fs, trial.n_dof
    if t.shape[0] < min_samples:
        raise TrialFormatError(f"{where}: {t.shape[0]} samples, fewer than one spectral "
                               f"segment ({min_samples})")
    needed = ("theta", "tau_h") if trial.perturbation_kind == "position" else SIGNALS
    for s in needed:
        if getattr(trial, s) is None:
            raise TrialFormatError(f"{where}: signal {s} missing")
    for s in trial.signals():
        arr = trial.signal(s)
        if arr.shape != (t.shape[0], n):
            raise TrialFormatError(f"{where}: signal {s} has shape {arr.shape}, expected "
                                   f"({t.shape[0]}, {n})")
        bad = ~np.isfinite(arr)
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise TrialFormatError(f"{where}: non-finite or blank value {_num(arr[row, col])} in "
                                   f"column '{s}[{col + 1}]' at data row {row + 1}")
    _check_time(t, fs, where)
    _check_perturbation(trial, where)


def _check_time(t: np.ndarray, fs: float, where) -> None:
    """Refuse a ``t`` that is not ``arange(N) / fs`` at its printed resolution.

    Each value may be off ``n/fs`` by half its own last printed digit (ties and float
    noise included: a relative slack of 1e-6), by 1e-3/fs, or agree in single precision.
    The printed digit is judged per value (:func:`_printed_resolution`), so fixed decimals
    and significant digits (``%.7g``, whose resolution grows with magnitude) both read.
    """
    bad = ~np.isfinite(t)
    if bad.any():
        raise TrialFormatError(f"{where}: non-finite or blank value in column 't' at data row "
                               f"{int(np.argmax(bad)) + 1}")
    if abs(t[0]) > 0.5 / fs:
        raise TrialFormatError(f"{where}: column 't' must start at 0, starts at "
                               f"{_num(t[0])}")
    grid = np.arange(t.size) / fs
    err = np.abs(t - grid)
    off = err > 1e-3 / fs * (1 + 1e-6)
    if off.any():
        off &= t.astype(np.float32) != grid.astype(np.float32)
    if not off.any():
        return
    res = _printed_resolution(t)
    off &= err > 0.5 * res * (1 + 1e-6) + 4 * np.spacing(np.abs(t))
    if not off.any():
        return
    _time_fault(t, grid, res, off, fs, where)


def _time_fault(t, grid, res, off, fs, where) -> None:
    """Raise the message that says what is wrong with a refused ``t``."""
    dt = np.diff(t)
    step = (t[-1] - t[0]) / (t.size - 1)
    # a repeated value is a fault only where the printing is finer than the step
    back = (dt < 0) | ((dt == 0) & (res[1:] <= abs(step) * (1 + 1e-6)))
    if back.any():
        row = int(np.argmax(back)) + 2
        raise TrialFormatError(f"{where}: column 't' is not increasing at data row {row} "
                               f"(t={_num(t[row - 1])} after {_num(t[row - 2])})")
    if abs(step * fs - 1) > 1e-3:
        raise TrialFormatError(f"{where}: key 'fs'={_num(fs)} disagrees with column 't' "
                               f"(mean step {_num(step)} s, i.e. fs={_num(1.0 / step)})")
    row = int(np.argmax(off)) + 1
    raise TrialFormatError(f"{where}: column 't' is not uniform at data row {row} "
                           f"(t={_num(t[row - 1])}, expected {_num(grid[row - 1])} at "
                           f"fs={_num(fs)}; allowed off by half the printed digit, "
                           f"{_num(0.5 * res[row - 1])})")


def _num(x) -> str:
    """A number as plain text (no numpy repr)."""
    return repr(float(x))


def _printed_resolution(t: np.ndarray) -> np.ndarray:
    """Last printed digit [s] of each ``t``, shape (N,).

    Read from the values themselves as the coarser of two readings: fixed decimals and
    significant digits, so ``%.6f``, ``%.7g`` and ``%.5e`` all read. Each value is judged
    at its own decimals and digits, or at those of the file (99th percentile over the
    values) where it shows fewer: a printed ``30.000`` comes back as ``30.0`` and must not
    get a coarser digit, while one value typed with more decimals does not make the rest
    of the file stricter.
    """
    a = np.abs(t)
    ulp = 4 * np.spacing(np.maximum(a, 1e-300))
    dec = np.full(t.shape, 17)
    todo = np.ones(t.shape, dtype=bool)
    for d in range(17):
        idx = np.nonzero(todo)[0]
        if not idx.size:
            break
        hit = np.abs(np.round(t[idx], d) - t[idx]) <= ulp[idx]
        dec[idx[hit]] = d
        todo[idx[hit]] = False
    nz = a > 0
    mag = np.zeros(t.shape)
    mag[nz] = np.floor(np.log10(a[nz]))
    sig = np.where(nz, dec + mag + 1, 1)
    file_dec = np.quantile(dec, 0.99, method="higher")
    file_sig = np.quantile(sig, 0.99, method="higher")
    by_decimals = 10.0 ** -np.maximum(dec, file_dec)
    by_digits = 10.0 ** (mag - np.maximum(sig, file_sig) + 1)
    return np.maximum(by_decimals, by_digits)


def _check_perturbation(trial: Trial, where) -> None:
    k = trial.perturbed_dof
    if k is None:
        return
    if trial.perturbation_kind == "position":
        name = "theta_ref" if trial.theta_ref is not None else "theta"
    else:
        name = "tau_delta"
    if not np.any(trial.signal(name)[:, k - 1]):
        hint = (" (a position perturbation? declare \"perturbation\": {\"kind\": "
                "\"position\"} and give theta_ref[k] if it was recorded)"
                if name == "tau_delta" else "")
        raise TrialFormatError(f"{where}: column '{name}[{k}]' is identically zero for "
                               f"the perturbed joint {k}{hint}")
