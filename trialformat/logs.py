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
import re
import shutil
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import reference as ref
from . import csvtable
from .errors import OutputError, TrialFormatError

FORMAT = "arm-impedance-trial/1"
SIGNALS = ("tau_delta", "theta", "tau_h", "tau_m")
MIN_SAMPLES = 8192  # one spectral segment (Table IV)
#: Most joints a trial may declare (n_dof): a limit far above any arm, refused up front
#: instead of exhausting memory on the metadata's per-joint arrays.
MAX_DOF = 64
#: File endings of a trial, longest first (a name keeps its other dots: S1.dof1.csv is
#: the trial S1.dof1).
TRIAL_SUFFIXES = (".csv.gz", ".csv", ".json", ".mat")
#: Marker file of a report folder written by this project: only such a folder (or an
#: empty one) is replaced by a new report.
REPORT_MARK = ".armimp-report.json"
REPORT_FORMAT = "arm-impedance-report/1"


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
        "posture_deg": ref.reference("3dof" if n_dof == 3 else "2dof")["human_arm"][
            "posture_deg"],
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
    stem = trial_stem(stem)
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
    csv_path, json_path = with_ending(stem, ".csv"), with_ending(stem, ".json")
    atomic_write(csv_path, lambda fh: fh.write(csvtable.to_text(header, table)))
    atomic_write(json_path, lambda fh: fh.write(json.dumps(meta, indent=2).encode()))
    return csv_path


def atomic_write(path: str | os.PathLike, write) -> None:
    """Write through a temporary file and rename; ``write(fh)`` gets a binary handle.

    The file ends with mode 0666 masked by the process umask.
    """
    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except PermissionError:  # named as the user knows it, not by the temporary name
        raise OutputError(f"{path}: cannot write in {path.parent} (permission denied): give "
                          f"a path in a writable folder") from None
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


def trial_stem(path: str | os.PathLike) -> Path:
    """The trial a path names: ``path`` without one ending of :data:`TRIAL_SUFFIXES`
    (``S1.dof1.csv`` -> ``S1.dof1``, ``trial.csv.gz`` -> ``trial``, ``level_0.5`` ->
    ``level_0.5``); other dots are part of the name."""
    path = Path(path)
    lower = path.name.lower()
    for ending in TRIAL_SUFFIXES:
        if lower.endswith(ending) and len(lower) > len(ending):
            return path.with_name(path.name[:-len(ending)])
    return path


def with_ending(stem: str | os.PathLike, ending: str) -> Path:
    """``stem`` with ``ending`` appended (never cut at a dot of the name, unlike
    ``Path.with_suffix``)."""
    stem = Path(stem)
    return stem.with_name(stem.name + ending)


def check_out_parent(path: str | os.PathLike, option: str = "--out") -> None:
    """Refuse an output path below an existing file (``A/res.json/x.json`` where
    ``A/res.json`` is a file), before anything is written: the nearest existing ancestor
    of ``path`` must be a folder.

    Raises
    ------
    trialformat.errors.OutputError
        Naming ``option``, ``path`` and the file in the way.
    """
    path = Path(path)
    if path.is_dir() and read_only(path):
        raise OutputError(f"{option} {path}: the folder is read-only (mode "
                          f"{path.stat().st_mode & 0o777:o}); it is left as it is: make it "
                          f"writable (chmod u+w) or give another folder")
    for parent in path.parents:
        if parent.exists() or parent.is_symlink():
            if not parent.is_dir():
                what = "a file" if parent.exists() else "a link to nothing"
                raise OutputError(f"{option} {path}: {parent} is {what}, not a folder; give "
                                  f"a path in a folder (e.g. {parent.parent / path.name})")
            if read_only(parent):
                raise OutputError(f"{option} {path}: cannot write in {parent} (read-only, "
                                  f"mode {parent.stat().st_mode & 0o777:o}): give a path in "
                                  f"a writable folder")
            return


def read_only(folder: Path) -> bool:
    """True for a folder this process may not write in, or whose mode grants no write
    (a folder a user protected, refused even where the process could override it)."""
    try:
        mode = folder.stat().st_mode
    except OSError:
        return False
    return not os.access(folder, os.W_OK | os.X_OK) or not mode & 0o222


