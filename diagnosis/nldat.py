"""Trials from a ``.mat`` of NLID toolbox ``nldat`` objects (the reklab recordings).

The public NLID toolbox (reklab/reklab_public) stores a recording as an ``nldat`` class
object (``dataSet`` N x channels, ``chanNames``, ``domainIncr`` [s], ``domainStart``):
MATLAB class objects that scipy.io cannot read; the ``mat-io`` package does
(``matio.load_from_mat``). Each object with one angle channel (``pos*``) and one torque
channel (``tq*``) becomes a one-joint position-perturbation trial, in memory:

- ``theta[1]`` = the angle channel [rad], ``tau_h[1]`` = the torque channel [N m], as
  stored (a reversed torque sign is found by the conventions stage, not assumed);
- ``fs = 1 / domainIncr``; ``perturbation.kind = "position"`` without a reference (none
  is stored); ``sensors.torque_sampling = "instantaneous"`` (a lab's ADC samples
  torque and angle together); ``condition`` = the variable name (each object is its own
  limb state); ``source`` names the file and the variable.

(This is the diagnosis's own small adapter; trialformat.matlab may gain a general
``nldat`` reader, which would then be used instead.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import trialformat as tf
from trialformat.logs import finish_trial

from .errors import DiagnosisInputError

ANGLE_PREFIXES = ("pos", "ang", "theta")
TORQUE_PREFIXES = ("tq", "torq", "trq")


def _objects(path: Path) -> dict:
    try:
        from matio import load_from_mat
    except ImportError:
        return {}
    try:
        data = load_from_mat(str(path))
    except Exception:  # noqa: BLE001 - not a file mat-io reads: not an nldat file
        return {}
    return {k: v for k, v in data.items()
            if hasattr(v, "properties") and "dataSet" in getattr(v, "properties", {})}


def _text(value) -> str:
    arr = np.asarray(value, dtype=object).ravel()
    while arr.size == 1 and isinstance(arr[0], np.ndarray):
        arr = np.asarray(arr[0], dtype=object).ravel()
    return "".join(str(a) for a in arr)


def _names(value) -> list:
    arr = np.asarray(value, dtype=object).ravel()
    return [_text(a) for a in arr]


def read_nldat_trials(path, *, min_samples: int = tf.MIN_SAMPLES) -> list:
    """The trials of the ``nldat`` objects in ``path`` (empty when it holds none).

    Raises
    ------
    DiagnosisInputError
        An ``nldat`` object without one angle and one torque channel, or without a
        sample increment (names the file, the variable and its channels).
    """
    path = Path(path)
    out = []
    for name, obj in _objects(path).items():
        p = obj.properties
        data = np.asarray(p["dataSet"], dtype=float)
        chans = _names(p.get("chanNames", []))
        where = f"{path} variable {name!r}"
        if data.ndim != 2 or data.shape[1] != len(chans):
            raise DiagnosisInputError(f"{where}: dataSet of shape {data.shape} but channels "
                                      f"{chans}")
        angle = [i for i, c in enumerate(chans) if c.lower().startswith(ANGLE_PREFIXES)]
        torque = [i for i, c in enumerate(chans) if c.lower().startswith(TORQUE_PREFIXES)]
        if len(angle) != 1 or len(torque) != 1:
            raise DiagnosisInputError(f"{where}: channels {chans}; expected one angle "
                                      f"({'/'.join(ANGLE_PREFIXES)}*) and one torque "
                                      f"({'/'.join(TORQUE_PREFIXES)}*) channel")
        incr = float(np.asarray(p.get("domainIncr", np.nan), dtype=float).ravel()[0])
        if not np.isfinite(incr) or incr <= 0:
            raise DiagnosisInputError(f"{where}: domainIncr {incr!r} is not a positive "
                                      f"sample increment [s]")
        fs = 1.0 / incr
        if abs(fs - round(fs)) < 1e-9 * fs:
            fs = float(round(fs))
        n = data.shape[0]
        meta = {"format": tf.FORMAT, "fs": fs, "n_dof": 1, "perturbed_dof": 1,
                "perturbation": {"kind": "position"},
                "sensors": {"torque_sampling": "instantaneous"},
                "condition": name,
                "source": f"nldat object {name!r} of {path.name} (channels {chans})"}
        arrays = {"t": np.arange(n) / fs, "theta": data[:, angle], "tau_h": data[:, torque]}
        try:
            trial = finish_trial(meta, arrays, name, [], where, min_samples=min_samples)
        except tf.TrialFormatError as exc:
            raise DiagnosisInputError(str(exc)) from None
        out.append(trial)
    return out
