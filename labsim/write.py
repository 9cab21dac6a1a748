"""Writing a :class:`labsim.Recording` the ways labs store recordings, and its truth.

``write(rec, folder, name, representation)`` writes ``NAME.csv`` (or ``.csv.gz``, or
``.mat``) with ``NAME.json``, in the layouts ``trialformat`` reads (docs/spec/log-format.md),
and ``NAME.truth.json`` beside them (never read by the diagnosis). Representations
(:data:`REPRESENTATIONS`; docs/labsim.md):

- ``"csv"``: trialformat's own writer (shortest round-trip text: bit-exact);
- ``"csv17"``: ``%.17g`` (bit-exact); ``"sigN"``: N significant digits (``%.Ng``,
  N = 4..17); ``"fixedD"``: D decimals (``%.Df``, D = 1..17), ``t`` too;
- ``"float32"``: values rounded to single precision, printed as the shortest text of
  each float32; ``"float32_9"``: the float32 printed with ``%.9g``;
- ``"pandas"``: ``DataFrame.to_csv`` with its defaults (shortest round-trip text);
- ``"semicolon"``, ``"tab"``: other separators (``.`` decimal mark); ``"quoted"``: the csv
  module's QUOTE_NONNUMERIC (quoted header); ``"excel"``: UTF-8 with a byte-order mark and
  CRLF line ends; ``"gzip"``: ``NAME.csv.gz``;
- ``"decimal_comma"``: ``;`` separator and ``,`` decimal mark (continental spreadsheets):
  refused by trialformat (log-format.md allows only ``.``), for testing that refusal;
- ``"mat5"``, ``"mat5_struct"``, ``"mat5_float32"``: MATLAB v5 by scipy.io (trialformat's
  ``write_trial_mat``; the metadata a JSON string or a struct; single precision);
  ``"mat73"``: MATLAB v7.3 (HDF5 via h5py, MATLAB's layout: 512-byte user block, arrays
  stored transposed, ``MATLAB_class`` attributes, the metadata a JSON char array).

The file stores tau_h with the spec's ``sensors.torque_sign`` (the metadata declares it).
A moving joint's scheduling variable is the extra column ``sv`` declared by the metadata
key ``scheduling`` in the CSV forms; a ``.mat`` holds it as the variable ``sv``, which
trialformat does not read, so its metadata does not declare it.
"""

from __future__ import annotations

import copy
import csv
import gzip
import io
import json
import re
from pathlib import Path

import numpy as np

import trialformat

REPRESENTATIONS = ("csv", "csv17", "sigN", "fixedD", "float32", "float32_9", "pandas",
                   "semicolon",
                   "tab", "quoted", "excel", "gzip", "decimal_comma", "mat5",
                   "mat5_struct", "mat5_float32", "mat73")


