"""Resuming a killed diagnosis: every finished task's result, kept in the out folder.

The store lives in ``OUT/.diagnosis-cache/KEY/``, KEY a SHA-256 of everything the result
depends on (the measured numbers and metadata of every trial, the options, the plant file
and its size and time, the RK4 step, :data:`CACHE_VERSION`). Each task's result is one
file named by a hash of the task (function and arguments), written atomically as soon as
the task finishes: a re-run with the same inputs and options runs only the missing
tasks; other inputs or options get another KEY and start afresh. Nothing is unpickled:
fits are JSON, simulated trials ``.npz`` read with ``allow_pickle=False``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import shutil
import zipfile
from pathlib import Path

import numpy as np

import trialformat as tf

from ..fitting import EffectFit

#: bump when the meaning of a stored result changes
CACHE_VERSION = 2
CACHE_DIR = ".diagnosis-cache"
_MISSING = object()


def run_key(trials, config, plant, rk4_step) -> str:
    """SHA-256 (hex) of the inputs and options of a diagnosis."""
    h = hashlib.sha256()
    h.update(f"v{CACHE_VERSION}".encode())
    for t in trials:
        h.update(t.name.encode())
        h.update(json.dumps(t.meta, sort_keys=True, default=str).encode())
        for s in ("t", "tau_delta", "theta", "tau_h", "tau_m", "theta_ref"):
            x = getattr(t, s, None)
            h.update(s.encode())
            if x is not None:
                h.update(np.ascontiguousarray(x, dtype=float).tobytes())
    h.update(json.dumps(config.to_dict(), sort_keys=True, default=str).encode())
    plant_ref = getattr(plant, "path", plant)
    if plant_ref is not None:
        p = Path(str(plant_ref))
        st = p.stat() if p.is_file() else None
        h.update(f"{p.resolve()}:{st and (st.st_size, st.st_mtime_ns)}".encode())
    h.update(repr(rk4_step).encode())
    from orchestrator.trial import env_plant_parameters
    values = env_plant_parameters()  # --plant-parameter: other parameters, other runs
    if values:
        h.update(json.dumps(values, sort_keys=True).encode())
    return h.hexdigest()


def _arg_json(value):
    if isinstance(value, EffectFit):
        return {"fit": dataclasses.asdict(value)}
    if isinstance(value, dict) and value and all(hasattr(v, "sigma") for v in value.values()):
        return "norms"  # fixed by the nominal runs, themselves fixed by the run key
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return str(value)


def task_key(fn, args) -> str:
    text = json.dumps([fn.__name__, list(args)], sort_keys=True, default=_arg_json)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


class ResumeStore:
    """The finished tasks of one diagnosis (see the module docstring).

    Parameters
    ----------
    out_dir : path
        The report folder (the store is ``out_dir/.diagnosis-cache/key``).
    key : str
        :func:`run_key` of the run.
    """

    def __init__(self, out_dir, key: str):
        self.root = Path(out_dir) / CACHE_DIR
        self.folder = self.root / key
        self.n_reused = 0
        self.n_stored = 0
        #: cache entries found unreadable (a truncated .npz, a cut JSON) and recomputed
        self.n_corrupt = 0

    def map(self, runner, fn, arg_tuples, desc):
        keys = [task_key(fn, a) for a in arg_tuples]
        results = [self._load(k) for k in keys]
        todo = [i for i, v in enumerate(results) if v is _MISSING]
        self.n_reused += len(results) - len(todo)
        if todo:
            def done(j, value):
                self._save(keys[todo[j]], value)
            new = runner.map(fn, [arg_tuples[i] for i in todo], desc=desc, done=done)
            for i, value in zip(todo, new):
                results[i] = value
        return results

    # ------------------------------------------------------------------ JSON results
    def _json_path(self, key) -> Path:
        text = json.dumps(list(key) if isinstance(key, tuple) else key, sort_keys=True)
        return self.folder / f"r-{hashlib.sha256(text.encode()).hexdigest()[:32]}.json"

    def get_json(self, key):
        """The JSON result stored under ``key`` (a string or tuple of strings), or None
        (none stored, or unreadable: a disk that filled up)."""
        path = self._json_path(key)
        try:
            return json.loads(path.read_text()) if path.is_file() else None
        except (OSError, ValueError):
            return None

    def put_json(self, key, value) -> None:
        """Store ``value`` (JSON-able) under ``key``, atomically; a full disk only loses
        the resumability."""
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            text = json.dumps(value, default=_json_default)
            tf.atomic_write(self._json_path(key), lambda fh: fh.write(text.encode()))
            self.n_stored += 1
        except OSError:
            pass

    # ------------------------------------------------------------------ files
    def _save(self, key, value) -> None:
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            if isinstance(value, tf.Trial) or value is None:
                buf = io.BytesIO()
                arrays = {} if value is None else {
                    s: np.asarray(getattr(value, s)) for s in
                    ("t", "tau_delta", "theta", "tau_h", "tau_m", "theta_ref")
                    if getattr(value, s, None) is not None}
                meta = "null" if value is None else json.dumps(
                    {"meta": value.meta, "name": value.name}, default=_json_default)
                np.savez(buf, __meta__=np.array(meta), **arrays)
                tf.atomic_write(self.folder / f"{key}.npz", lambda fh: fh.write(buf.getvalue()))
            elif isinstance(value, EffectFit):
                text = json.dumps(dataclasses.asdict(value), default=_json_default)
                tf.atomic_write(self.folder / f"{key}.json", lambda fh: fh.write(text.encode()))
            else:
                return
            self.n_stored += 1
        except OSError:
            pass  # a full disk: the run goes on, only its resumability is lost

    def _load(self, key):
        js, npz = self.folder / f"{key}.json", self.folder / f"{key}.npz"
        try:
            if js.is_file():
                d = json.loads(js.read_text())
                d["effects"] = tuple(d["effects"])
                return EffectFit(**{k: _float(v) if k in ("calibration_gap", "held_out_gap",
                                                          "objective") else v
                                    for k, v in d.items()})
            if npz.is_file():
                with np.load(npz, allow_pickle=False) as z:
                    meta = json.loads(str(z["__meta__"]))
                    if meta is None:
                        return None
                    arrays = {k: z[k] for k in z.files if k != "__meta__"}
                return tf.Trial(meta=meta["meta"], name=meta["name"], **arrays)
        except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
            # unreadable (a disk that filled up, a truncated .npz): run the task again
            self.n_corrupt += 1
            return _MISSING
        return _MISSING

    def keep_only_current(self) -> None:
        """Remove the stores of other keys (earlier inputs or options)."""
        if self.root.is_dir():
            for p in self.root.iterdir():
                if p != self.folder:
                    shutil.rmtree(p, ignore_errors=True)


def _float(v):
    return float(v) if isinstance(v, str) else v


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)