def simulated_trial(stem: str | os.PathLike) -> bool:
    """True when ``stem.json`` is the metadata of a trial this project simulated (this
    format, with its ``simulation`` block) and the data file beside it is the one that
    run wrote (its SHA-256 equals ``simulation.csv_sha256``, :func:`seal_simulated`), i.e.
    the output of an earlier simulate run. A JSON that only looks simulated (copied beside
    a lab CSV, or written before the seal existed) is not."""
    stem = trial_stem(stem)
    json_path = with_ending(stem, ".json")
    try:
        meta = json.loads(json_path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError, OSError):
        return False
    if not (isinstance(meta, dict) and isinstance(meta.get("simulation"), dict)
            and str(meta.get("format", "")).startswith(FORMAT.split("/")[0])):
        return False
    sealed = meta["simulation"].get("csv_sha256")
    data = [p for p in (with_ending(stem, ".csv"), with_ending(stem, ".csv.gz"))
            if p.exists()]
    if not data:
        return True  # the metadata alone: nothing of a lab's is at stake beyond it
    return isinstance(sealed, str) and all(_sha256(p) == sealed for p in data)


def _sha256(path: Path) -> str:
    import hashlib
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def seal_simulated(csv_path: str | os.PathLike) -> None:
    """Record the SHA-256 of a simulated trial's CSV in its JSON (``simulation.csv_sha256``)
    so that a later simulate run replaces it only while it is that file
    (:func:`simulated_trial`)."""
    csv_path = Path(csv_path)
    json_path = with_ending(trial_stem(csv_path), ".json")
    meta = json.loads(json_path.read_text(encoding="utf-8"))
    meta.setdefault("simulation", {})["csv_sha256"] = _sha256(csv_path)
    atomic_write(json_path, lambda fh: fh.write(json.dumps(meta, indent=2).encode()))


def check_trial_out(stem: str | os.PathLike, option: str = "--out", *,
                    force: bool = False) -> None:
    """Refuse to write a trial over files this project did not write.

    ``stem.csv``, ``stem.csv.gz``, ``stem.json`` and ``stem.mat`` that exist are replaced
    only when ``stem.json`` is a simulated trial of this project (:func:`simulated_trial`)
    or ``force``; a folder of that name, or a parent that is a file, is always refused.

    Raises
    ------
    trialformat.errors.OutputError
        Naming ``option`` and the file at stake, and what would work.
    """
    stem = trial_stem(stem)
    check_out_parent(stem, option)
    files = [with_ending(stem, e) for e in (".csv", ".csv.gz", ".json", ".mat")]
    for f in files:
        if f.is_dir():
            raise OutputError(f"{option} {stem}: {f} is a folder; give another trial name")
    present = [f for f in files if f.exists()]
    if present and not force and not simulated_trial(stem):
        raise OutputError(f"{option} {stem}: {present[0]} exists and is not a trial this "
                          f"project simulated; it is left as it is: give a new name, or "
                          f"--force to replace it")


def check_report_out(out: str | os.PathLike, inputs=(), kinds=None) -> None:
    """Refuse a report folder ``out`` that would replace what this project did not write.

    Refused: an existing file; a folder that is, or holds, one of ``inputs`` (files or
    folders, compared after resolving links); a non-empty folder without the marker
    :data:`REPORT_MARK` of an earlier report (or, for reports written before the marker,
    their ``report.json`` / ``results.json`` index). A missing or empty folder, or an
    earlier report, is accepted.

    Raises
    ------
    trialformat.errors.OutputError
        Naming ``out`` and the input or file at stake, and what would work.
    """
    out = Path(out)
    check_out_parent(out, "--out")
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out}: is an existing file; a report is a folder: give a "
                          f"new folder name (e.g. {out.name}_report)")
    target = out.resolve()
    for source in inputs:
        source = Path(source)
        resolved = source.resolve()
        if resolved == target or target in resolved.parents:
            raise OutputError(f"--out {out}: is or holds the input {source}; a report "
                              f"replaces its folder, so it must not hold the trials: give "
                              f"a folder outside the inputs (e.g. {out.name}_report)")
    mark = out / REPORT_MARK
    if kinds is not None and mark.is_file():
        try:
            kind = json.loads(mark.read_text(encoding="utf-8")).get("kind")
        except (ValueError, UnicodeDecodeError, OSError, AttributeError):
            kind = None  # unreadable: judged as an unmarked folder below
        if kind is not None and kind not in kinds:  # a marker without kind: any report
            raise OutputError(f"--out {out}: holds a {kind} report of this "
                              f"project, not a {' or '.join(kinds)} report; it is left as "
                              f"it is: give a new folder (e.g. {out.name}_{kinds[0]})")
    if out.is_dir() and not mark.is_file() and not _earlier_report(out) \
            and any(out.iterdir()):
        raise OutputError(f"--out {out}: folder is not empty and is not a report of this "
                          f"project (no {REPORT_MARK}); it is left as it is: give a new or "
                          f"empty folder")