def _jsonable(value):
    """numpy arrays and scalars as lists and floats, recursively."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if np.isfinite(v) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def truth_document(rec, truth_fs: float | None = 100.0) -> dict:
    """The truth as written to ``NAME.truth.json``: the arrays at ``truth_fs`` (every
    fs/truth_fs-th sample; None: all samples), ``arrays_fs`` saying which."""
    truth = dict(rec.truth)
    arrays = truth.pop("arrays")
    fs = float(rec.spec.fs)
    step = 1 if truth_fs is None else max(1, int(round(fs / truth_fs)))
    truth["arrays_fs"] = fs / step
    # the torques of each part stay in memory (rec.truth); the file keeps their RMS
    truth["arrays"] = {k: np.asarray(v)[::step] for k, v in arrays.items()
                       if not k.startswith("tau_") or k == "tau_bg"}
    return _jsonable(truth)


def read_truth(path) -> dict:
    """``NAME.truth.json`` back, its arrays as numpy arrays."""
    doc = json.loads(Path(path).read_text())
    doc["arrays"] = {k: np.asarray(v, dtype=float) for k, v in doc.get("arrays", {}).items()}
    if "K_of_rho" in doc:
        doc["K_of_rho"] = {k: (np.asarray(v) if isinstance(v, list) else v)
                           for k, v in doc["K_of_rho"].items()}
    return doc


def _table(trial) -> tuple[list[str], np.ndarray]:
    """Header and the values as the file stores them (torque sign applied)."""
    n = trial.n_dof
    sign = (trial.meta.get("sensors") or {}).get("torque_sign", 1)
    header, cols = ["t"], [trial.t[:, None]]
    for s in trial.signals():
        v = trial.signal(s) * (sign if s == "tau_h" else 1)
        header += [f"{s}[{j}]" for j in range(1, n + 1)]
        cols.append(v)
    for k, v in trial.extra.items():
        header.append(k)
        cols.append(np.asarray(v, float)[:, None])
    return header, np.hstack(cols)


def _printf_csv(header, table, fmt: str, sep: str = ",", newline: str = "\n",
                decimal: str = ".") -> bytes:
    buf = io.StringIO()
    np.savetxt(buf, table, fmt=fmt, delimiter=sep, newline=newline)
    text = buf.getvalue()
    if decimal != ".":
        text = text.replace(".", decimal)
    return (sep.join(header) + newline + text).encode()


def _float32_text(table: np.ndarray, fmt: str | None) -> np.ndarray:
    """Each value as text of its float32 (shortest, or printed by ``fmt``)."""
    f32 = table.astype(np.float32)
    if fmt is None:
        return np.vectorize(lambda v: np.format_float_positional(v, unique=True, trim="-")
                            if 1e-4 <= abs(v) < 1e16 or v == 0 else
                            np.format_float_scientific(v, unique=True, trim="-"),
                            otypes=[object])(f32)
    return np.vectorize(lambda v: fmt % float(v), otypes=[object])(f32)


def _text_csv(header, cells: np.ndarray) -> bytes:
    rows = [",".join(header)] + [",".join(r) for r in cells.astype(str)]
    return ("\n".join(rows) + "\n").encode()


def _csv_bytes(rep: str, trial) -> bytes:
    header, table = _table(trial)
    if rep == "csv17":
        return _printf_csv(header, table, "%.17g")
    m = re.fullmatch(r"sig(\d+)", rep)
    if m and 4 <= int(m.group(1)) <= 17:
        return _printf_csv(header, table, f"%.{int(m.group(1))}g")
    m = re.fullmatch(r"fixed(\d+)", rep)
    if m and 1 <= int(m.group(1)) <= 17:
        return _printf_csv(header, table, f"%.{int(m.group(1))}f")
    if rep in ("float32", "float32_9"):
        cells = _float32_text(table, None if rep == "float32" else "%.9g")
        cells[:, 0] = [repr(float(v)) for v in table[:, 0]]  # t exact: only data single
        return _text_csv(header, cells)
    if rep == "pandas":
        import pandas as pd
        buf = io.StringIO()
        pd.DataFrame(table, columns=header).to_csv(buf, index=False)
        return buf.getvalue().encode()
    if rep == "semicolon":
        return _printf_csv(header, table, "%.17g", sep=";")
    if rep == "tab":
        return _printf_csv(header, table, "%.17g", sep="\t")
    if rep == "decimal_comma":
        return _printf_csv(header, table, "%.10g", sep=";", decimal=",")
    if rep == "excel":
        return b"\xef\xbb\xbf" + _printf_csv(header, table, "%.15g", newline="\r\n")
    if rep == "quoted":
        buf = io.StringIO()
        out = csv.writer(buf, quoting=csv.QUOTE_NONNUMERIC, lineterminator="\n")
        out.writerow(header)
        out.writerows(table.tolist())
        return buf.getvalue().encode()
    raise ValueError(f"unknown representation {rep!r}; known: {', '.join(REPRESENTATIONS)} "
                     f"(sigN: N = 4..17 significant digits, fixedD: D = 1..17 decimals)")


def _write_mat73(path: Path, trial) -> None:
    """MATLAB v7.3: HDF5 with a 512-byte user block holding MATLAB's header text."""
    import h5py
    header, table = _table(trial)
    n = trial.n_dof
    tmp = path.with_name(f".{path.name}.tmp")
    with h5py.File(tmp, "w", userblock_size=512) as fh:
        def put(name, arr):
            ds = fh.create_dataset(name, data=np.asarray(arr, float).T)  # column-major
            ds.attrs["MATLAB_class"] = np.bytes_("double")
        put("t", trial.t[:, None])
        col = 1
        for s in trial.signals():
            put(s, table[:, col:col + n])
            col += n
        for k in trial.extra:
            put(k, table[:, col:col + 1])
            col += 1
        text = json.dumps(trial.meta)
        ds = fh.create_dataset("meta", data=np.array([[ord(c) for c in text]],
                                                     dtype=np.uint16).T)
        ds.attrs["MATLAB_class"] = np.bytes_("char")
        ds.attrs["MATLAB_int_decode"] = np.int32(2)
    with open(tmp, "r+b") as fh:
        head = (b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created by: labsim "
                b"HDF5 schema 1.00 .").ljust(116, b" ")
        fh.write(head + b"\x00" * 8 + b"\x00\x02" + b"IM")
    tmp.replace(path)


