"""Recordings stored as NLID toolbox ``nldat`` objects in MATLAB ``.mat`` files.

The NLID toolbox of the Kearney lab (reklab/reklab_public) stores a recording as a MATLAB
class object ``nldat`` (opaque MCOS data, which ``scipy.io.loadmat`` cannot read). This
module reads them with mat-io (``matio.load_from_mat``, BSD-3). Each object's properties
used here:

``dataSet`` (N, channels)
    the samples, one column per channel;
``chanNames`` (1, channels) cell of char
    channel names, mapped to the trial's columns (below);
``domainIncr`` [s]
    the sampling interval: ``fs = 1 / domainIncr``;
``domainStart`` [s], ``comment``
    kept in the metadata's ``source``.

Channel mapping (default): a name ``pos``, ``pos1``, ``pos2``... (also ``angle``,
``theta``, ``position``) is the measured angle ``theta[j]`` of joint j (j the
trailing digits, 1 if none; in the units ``chanUnits`` states, converted to rad,
trialformat.units; rad when not stated); ``tq``, ``tq1``... (also ``torque``, ``tau``, ``trq``) is the
interaction torque ``tau_h[j]`` [N m]. The NLID lab's suffixes ``Pert``, ``Meas``,
``Measured``, ``Total``, ``Tot`` may follow the signal's name (``posPert1``, ``tqPert1``:
the position perturbation and the torque in response to it; case ignored, ``_`` allowed).
Any other name (``posRef1``, ``ang``) maps to nothing; two channels mapping to one column
are refused, naming the mapping to declare. A sidecar ``NAME.json`` beside ``NAME.mat`` may
declare the mapping and the conventions::

    {"channels": {"pos1": "theta[1]", "tq1": "tau_h[1]", "ref": "theta_ref[1]"},
     "torque_sign": -1,
     "meta": {"posture_deg": [0.0]},
     "scheduling": "sv",
     "variables": {"z_pf": {"torque_sign": -1, "meta": {"condition": "pf"}}}}

Auxiliary variables: an ``nldat`` object of one channel that maps to no column (the
scheduling variable ``sv`` of a moving-joint recording, an EMG) is not a recording. It is
attached to every recording of the file with the same number of samples, ``domainIncr`` and
``domainStart``, as an extra column named by the variable, and described in the metadata
key ``auxiliary`` (``{"sv": {"units": "rad", "description": CHANNEL NAME, "source":
"nldat variable 'sv' of FILE.mat"}}``; units from ``chanUnits``, brackets stripped,
``Default Units`` = not stated). One that cannot be attached (another length, rate or
start, a name taken by a channel) is skipped with a one-line warning naming it and why, and
recorded as ``{"skipped": REASON}``: it never sinks the file. ``scheduling`` (a name, or
``{"name": ..., "units": ...}``) declares the scheduling variable
(trialformat.scheduling); without it, a variable named ``sv`` or whose channel name says
"scheduling" is taken by default, with a note.

``channels`` maps a channel name to ``theta[j]``, ``tau_h[j]``, ``theta_ref[j]``,
``tau_delta[j]``, ``tau_m[j]`` or ``null`` (ignored); ``torque_sign`` is
``sensors.torque_sign`` of log-format.md (-1: the file's torque has the opposite sign);
``meta`` is merged into every trial's metadata; ``variables`` holds the same keys for one
object; ``"sensors": {"torque_sign": -1}`` at the top, as in a trial's metadata, is the
same as ``"torque_sign": -1``. Channels not mapped are kept as extra columns.

Every recording is a position perturbation of joint 1..n (``perturbation.kind:
position``), the measured angle being the perturbation unless a ``theta_ref`` channel is
mapped. A file holding several ``nldat`` objects gives one trial per object, named by the
variable (``z_df``; ``FILE:VAR`` selects one).
"""

from __future__ import annotations

import copy
import json
import re
import warnings
from pathlib import Path

import numpy as np

from .errors import MatFileError
from .logs import FORMAT, MAX_DOF, MIN_SAMPLES, SIGNALS, complete_metadata, finish_trial

NLDAT = "nldat"
TARGETS = SIGNALS + ("theta_ref",)
#: a suffix the NLID lab's recordings put after the signal's name (``posPert1``,
#: ``tqPert1``: the position perturbation and the torque in response to it)
_SUFFIX = r"(?:[_ ]?(?:pert|meas|measured|total|tot))?"
_DEFAULT_NAMES = {"theta": re.compile(r"^(?:pos|angle|theta|position)" + _SUFFIX + r"_?(\d*)$",
                                      re.I),
                  "tau_h": re.compile(r"^(?:tq|torque|tau|trq)" + _SUFFIX + r"_?(\d*)$", re.I)}
