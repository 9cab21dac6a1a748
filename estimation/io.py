"""Reading trials from CSV+JSON (trialformat) or MATLAB ``.mat`` (estimation.matlab)."""

from __future__ import annotations

import os
from pathlib import Path

import trialformat as tf

from .matlab import is_mat, read_trial_mat


def read_trial(path, *, min_samples=tf.MIN_SAMPLES) -> tf.Trial:
    """Read one trial, dispatching on the suffix: ``.mat`` or ``.csv``/``.json``/stem."""
    if is_mat(path):
        return read_trial_mat(path, min_samples=min_samples)
    return tf.read_trial(path, min_samples=min_samples)


def read_trials(source, *, min_samples=tf.MIN_SAMPLES) -> list[tf.Trial]:
    """Read every trial of a folder (``*.csv`` and ``*.mat``) or of a list of paths.

    A stem present both as ``NAME.csv`` and ``NAME.mat`` is refused as ambiguous.
    """
    if isinstance(source, (str, os.PathLike)) and Path(source).is_dir():
        csv = sorted(Path(source).glob("*.csv"))
        mat = sorted(Path(source).glob("*.mat"))
        both = sorted({p.stem for p in csv} & {p.stem for p in mat})
        if both:
            raise tf.TrialFormatError(f"{source}: trial(s) {both} present both as .csv and "
                                      f".mat; keep one")
        paths = csv + mat
        if not paths:
            raise tf.TrialFormatError(f"{source}: folder holds no trial (no NAME.csv or "
                                      f"NAME.mat)")
    elif isinstance(source, (str, os.PathLike)):
        paths = [Path(source)]
    else:
        paths = [Path(p) for p in source]
        if not paths:
            raise tf.TrialFormatError("no trial given (empty list of paths)")
    return [read_trial(p, min_samples=min_samples) for p in paths]