def write(rec, folder, name: str, representation: str = "csv17", *,
          truth_fs: float | None = 100.0) -> dict:
    """Write the recording as ``folder/NAME.*`` and ``folder/NAME.truth.json``.

    Parameters
    ----------
    rec : labsim.Recording
    folder : path; created if absent
    name : str
        Trial name (dots kept: ``a.b`` writes ``a.b.csv``).
    representation : str
        One of :data:`REPRESENTATIONS` (module docstring).
    truth_fs : float or None
        Rate [Hz] of the truth's arrays in the file (None: fs).

    Returns
    -------
    dict with the paths written: ``data``, ``meta`` (None for ``.mat``, which holds it),
    ``truth``.

    Raises
    ------
    ValueError
        An unknown representation.
    """
    folder = Path(folder)
    trialformat.check_out_parent(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stem = folder / name
    trial = rec.trial
    rep = representation
    meta_bytes = json.dumps(trial.meta, indent=2).encode()
    paths = {"meta": stem.with_name(name + ".json")}
    if rep == "csv":
        paths["data"] = trialformat.write_trial(stem, trial)
    elif rep == "gzip":
        header, table = _table(trial)
        body = _printf_csv(header, table, "%.17g")
        paths["data"] = stem.with_name(name + ".csv.gz")
        trialformat.atomic_write(paths["data"], lambda fh: fh.write(
            gzip.compress(body, mtime=0)))
        trialformat.atomic_write(paths["meta"], lambda fh: fh.write(meta_bytes))
    elif rep.startswith("mat"):
        paths["meta"] = None
        if "scheduling" in trial.meta:  # trialformat reads no extra variable of a .mat
            trial = copy.copy(trial)
            trial.meta = {k: v for k, v in trial.meta.items() if k != "scheduling"}
        paths["data"] = stem.with_name(name + ".mat")
        if rep == "mat73":
            _write_mat73(paths["data"], trial)
        elif rep in ("mat5", "mat5_struct", "mat5_float32"):
            _write_mat5(paths["data"], trial, rep)
        else:
            raise ValueError(f"unknown representation {rep!r}; known: "
                             f"{', '.join(REPRESENTATIONS)}")
    else:
        body = _csv_bytes(rep, trial)
        paths["data"] = stem.with_name(name + ".csv")
        trialformat.atomic_write(paths["data"], lambda fh: fh.write(body))
        trialformat.atomic_write(paths["meta"], lambda fh: fh.write(meta_bytes))
    paths["truth"] = stem.with_name(name + ".truth.json")
    doc = json.dumps(truth_document(rec, truth_fs)).encode()
    trialformat.atomic_write(paths["truth"], lambda fh: fh.write(doc))
    return paths


def _write_mat5(path: Path, trial, rep: str) -> None:
    """MATLAB v5 by scipy.io in trialformat's layout (``t`` a column, each signal N x n,
    extra columns as vectors, ``meta`` JSON text or a struct)."""
    from scipy import io as sio
    from trialformat.matlab import _struct_safe
    header, table = _table(trial)
    n = trial.n_dof
    cast = np.float32 if rep == "mat5_float32" else float
    data, col = {"t": trial.t[:, None]}, 1
    for s in trial.signals():
        data[s] = table[:, col:col + n].astype(cast)
        col += n
    for k in trial.extra:
        data[k] = table[:, col:col + 1].astype(cast)
        col += 1
    data["meta"] = _struct_safe(trial.meta) if rep == "mat5_struct" else json.dumps(trial.meta)
    tmp = path.with_name(f".{path.stem}.tmp.mat")
    sio.savemat(tmp, data, do_compression=True)
    tmp.replace(path)


#: the representations a "mixed" set draws from (every one trialformat reads)
LAB_REPRESENTATIONS = ("csv17", "sig7", "sig6", "fixed6", "float32", "float32_9", "pandas",
                       "semicolon", "tab", "quoted", "excel", "gzip", "mat5", "mat5_struct",
                       "mat5_float32", "mat73")


def write_set(folder, kinds, count: int, *, seed: int = 0, representation: str = "csv17",
              n_dof: int = 1, duration_s: float = 60.0, fs: float = 1000.0,
              truth_fs: float | None = 100.0, blind: bool = True, progress=None) -> list:
    """A validation set: ``count`` recordings of each kind, drawn and written to ``folder``.

    Recording i of kind k is ``draw(k, default_rng([seed, index of k, i]))``. Names: with
    ``blind`` (default) ``rec_NNNN`` in an order shuffled by the seed, so that neither the
    name nor the position tells the kind; else ``KIND_NNN`` (``+`` written ``_``).
    ``representation="mixed"`` stores each in one of :data:`LAB_REPRESENTATIONS` drawn
    from the recording's generator. A manifest ``_labsim_set.truth.json`` (kinds, names,
    files, representations) is written last; like every ``*.truth.json`` it is not a
    trial. ``progress(i, total, name)`` is called after each recording. Returns the
    manifest's entries (in the order of kinds, then i).
    """
    from .draw import draw
    from .recording import simulate
    folder = Path(folder)
    kinds = [kinds] if isinstance(kinds, str) else list(kinds)
    entries, total, done = [], len(kinds) * int(count), 0
    order = np.random.default_rng([int(seed), 7919]).permutation(total)
    for ki, kind in enumerate(kinds):
        for i in range(int(count)):
            rng = np.random.default_rng([int(seed), ki, i])
            spec = draw(kind, rng, n_dof=n_dof, duration_s=duration_s, fs=fs)
            rep = representation
            if rep == "mixed":
                rep = LAB_REPRESENTATIONS[int(rng.integers(len(LAB_REPRESENTATIONS)))]
            name = (f"rec_{order[ki * int(count) + i]:04d}" if blind
                    else f"{kind.replace('+', '_')}_{i:03d}")
            paths = write(simulate(spec), folder, name, rep, truth_fs=truth_fs)
            entries.append({"name": name, "kind": kind, "representation": rep,
                            "data": paths["data"].name, "truth": paths["truth"].name})
            done += 1
            if progress is not None:
                progress(done, total, name)
    doc = {"format": "labsim-set/1", "seed": int(seed), "kinds": kinds, "count": int(count),
           "blind": bool(blind),
           "n_dof": n_dof, "duration_s": duration_s, "fs": fs, "recordings": entries}
    body = json.dumps(doc, indent=1).encode()
    trialformat.atomic_write(folder / "_labsim_set.truth.json", lambda fh: fh.write(body))
    return entries