_TARGET = re.compile(r"^(" + "|".join(TARGETS) + r")\[(\d+)\]$")
SIDECAR_KEYS = ("channels", "torque_sign", "meta", "variables", "sensors", "scheduling")
VARIABLE_KEYS = ("channels", "torque_sign", "meta", "scheduling")


def inventory(path) -> dict:
    """``{name: (shape, class)}`` of every variable of a ``.mat`` file (mat-io's whosmat).

    Returns an empty dict when mat-io cannot list the file.
    """
    try:
        from matio import whosmat
        return {str(k): (tuple(v[0]), str(v[1])) for k, v in whosmat(str(path)).items()}
    except Exception:  # noqa: BLE001 - a listing is only used to explain a refusal
        return {}


def describe_inventory(inv: dict) -> str:
    """``z_df (1x1 nldat), t (1x60000 double)``, or ``(no variable could be listed)``."""
    if not inv:
        return "(no variable could be listed)"
    return ", ".join(f"{k} ({'x'.join(str(s) for s in shape)} {cls})"
                     for k, (shape, cls) in inv.items())


def holds_nldat(inv: dict) -> bool:
    return any(cls == NLDAT for _, cls in inv.values())


def read_nldat_trials(path, *, variable: str | None = None,
                      min_samples: int = MIN_SAMPLES) -> list:
    """Read every ``nldat`` object of ``path`` (or only ``variable``) as a Trial.

    Parameters
    ----------
    path : str or os.PathLike
        ``NAME.mat`` (v5/v7 or v7.3); an optional sidecar ``NAME.json`` (module docstring).
    variable : str or None
        Read this variable only.
    min_samples : int
        Fewest samples a trial may have (one spectral segment).

    Returns
    -------
    list of trialformat.Trial, in the file's variable order: ``theta``, ``tau_h`` (N, n),
    ``t = arange(N) / fs``, metadata with ``fs = 1/domainIncr``, ``n_dof`` = number of
    joints mapped, ``perturbation.kind = "position"``, ``source`` naming the file, object
    and comment.

    Raises
    ------
    MatFileError
        The file does not load, holds no ``nldat`` (the message lists its variables and
        classes), a channel maps to nothing usable, ``domainIncr`` is not positive, or the
        sidecar is malformed (naming the key).
    """
    path = Path(path)
    sidecar = _sidecar(path)
    try:
        from matio import load_from_mat
        data = load_from_mat(str(path))
    except Exception as exc:  # noqa: BLE001 - mat-io raises many types; name the file
        raise MatFileError(f"{path}: mat-io cannot read it: {exc}") from None
    objects = {k: v for k, v in data.items() if getattr(v, "classname", None) == NLDAT}
    if not objects:
        raise MatFileError(f"{path}: holds no nldat object; its variables: "
                           f"{describe_inventory(inventory(path))}")
    unknown = sorted(set(sidecar.get("variables") or {}) - set(data))
    if unknown:
        raise MatFileError(f"{path.with_suffix('.json')}: key 'variables' names "
                           f"{unknown}, not in the file (it holds {', '.join(data)})")
    aux = {k: v for k, v in objects.items() if _auxiliary(v, _settings(sidecar, k))}
    recordings = {k: v for k, v in objects.items() if k not in aux}
    if not recordings:  # nothing else to attach them to: refused as recordings
        recordings, aux = objects, {}
    if variable is not None:
        if variable not in objects:
            raise MatFileError(f"{path}: no nldat variable {variable!r}; nldat objects: "
                               f"{', '.join(objects)}")
        if variable in aux:
            raise MatFileError(
                f"{path}: nldat variable {variable!r} is an auxiliary variable (one "
                f"channel, no angle or torque), attached to the recordings as a column; "
                f"read a recording: {', '.join(f'{path.name}:{k}' for k in recordings)}")
        recordings = {variable: recordings[variable]}
    trials = []
    for name, obj in recordings.items():
        trial = _trial(path, name, obj, _settings(sidecar, name), min_samples)
        start = _scalar(obj.properties, "domainStart", name) \
            if "domainStart" in obj.properties else 0.0
        for aux_name, aux_obj in aux.items():
            _attach(path, trial, start, aux_name, aux_obj)
        trials.append(trial)
    return trials