def _earlier_report(out: Path) -> bool:
    """A report written before reports were marked: its own index file (``report.json`` of
    the paper kind, ``results.json`` of the lab kind) with the keys this project writes."""
    for name, keys in (("report.json", {"variant_in_figures", "rows", "summary"}),
                       ("results.json", {"options", "results"})):
        path = out / name
        if path.is_file():
            try:
                doc = json.loads(path.read_text(encoding="utf-8"))
            except (ValueError, UnicodeDecodeError, OSError):
                continue
            if isinstance(doc, dict) and keys <= set(doc):
                return True
    return False


def replace_dir(tmp: str | os.PathLike, out: str | os.PathLike, kind: str = "report") -> None:
    """Put the finished folder ``tmp`` in place of ``out`` (a report written whole or not
    at all): the old folder is moved aside first, then removed.

    ``tmp`` gets the marker :data:`REPORT_MARK` (``kind`` recorded in it); ``out`` is
    replaced only when it is missing, empty or marked (:func:`check_report_out`), so a
    report never deletes a folder it did not write.
    """
    tmp, out = Path(tmp), Path(out)
    check_report_out(out)
    mark = json.dumps({"format": REPORT_FORMAT, "kind": kind}).encode()
    atomic_write(tmp / REPORT_MARK, lambda fh: fh.write(mark))
    if out.is_dir() and not any(out.iterdir()):
        out.rmdir()
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
    stem = trial_stem(stem)
    return with_ending(stem, ".json").is_file() and (
        with_ending(stem, ".csv").is_file() or with_ending(stem, ".csv.gz").is_file())


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
    from .matlab import read_trial_mat, split_variable
    path = mat_of_stem(path)
    if split_variable(path)[0].suffix.lower() == ".mat":
        return read_trial_mat(path, min_samples=min_samples)
    stem = trial_stem(path)
    json_path = with_ending(stem, ".json")
    csv_path = _data_file(Path(path), stem)
    if not (Path(path).exists() or csv_path.exists() or json_path.exists()):
        raise TrialFormatError(f"{path}: no such file or folder")
    meta, filled = _read_metadata(json_path)
    if not csv_path.is_file():
        raise TrialFormatError(f"{csv_path}: data file missing")
    header, delimiter = csvtable.read_header(csv_path)
    try:
        header = _rename_channels(header, meta, json_path, csv_path)
        header, header_units = _header_units(header)
        arrays = _columns(csv_path, header, delimiter, meta, filled)
    except TrialFormatError as exc:
        raise with_key_hints(exc, meta, filled, json_path) from None
    return finish_trial(meta, arrays, stem.name, filled, csv_path, min_samples=min_samples,
                        units=header_units)


def _header_units(header: list[str]) -> tuple[list[str], dict]:
    """Column names with a stated unit split off (``theta[1] (deg)`` -> ``theta[1]``,
    trialformat.units), and ``{column: unit}`` of those that state one."""
    from .units import split_header
    names, units = [], {}
    for h in header:
        name, unit = split_header(h)
        names.append(name)
        if unit is not None:
            units[name] = unit
    return names, units


