"""Trials from a ``.mat`` of NLID toolbox ``nldat`` objects (the reklab recordings).

The reading is trialformat.nlid's (channels by name, ``fs = 1 / domainIncr``, a position
perturbation without a reference, torque sampled with the angle). What the diagnosis adds
is one rule: each ``nldat`` object is its own recording of its own limb state, so an object
without a declared ``condition`` gets its variable name as condition, and a folder of them
is diagnosed recording by recording (docs/diagnosis.md), not as one experiment.
"""

from __future__ import annotations

from pathlib import Path

import trialformat as tf

from .errors import DiagnosisInputError


def read_nldat_trials(path, *, min_samples: int = tf.MIN_SAMPLES) -> list:
    """The trials of the ``nldat`` objects in ``path`` (empty when it holds none).

    Returns
    -------
    list of trialformat.Trial
        One one-joint (or n-joint) position trial per object, ``condition`` = the
        variable name unless the sidecar declares one.

    Raises
    ------
    DiagnosisInputError
        An ``nldat`` object the reader refuses (channels, increment); the message names
        the file and the variable.
    """
    from trialformat import nlid
    path = Path(path)
    if not path.is_file() or not nlid.holds_nldat(nlid.inventory(path)):
        return []
    try:
        trials = nlid.read_nldat_trials(path, min_samples=min_samples)
    except tf.TrialFormatError as exc:
        raise DiagnosisInputError(str(exc)) from None
    for t in trials:
        if not t.meta.get("condition"):
            t.meta["condition"] = t.name
    return trials