def _auxiliary(obj, settings: dict) -> bool:
    """True for an object of one channel that maps to no column (sidecar or default names)."""
    props = getattr(obj, "properties", None)
    if not isinstance(props, dict) or "dataSet" not in props:
        return False
    shape = np.shape(props["dataSet"])
    try:
        names = _names(props.get("chanNames", np.zeros(0)))
    except Exception:  # noqa: BLE001 - a malformed object is the recording reader's to name
        return False
    if len(shape) not in (1, 2) or (len(shape) == 2 and shape[1] != 1) or len(names) != 1:
        return False
    declared = settings["channels"]
    if names[0] in declared:
        return declared[names[0]] is None
    return not any(p.match(names[0]) for p in _DEFAULT_NAMES.values())


def _units(props, names) -> list:
    """Per-channel units of ``chanUnits`` (``(rad)`` -> ``rad``; ``Default Units`` or a
    count that does not match the channels: not stated, "")."""
    try:
        units = _names(props.get("chanUnits", np.zeros(0)))
    except Exception:  # noqa: BLE001 - units are a description; absent is "not stated"
        units = []
    if len(units) != len(names):
        return [""] * len(names)
    out = []
    for u in units:
        u = u.strip().strip("()[]").strip()
        out.append("" if u.lower() in ("default units", "default", "none") else u)
    return out


def _attach(path: Path, trial, start: float, name: str, obj) -> None:
    """Add auxiliary variable ``name`` to ``trial`` as an extra column (module docstring),
    or record and warn why it is skipped."""
    props = obj.properties
    source = f"nldat variable '{name}' of {path.name}"
    aux = trial.meta.setdefault("auxiliary", {})
    reason = None
    data = np.asarray(props["dataSet"])
    if data.dtype.kind not in "biuf":
        reason = f"not numeric (dtype {data.dtype})"
    else:
        try:
            incr = _scalar(props, "domainIncr", source)
            own_start = _scalar(props, "domainStart", source) if "domainStart" in props \
                else 0.0
        except MatFileError as exc:
            incr, own_start, reason = None, None, str(exc).split(": ", 1)[-1]
        n = data.shape[0]
        if reason is None and (n != trial.n_samples or not np.isfinite(incr) or
                               abs(incr * trial.fs - 1) > 1e-9):
            reason = (f"{n} samples at {1 / incr if incr else float('nan'):g} Hz, the "
                      f"recording {trial.n_samples} at {trial.fs:g} Hz")
        elif reason is None and abs(own_start - start) > incr / 2:
            reason = f"starts at {own_start:g} s, the recording at {start:g} s"
        elif reason is None and name in trial.extra:
            reason = "the recording has a channel of that name"
    if reason is not None:
        aux[name] = {"skipped": reason, "source": source}
        warnings.warn(f"{path.name}:{trial.name}: {source} not attached ({reason}); "
                      f"skipped", stacklevel=4)
        return
    names = _names(props.get("chanNames", np.zeros(0)))
    trial.extra[name] = data.astype(float).reshape(-1)
    aux[name] = {"units": _units(props, names)[0], "description": names[0], "source": source}