def mat_of_stem(path: str | os.PathLike) -> str | os.PathLike:
    """``NAME.mat`` for a stem ``NAME`` that names no file, CSV or JSON but a ``.mat``
    (``NAME:VAR`` too, for ``NAME.mat:VAR``); else ``path`` unchanged. CSV trials are named
    by their stem, so a ``.mat`` is too."""
    text = str(path)
    if Path(text).exists() or text.lower().endswith(".mat") or ".mat:" in text.lower():
        return path
    head, sep, var = text.rpartition(":")
    if sep and head and var and "/" not in var and "\\" not in var \
            and Path(head + ".mat").is_file() and not Path(head).exists():
        return f"{head}.mat:{var}"
    stem = Path(text)
    if any(with_ending(stem, e).exists() for e in (".csv", ".csv.gz", ".json")):
        return path
    mat = with_ending(stem, ".mat")
    return mat if mat.is_file() else path


def _data_file(path: Path, stem: Path) -> Path:
    """The CSV of a trial named by ``path``: the file itself, else ``stem.csv`` or
    ``stem.csv.gz`` (both present: refused as ambiguous)."""
    if path.name.lower().endswith((".csv", ".csv.gz")):
        return path
    plain, gz = with_ending(stem, ".csv"), with_ending(stem, ".csv.gz")
    if plain.is_file() and gz.is_file():
        raise TrialFormatError(f"{stem}: trial present both as {plain.name} and {gz.name}; "
                               f"keep one or name the file")
    return gz if gz.is_file() else plain


def folder_trials(folder: str | os.PathLike) -> list[Path]:
    """The trial files of a folder: ``NAME.csv``, ``NAME.csv.gz`` and ``NAME.mat``, sorted
    per kind. A name present in two forms is refused as ambiguous; an empty list when the
    folder holds none."""
    folder = Path(folder)
    found = {}
    for pattern in ("*.csv", "*.csv.gz", "*.mat"):
        for p in sorted(folder.glob(pattern)):
            found.setdefault(trial_stem(p).name, []).append(p)
    both = sorted(name for name, ps in found.items() if len(ps) > 1)
    if both:
        forms = "; ".join(f"{name} both as " + " and ".join(
            p.name[len(name):] for p in found[name]) for name in both)
        raise TrialFormatError(f"{folder}: trial(s) present in more than one form: {forms}; "
                               f"keep one")
    return [ps[0] for ps in found.values()]


def finish_trial(meta: dict, arrays: dict, name: str, filled: list, where, *,
                 min_samples: int = MIN_SAMPLES, units: dict | None = None,
                 units_by: str = "column header") -> Trial:
    """Build, check and convert a trial from its arrays (shared by the CSV and .mat readers).

    ``units`` ({column: unit}, from the CSV headers or the nldat ``chanUnits``; said to be
    stated by ``units_by``) and the metadata's ``units`` key are applied first
    (trialformat.units: converted to SI, recorded in ``units_read``)."""
    from .units import apply_units
    try:
        apply_units(meta, arrays, units or {}, where, by=units_by)
        trial = Trial(meta=meta, name=name, filled_defaults=filled, **arrays)
        check_trial(trial, where, min_samples=min_samples)
    except TrialFormatError as exc:
        raise with_key_hints(exc, meta, filled, where) from None
    exact = np.arange(trial.n_samples) / trial.fs
    if not np.array_equal(trial.t, exact):
        trial.t_stored = trial.t
    trial.t = exact
    for s, value in _convention(meta, trial).items():
        setattr(trial, s, value)
    if filled:
        source = ("the reference configuration" if trial.n_dof in REFERENCE_JOINTS else
                  f"the documented {trial.n_dof}-joint defaults (log-format.md)")
        warnings.warn(f"{Path(str(where)).name}: metadata keys absent, filled from "
                      f"{source}: {', '.join(filled)}", stacklevel=3)
    return trial


