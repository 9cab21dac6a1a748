"""Reading the measured trials of a diagnosis, blind to any truth.

Only ``NAME.csv`` with its ``NAME.json`` are read; files whose stem ends in ``.truth``
are never opened, and the ``simulation`` key a simulator may leave in the metadata is
dropped on reading, so no code after this point can see what was really simulated.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import trialformat as tf

from .errors import DiagnosisInputError

#: metadata keys that every trial of one diagnosis must declare identically
DECLARED_KEYS = ("fs", "n_dof", "posture_deg", "controller", "sensors", "robot", "friction")
HIDDEN_KEYS = ("simulation",)


def trial_paths(source) -> list[Path]:
    """The ``NAME.csv`` paths of a folder (or a list of paths), truth files excluded."""
    if isinstance(source, (str, os.PathLike)):
        folder = Path(source)
        if not folder.is_dir():
            raise DiagnosisInputError(f"{folder}: not a folder of trials")
        paths = sorted(folder.glob("*.csv"))
    else:
        paths = [Path(p) for p in source]
    paths = [p for p in paths if not p.stem.endswith(".truth")]
    if not paths:
        raise DiagnosisInputError(f"{source}: no trial (no NAME.csv with its NAME.json)")
    return paths


def load_trials(source, *, min_samples: int = tf.MIN_SAMPLES) -> list[tf.Trial]:
    """Read the measured trials and check that they declare one set-up.

    Raises
    ------
    DiagnosisInputError
        No trial, a trial the format refuses (too short, ...), or declared set-ups that
        disagree (the message names both files and the key).
    """
    trials = []
    for path in trial_paths(source):
        try:
            trial = tf.read_trial(path, min_samples=min_samples)
        except tf.TrialFormatError as exc:
            raise DiagnosisInputError(str(exc)) from None
        for key in HIDDEN_KEYS:
            trial.meta.pop(key, None)
        trials.append(trial)
    check_consistent(trials)
    return trials


def check_consistent(trials) -> None:
    """Refuse trials whose declared set-ups (DECLARED_KEYS) differ."""
    first = trials[0]
    for trial in trials[1:]:
        for key in DECLARED_KEYS:
            a, b = first.meta.get(key), trial.meta.get(key)
            if json.dumps(a, sort_keys=True) != json.dumps(b, sort_keys=True):
                raise DiagnosisInputError(
                    f"trial {trial.name!r} declares {key}={json.dumps(b, sort_keys=True)} but "
                    f"trial {first.name!r} declares {key}={json.dumps(a, sort_keys=True)}: "
                    f"one diagnosis takes trials of one declared set-up")