def _sidecar(path: Path) -> dict:
    side = path.with_suffix(".json")
    if not side.is_file():
        return {}
    try:
        doc = json.loads(side.read_text(encoding="utf-8-sig"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise MatFileError(f"{side}: JSON does not parse: {exc}") from None
    if not isinstance(doc, dict):
        raise MatFileError(f"{side}: must be a JSON object with keys {list(SIDECAR_KEYS)}")
    bad = sorted(set(doc) - set(SIDECAR_KEYS))
    if bad:
        raise MatFileError(f"{side}: unknown key(s) {bad} for an nldat file (known: "
                           f"{list(SIDECAR_KEYS)}; the trial metadata goes under 'meta')")
    for key, kind in (("channels", dict), ("meta", dict), ("variables", dict)):
        if key in doc and not isinstance(doc[key], kind):
            raise MatFileError(f"{side}: key '{key}' must be a JSON object")
    for name, sub in (doc.get("variables") or {}).items():
        if not isinstance(sub, dict) or set(sub) - set(VARIABLE_KEYS):
            raise MatFileError(f"{side}: key 'variables.{name}' must be an object with "
                               f"keys among {', '.join(VARIABLE_KEYS)}")
    _fold_sensors(doc, side)
    doc["_where"] = str(side)
    return doc


def _fold_sensors(doc: dict, side: Path) -> None:
    """``"sensors": {...}`` at the top, as in a trial's metadata (and as the torque-sign
    warning says): its ``torque_sign`` is the sidecar's, the rest goes to ``meta.sensors``."""
    if "sensors" not in doc:
        return
    sensors = doc.pop("sensors")
    if not isinstance(sensors, dict):
        raise MatFileError(f"{side}: key 'sensors' must be a JSON object")
    sensors = dict(sensors)
    if "torque_sign" in sensors:
        sign = sensors.pop("torque_sign")
        if "torque_sign" in doc and doc["torque_sign"] != sign:
            raise MatFileError(f"{side}: 'torque_sign' {doc['torque_sign']!r} and "
                               f"'sensors.torque_sign' {sign!r} disagree; give one")
        doc["torque_sign"] = sign
    if sensors:
        meta = doc.setdefault("meta", {})
        meta.setdefault("sensors", {}).update(sensors)


def _settings(sidecar: dict, name: str) -> dict:
    own = (sidecar.get("variables") or {}).get(name, {})
    meta = copy.deepcopy(sidecar.get("meta") or {})
    meta.update(copy.deepcopy(own.get("meta") or {}))
    channels = dict(sidecar.get("channels") or {})
    channels.update(own.get("channels") or {})
    sign = own.get("torque_sign", sidecar.get("torque_sign"))
    where = sidecar.get("_where", "")
    scheduling = own.get("scheduling", sidecar.get("scheduling"))
    if scheduling is not None:
        meta["scheduling"] = scheduling  # its form is checked by trialformat.scheduling
    if sign is not None and sign not in (1, -1):
        raise MatFileError(f"{where}: key 'torque_sign' must be 1 or -1, got {sign!r}")
    return {"meta": meta, "channels": channels, "torque_sign": sign, "where": where}


def _text(value) -> str:
    """A MATLAB char array (as mat-io returns it: nested arrays of str) as one string."""
    arr = np.asarray(value, dtype=object).ravel()
    parts = []
    for a in arr:
        if isinstance(a, np.ndarray):
            parts.append(_text(a))
        else:
            parts.append(str(a))
    return "".join(parts)


def _names(value) -> list:
    arr = np.asarray(value, dtype=object)
    if arr.dtype.kind == "U":
        return [str(s) for s in arr.ravel()]
    return [_text(c) for c in arr.ravel()]


def _scalar(props, key, where) -> float:
    try:
        value = float(np.asarray(props[key], dtype=float).ravel()[0])
    except (KeyError, IndexError, TypeError, ValueError):
        raise MatFileError(f"{where}: property '{key}' missing or not a number") from None
    return value


def _trial(path: Path, name: str, obj, settings: dict, min_samples: int):
    where = f"{path} variable '{name}' (nldat)"
    props = obj.properties
    if not isinstance(props, dict) or "dataSet" not in props:
        raise MatFileError(f"{where}: no property 'dataSet' (properties: "
                           f"{sorted(props) if isinstance(props, dict) else props})")
    data = np.asarray(props["dataSet"])
    if data.dtype.kind not in "biuf":
        raise MatFileError(f"{where}: property 'dataSet' is not numeric "
                           f"(dtype {data.dtype})")
    data = data.astype(float)
    if data.ndim == 1:
        data = data[:, None]
    if data.ndim != 2:
        raise MatFileError(f"{where}: property 'dataSet' has shape {data.shape}; expected "
                           f"(samples, channels) (several realisations are not read)")
    names = _names(props.get("chanNames", np.zeros(0)))
    if len(names) != data.shape[1]:
        raise MatFileError(f"{where}: {len(names)} channel names {names} for "
                           f"{data.shape[1]} data columns")
    incr = _scalar(props, "domainIncr", where)
    if not np.isfinite(incr) or incr <= 0:
        raise MatFileError(f"{where}: property 'domainIncr' must be a positive sampling "
                           f"interval [s], got {incr!r}")
    start = _scalar(props, "domainStart", where) if "domainStart" in props else 0.0
    columns = _map_channels(names, settings, where)
    joints = sorted({j for s, j in columns.values() if s in ("theta", "tau_h")})
    for s in ("theta", "tau_h"):
        have = sorted(j for t, j in columns.values() if t == s)
        if not have:
            raise MatFileError(
                f"{where}: no channel maps to {s}[j] (channels: {names}); declare the "
                f"mapping in {path.with_suffix('.json').name}, e.g. "
                f'{{"channels": {{"{names[0] if names else "pos1"}": "theta[1]", ...}}}}')
    n = max(joints)
    for s in ("theta", "tau_h"):
        missing = [j for j in range(1, n + 1) if (s, j) not in columns.values()]
        if missing:
            raise MatFileError(f"{where}: no channel for {s}{missing} (mapping: "
                               f"{_show(columns)}); every joint 1..{n} needs theta and tau_h")
    arrays = {"t": np.arange(data.shape[0]) * incr, "extra": {}}
    for s in TARGETS:
        cols = {j: c for c, (t, j) in columns.items() if t == s}
        if cols:
            if max(cols) > n:
                raise MatFileError(f"{where}: channel(s) {list(cols.values())} map to "
                                   f"{s}[{max(cols)}] beyond the {n} joint(s) with angle "
                                   f"and torque")
            arr = np.zeros((data.shape[0], n))
            for j, c in cols.items():
                arr[:, j - 1] = data[:, names.index(c)]
            arrays[s] = arr
    for c in names:
        if c not in columns and settings["channels"].get(c, "") is not None:
            arrays["extra"][c] = data[:, names.index(c)]
    meta = _metadata(path, name, props, settings, n, incr, start, names, columns)
    filled = complete_metadata(meta, where)
    stated = _units(props, names)  # chanUnits, applied to the columns they name
    units = {f"{s}[{j}]": stated[names.index(c)] for c, (s, j) in columns.items()
             if stated[names.index(c)]}
    return finish_trial(meta, arrays, name, filled, f"{path}:{name}", min_samples=min_samples,
                        units=units, units_by=f"chanUnits of {name}")


def _show(columns) -> str:
    return ", ".join(f"{c} -> {s}[{j}]" for c, (s, j) in columns.items())


def _map_channels(names, settings, where) -> dict:
    """``{channel: (signal, joint)}`` from the sidecar's mapping, else the default names."""
    declared = settings["channels"]
    unknown = sorted(set(declared) - set(names))
    if unknown:
        raise MatFileError(f"{settings['where']}: key 'channels' names {unknown}, not "
                           f"channels of {where} (channels: {names})")
    out = {}
    for c in names:
        if c in declared:
            target = declared[c]
            if target is None:
                continue
            m = _TARGET.match(str(target))
            if not m or not 1 <= int(m.group(2)) <= MAX_DOF:
                raise MatFileError(f"{settings['where']}: key 'channels.{c}' must be one "
                                   f"of {', '.join(s + '[j]' for s in TARGETS)} (1 <= j <= "
                                   f"{MAX_DOF}) or null, got {target!r}")
            out[c] = (m.group(1), int(m.group(2)))
            continue
        for signal, pattern in _DEFAULT_NAMES.items():
            m = pattern.match(c)
            if m:
                out[c] = (signal, int(m.group(1) or 1))
    taken = {}
    for c, key in out.items():
        if key in taken:
            raise MatFileError(f"{where}: channels {taken[key]!r} and {c!r} both map to "
                               f"{key[0]}[{key[1]}]; declare the mapping in the sidecar "
                               f"('channels')")
        taken[key] = c
    return out


def _metadata(path, name, props, settings, n, incr, start, names, columns) -> dict:
    comment = _text(props["comment"]) if "comment" in props else ""
    meta = {"format": FORMAT, "fs": 1.0 / incr, "n_dof": n,
            "perturbed_dof": 1 if n == 1 else None,
            "perturbation": {"kind": "position"},
            "source": f"NLID nldat {path.name}:{name}"
                      + (f" ({comment})" if comment else "")
                      + f"; channels {_show(columns)}; domainStart {start:g} s"}
    # a lab's ADC samples angle and torque together (log-format.md, torque_sampling)
    meta["sensors"] = {"torque_sampling": "instantaneous"}
    if settings["torque_sign"] is not None:
        meta["sensors"]["torque_sign"] = settings["torque_sign"]
    for key, value in settings["meta"].items():
        if isinstance(value, dict) and isinstance(meta.get(key), dict):
            meta[key] = {**meta[key], **value}
        else:
            meta[key] = value
    return meta