def read_trials(source, *, min_samples: int = MIN_SAMPLES) -> list[Trial]:
    """Read every trial of a folder (``*.csv`` and ``*.mat``) or of a list of paths.

    A stem present in two forms (``NAME.csv``, ``NAME.csv.gz``, ``NAME.mat``) is refused
    as ambiguous. A ``.mat`` holding a struct array of trials gives one trial per element
    (:func:`trialformat.matlab.read_trials_mat`), a ``.mat`` of NLID ``nldat`` objects one
    trial per object (trialformat.nlid); names that repeat across files become ``FILE:VAR``.
    """
    if isinstance(source, (str, os.PathLike)) and Path(source).is_dir():
        paths = folder_trials(source)
        if not paths:
            raise TrialFormatError(f"{source}: folder holds no trial (no NAME.csv, "
                                   f"NAME.csv.gz or NAME.mat)")
    elif isinstance(source, (str, os.PathLike)):
        paths = [Path(source)]
    else:
        paths = [Path(p) for p in source]
        if not paths:
            raise TrialFormatError("no trial given (empty list of paths)")
    from .matlab import read_trials_mat, split_variable
    trials, origin = [], []
    for p in map(mat_of_stem, paths):
        if split_variable(p)[0].suffix.lower() == ".mat":
            got = read_trials_mat(p, min_samples=min_samples)
        else:
            got = [read_trial(p, min_samples=min_samples)]
        trials += got
        origin += [split_variable(p)[0].stem] * len(got)
    names = [t.name for t in trials]
    for t, stem in zip(trials, origin):
        if names.count(t.name) > 1 and t.name != stem:
            t.name = f"{stem}:{t.name}"
    return trials


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
    _fold_torque_sign(meta, json_path)
    return meta, complete_metadata(meta, json_path)


def _fold_torque_sign(meta: dict, where) -> None:
    """A top-level ``"torque_sign"`` (as an nldat sidecar writes it) is
    ``sensors.torque_sign``, never ignored; the two disagreeing are refused."""
    if "torque_sign" not in meta:
        return
    value = meta.pop("torque_sign")
    sensors = meta.setdefault("sensors", {})
    if not isinstance(sensors, dict):
        return  # complete_metadata names the malformed 'sensors'
    if "torque_sign" in sensors and sensors["torque_sign"] != value:
        raise TrialFormatError(f"{where}: key 'torque_sign' ({value!r}) and key "
                               f"'sensors.torque_sign' ({sensors['torque_sign']!r}) disagree; "
                               f"state the sign once, as 'sensors.torque_sign'")
    sensors["torque_sign"] = value


_TARGET_COLUMN = re.compile(r"^(?:t|(?:" + "|".join(SIGNALS + ("theta_ref",))
                            + r")\[(\d+)\])$")
_UNIT_TAIL = re.compile(r"^(.*?)\s*([\(\[][^\)\]]*[\)\]])\s*$")


def _rename_channels(header: list[str], meta: dict, json_path: Path, csv_path: Path
                     ) -> list[str]:
    """The header with the metadata's ``"channels"`` mapping applied (``{"pos": "theta[1]",
    "ang (deg)": ...}``, a column's name, with or without its unit, to ``t``,
    ``theta[j]``, ``tau_h[j]``, ``theta_ref[j]``, ``tau_delta[j]``, ``tau_m[j]``, or null:
    left as an extra column); the mapping is removed from the metadata and recorded in
    ``channels_read``.

    Raises
    ------
    TrialFormatError
        ``channels`` not an object, a target that is not a column of the format, or a
        name that is not a column of the CSV (naming the key and the header).
    """
    channels = meta.pop("channels", None)
    meta.pop("channels_read", None)  # an earlier reader's record (the file is renamed)
    if channels is None:
        return header
    if not isinstance(channels, dict):
        raise TrialFormatError(f"{json_path}: key 'channels' must be an object mapping a "
                               f"column of {csv_path.name} to its name in the format, e.g. "
                               f'{{"pos": "theta[1]"}}, got {_short(channels)}')
    for name, target in channels.items():
        if target is not None and not (isinstance(target, str)
                                       and _TARGET_COLUMN.match(target)):
            raise TrialFormatError(
                f"{json_path}: key 'channels.{name}' must be one of t, "
                f"{', '.join(s + '[j]' for s in SIGNALS + ('theta_ref',))} or null, got "
                f"{_short(target)}")
    out, used = [], set()
    for h in header:
        m = _UNIT_TAIL.match(h)
        if h in channels:
            key, tail = h, ""
        elif m and m.group(1) in channels:
            key, tail = m.group(1), " " + m.group(2)
        else:
            out.append(h)
            continue
        used.add(key)
        out.append(channels[key] + tail if channels[key] is not None
                   else h + " #ignored" if _TARGET_COLUMN.match(key) else h)
    unknown = [k for k in channels if k not in used]
    if unknown:
        raise TrialFormatError(f"{json_path}: key 'channels' names {unknown}, not columns "
                               f"of {csv_path.name} (header: "
                               f"{csvtable.printable(', '.join(header))[:300]})")
    meta["channels_read"] = {k: v for k, v in channels.items()}
    return out


