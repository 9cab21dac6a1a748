"""Reading the measured trials of a diagnosis, blind to any truth.

Only ``NAME.csv`` with its ``NAME.json`` (or ``NAME.mat``, trialformat.matlab) are read;
files whose stem ends in ``.truth`` are never opened, and the ``simulation`` key a simulator may leave in the metadata is
dropped on reading, so no code after this point can see what was really simulated.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

import trialformat as tf

from .errors import DiagnosisInputError

#: metadata keys that every trial of one diagnosis must declare identically
DECLARED_KEYS = ("fs", "n_dof", "posture_deg", "controller", "sensors", "robot", "friction")
HIDDEN_KEYS = ("simulation",)


def trial_paths(source) -> list[Path]:
    """The ``NAME.csv`` / ``NAME.mat`` paths of a folder (or a list of paths), truth
    files excluded."""
    if isinstance(source, (str, os.PathLike)):
        folder = Path(source)
        if not folder.is_dir():
            raise DiagnosisInputError(f"{folder}: not a folder of trials")
        try:
            paths = tf.logs.folder_trials(folder)  # .csv, .csv.gz, .mat; dotted names kept
        except tf.TrialFormatError as exc:
            raise DiagnosisInputError(str(exc)) from None
    else:
        paths = [Path(p) for p in source]
    paths = [p for p in paths if not tf.trial_stem(p).name.endswith(".truth")]
    if not paths:
        raise DiagnosisInputError(f"{source}: no trial (no NAME.csv with its NAME.json, "
                                  f"no NAME.mat)")
    return paths


def load_trials(source, *, min_samples: int = tf.MIN_SAMPLES) -> list[tf.Trial]:
    """Read the measured trials and check that they declare one set-up.

    Raises
    ------
    DiagnosisInputError
        No trial, a trial the format refuses (too short, ...), or declared set-ups that
        disagree (the message names both files and the key).
    """
    from estimation.io import read_trial
    trials = []
    for path in trial_paths(source):
        try:
            trial = read_trial(path, min_samples=min_samples)
        except (tf.TrialFormatError, ValueError) as exc:
            raise DiagnosisInputError(str(exc)) from None
        for key in HIDDEN_KEYS:
            trial.meta.pop(key, None)
        # float32 storage (a .mat) is a representation, not a working precision
        for s in tf.SIGNALS:
            setattr(trial, s, np.asarray(trial.signal(s), dtype=float))
        trial.t = np.asarray(trial.t, dtype=float)
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