_CHOICES = {("perturbation", "kind"): ("torque", "position"),
            ("sensors", "torque_sampling"): ("left_limit", "instantaneous"),
            ("sensors", "torque_sign"): (1, -1),
            (None, "angles"): ("absolute",)}
_CHOICE_HINTS = {"angles": " (absent: theta is the deviation from posture_deg)"}


#: top-level metadata keys this project reads or writes (log-format.md); any other key is
#: an extra key (allowed), named in a note only when it looks like a misspelling of these
KNOWN_KEYS = ("format", "fs", "n_dof", "perturbed_dof", "posture_deg", "perturbation",
              "controller", "sensors", "robot", "friction", "source", "condition", "angles",
              "units", "units_read", "channels", "channels_read", "torque_sign",
              "scheduling", "auxiliary", "simulation")
#: keys of the nested objects besides those of the defaults (default_metadata)
_KNOWN_SUBKEYS = {"perturbation": ("kind", "signal", "switch_s", "level", "peak"),
                  "sensors": ("torque_sign", "torque_sampling"),
                  "controller": ("tuning", "time_delay_estimation")}


def _known_subkeys() -> dict:
    out = {k: set(v) for k, v in _KNOWN_SUBKEYS.items()}
    for n in (1, 2, 3):
        for key, value in default_metadata(n).items():
            if isinstance(value, dict):
                out.setdefault(key, set()).update(value)
    return {k: sorted(v) for k, v in out.items()}


def _close_key(key: str, known) -> str | None:
    """The known key ``key`` is probably a misspelling of (the same but for case, else the
    closest by difflib at ratio >= 0.75), or None."""
    import difflib
    if not isinstance(key, str) or key in known:
        return None
    for k in known:
        if k.lower() == key.lower():
            return k
    close = difflib.get_close_matches(key, list(known), n=1, cutoff=0.75)
    return close[0] if close else None


def misspelled_keys(meta: dict) -> list[tuple[str, str]]:
    """``(key, known key)`` pairs, dotted for nested ones (``perturbation.levle``), of the
    metadata's unknown keys that look like a misspelling of a known one: ``"perturbaton"``,
    ``"sensor"``, ``"Fs"`` (for ``fs``). Extra keys far from every known one are not named."""
    pairs = []
    for key in meta:
        right = _close_key(key, KNOWN_KEYS)
        if right is not None:
            pairs.append((key, right))
    for group, subs in _known_subkeys().items():
        holder = meta.get(group)
        if isinstance(holder, dict):
            for key in holder:
                right = _close_key(key, subs)
                if right is not None:
                    pairs.append((f"{group}.{key}", f"{group}.{right}"))
    return pairs


def with_key_hints(exc: TrialFormatError, meta: dict, filled, where) -> TrialFormatError:
    """``exc`` with a note for each misspelled key whose intended key was absent (filled
    from the defaults): the refusal may be caused by the default, not by the data."""
    said = [(w, r) for w, r in misspelled_keys(meta) if r in (filled or ())]
    if not said:
        return exc
    name = Path(str(where)).name
    if name.lower().endswith((".csv", ".csv.gz")):  # the keys are the JSON's
        name = with_ending(trial_stem(name), ".json").name
    notes = "; ".join(f"{name} has the unknown key '{w}': did you mean '{r}'? ('{r}' is "
                      f"absent, so its default was used)" for w, r in said)
    return exc.__class__(f"{exc}; {notes}")


def complete_metadata(meta: dict, where) -> list[str]:
    """Check the metadata keys and fill absent ones from the reference, in place.

    Integer keys written as integral floats (``2.0``, MATLAB doubles) become ints; 2.5 is
    refused. Shared by the readers of other containers (``.mat``). Returns the keys
    filled; raises TrialFormatError naming ``where``. An unknown key that looks like a
    misspelling of a known one (``"perturbaton"``) is named in a warning, and in a refusal
    that the default of the intended key may have caused.
    """
    name = Path(str(where)).name
    for wrong, right in misspelled_keys(meta):
        warnings.warn(f"{name}: unknown key '{wrong}': did you mean '{right}'?",
                      stacklevel=3)
    filled: list[str] = []
    try:
        _complete_metadata(meta, where, filled)
    except TrialFormatError as exc:
        raise with_key_hints(exc, meta, filled, where) from None
    return filled


def _complete_metadata(meta: dict, where, filled: list) -> None:
    _integral(meta, "n_dof", where, default=2)
    n_dof = meta.get("n_dof", 2)
    if not 1 <= n_dof <= MAX_DOF:
        raise TrialFormatError(f"{where}: key 'n_dof' must be an integer in 1..{MAX_DOF}, "
                               f"got {n_dof!r}")
    defaults = default_metadata(n_dof)
    for key, value in defaults.items():
        if isinstance(value, dict) and key in meta and not isinstance(meta[key], dict):
            raise TrialFormatError(f"{where}: key '{key}' must be a JSON object "
                                   f"({{...}}), got {_json_type(meta[key])} "
                                   f"{_short(meta[key])}")
    defaults["perturbed_dof"] = None
    if isinstance(meta.get("perturbation"), dict) and \
            meta["perturbation"].get("kind") == "position":
        del defaults["perturbation"]  # the torque perturbation's keys do not apply
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
    _check_posture(meta, n_dof, "posture_deg" in filled, where)
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
                      f"(this reader knows {FORMAT!r}); read as {FORMAT}", stacklevel=4)


def _check_posture(meta: dict, n_dof: int, filled: bool, where) -> None:
    """Refuse a ``posture_deg`` that is not n_dof finite numbers (degrees), naming it.

    With ``"angles": "absolute"`` the posture is what turns theta into a deviation, so
    it must be declared, not filled from the reference.
    """
    value = meta.get("posture_deg")
    if value is None or filled:
        if meta.get("angles") == "absolute":
            raise TrialFormatError(
                f"{where}: key 'posture_deg' is required with \"angles\": \"absolute\" "
                f"(the posture theta is measured about, {n_dof} number(s) in degrees, e.g. "
                f"[{', '.join(['0'] * n_dof)}]); or drop \"angles\" if theta is already "
                f"the deviation from the posture")
        if value is None:
            return
    flat = np.asarray(value, dtype=object).ravel()  # .mat readers give arrays
    ok = flat.size == n_dof and all(
        isinstance(v, (int, float, np.number)) and not isinstance(v, (bool, np.bool_))
        and np.isfinite(v) for v in flat)
    if not ok:
        raise TrialFormatError(
            f"{where}: key 'posture_deg' must be a list of {n_dof} finite number(s) in "
            f"degrees, one per joint (n_dof={n_dof}), got {_json_type(value)} "
            f"{_short(value)}")
    meta["posture_deg"] = [float(v) for v in flat]


def _json_type(value) -> str:
    """The JSON name of a value's type (null, boolean, number, string, array, object)."""
    if value is None:
        return "null"
    for kind, name in ((bool, "boolean"), ((int, float), "number"), (str, "string"),
                       (list, "array"), (dict, "object")):
        if isinstance(value, kind):
            return name
    return type(value).__name__


def _short(value, limit: int = 60) -> str:
    """A value as JSON text cut to ``limit`` characters (for messages)."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


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
        hint = ""
        kind = (meta.get("perturbation") or {}).get("kind")
        if kind != "position" and any(h.startswith("theta_ref[") for h in present) and \
                not any(c.startswith("theta_ref") for c in missing):
            hint = ("; the file has theta_ref: if the joint was perturbed by a position "
                    "servo, declare \"perturbation\": {\"kind\": \"position\"} (then t, "
                    "theta and tau_h suffice)")
        raise TrialFormatError(f"{csv_path}: missing columns for {said}: "
                               f"{', '.join(missing)} (header: "
                               f"{csvtable.printable(', '.join(header))[:500]}){hint}")
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
    gaps = [(f"{s}[{col + 1}]", trial.signal(s)[:, col]) for s in trial.signals()
            for col in range(n) if not np.all(np.isfinite(trial.signal(s)[:, col]))]
    if gaps:
        raise TrialFormatError(_gaps_message(gaps, t, fs, where, min_samples))
    _check_time(t, fs, where, "fs" in (trial.filled_defaults or []))
    _check_perturbation(trial, where)


#: gaps listed per column in the non-finite refusal (the rest counted)
MAX_GAPS_SAID = 4


def _rows(a: int, b: int) -> str:
    """Data rows a..b (1-based, inclusive) as text."""
    return f"row {a}" if a == b else f"rows {a}-{b}"


def _gaps_message(gaps, t, fs, where, min_samples) -> str:
    """The refusal of non-finite signal values: the first one (column and data row, as
    before), every column's runs of non-finite rows (data rows 1-based, with their time),
    the finite stretches left and what to do (cut the trial there; nothing is filled in).

    ``gaps``: [(column, values (N,))] of the columns holding a non-finite value."""
    n_rows = len(t)
    t_of = (lambda i: i / fs) if fs and np.isfinite(fs) and fs > 0 else (lambda i: float(t[i]))
    any_bad = np.zeros(n_rows, bool)
    first = None
    parts = []
    for name, x in gaps:
        bad = ~np.isfinite(x)
        any_bad |= bad
        row = int(np.argmax(bad))
        if first is None or row < first[1]:
            first = (name, row, x[row])
        m = np.concatenate([[False], bad, [False]]).astype(int)
        starts, stops = np.flatnonzero(np.diff(m) == 1), np.flatnonzero(np.diff(m) == -1)
        said = [f"{_rows(a + 1, b)} (t = {t_of(a):.6g}"
                + (f"-{t_of(b - 1):.6g}" if b - 1 > a else "") + " s)"
                for a, b in zip(starts[:MAX_GAPS_SAID], stops[:MAX_GAPS_SAID])]
        more = (f" and {len(starts) - MAX_GAPS_SAID} more gap(s)"
                if len(starts) > MAX_GAPS_SAID else "")
        parts.append(f"'{name}' {', '.join(said)}{more}: {int(bad.sum())} row(s)")
    name, row, value = first
    m = np.concatenate([[False], ~any_bad, [False]]).astype(int)
    starts, stops = np.flatnonzero(np.diff(m) == 1), np.flatnonzero(np.diff(m) == -1)
    if starts.size:
        k = int(np.argmax(stops - starts))
        a, b = int(starts[k]), int(stops[k])
        longest = (f"longest: {_rows(a + 1, b)}, {b - a} samples"
                   + (f", {(b - a) / fs:.4g} s" if fs and fs > 0 else ""))
        if b - a < min_samples:
            longest += (f", shorter than one spectral segment ({min_samples} samples): no "
                        f"cut is long enough, record the trial again")
    else:
        longest = "none: no row is finite in every column; record the trial again"
    return (f"{where}: non-finite or blank value {_num(value)} in column '{name}' at data "
            f"row {row + 1}; non-finite (NaN, blank or inf) values, rows counted from 1 at "
            f"the first data row: {'; '.join(parts)}. The estimate needs a finite value in "
            f"every row of the declared columns and fills no gap (nothing is interpolated "
            f"or dropped): cut the trial at the gaps and write each finite stretch as a "
            f"trial of its own, t restarting at 0 ({longest}), or repair the recording at "
            f"its source")


def _check_time(t: np.ndarray, fs: float, where, fs_filled: bool = False) -> None:
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
    _time_fault(t, grid, res, off, fs, where, fs_filled)


def _time_fault(t, grid, res, off, fs, where, fs_filled=False) -> None:
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
        key = (f"key 'fs' is absent and its reference value {_num(fs)} disagrees with "
               f"column 't'" if fs_filled else
               f"key 'fs'={_num(fs)} disagrees with column 't'")
        raise TrialFormatError(f"{where}: {key} (mean step {_num(step)} s, i.e. "
                               f"fs={_num(1.0 / step)}){'; declare fs' if fs_filled else ''}")
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
