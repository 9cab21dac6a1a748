"""Reading the measured trials of a diagnosis, blind to any truth.

Only ``NAME.csv`` with its ``NAME.json`` (or ``NAME.mat``, trialformat.matlab; or a
``.mat`` of NLID ``nldat`` objects, diagnosis.nldat) are read;
files whose stem ends in ``.truth`` are never opened, and the ``simulation`` key a simulator may leave in the metadata is
dropped on reading, so no code after this point can see what was really simulated.
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path

import numpy as np

import trialformat as tf

from .errors import DiagnosisInputError

#: metadata keys that every trial of one diagnosis must declare identically (torque
#: perturbation: the exoskeleton's set-up; position: only the rate and the joints)
DECLARED_KEYS = ("fs", "n_dof", "posture_deg", "controller", "sensors", "robot", "friction")
POSITION_DECLARED_KEYS = ("fs", "n_dof")
HIDDEN_KEYS = ("simulation",)


def trial_paths(source) -> list[Path]:
    """The ``NAME.csv`` / ``NAME.mat`` paths of a folder (or a list of paths), truth
    files excluded."""
    from trialformat.matlab import split_variable
    if isinstance(source, (str, os.PathLike)) and split_variable(source)[1] is not None:
        paths = [Path(source)]  # FILE.mat:VAR, one recording of a file of several
    elif isinstance(source, (str, os.PathLike)) and Path(source).is_file() and \
            str(source).lower().endswith((".csv", ".csv.gz", ".mat")):
        paths = [Path(source)]
    elif isinstance(source, (str, os.PathLike)):
        folder = Path(source)
        if not folder.is_dir():
            raise DiagnosisInputError(f"{folder}: not a folder of trials (nor a NAME.csv "
                                      f"or NAME.mat file)")
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


def load_trials(source, *, min_samples: int = tf.MIN_SAMPLES,
                check: bool = True) -> list[tf.Trial]:
    """Read the measured trials and (``check``) that they declare one set-up.

    A ``.mat`` holding NLID ``nldat`` objects (no ``meta``) gives one trial per object
    (diagnosis.nldat).

    Raises
    ------
    DiagnosisInputError
        No trial, a trial the format refuses (too short, ...), or declared set-ups that
        disagree (the message names both files and the key).
    """
    from estimation.io import read_trial
    trials = []
    read, notes = [], []
    for path in trial_paths(source):
        n_before = len(read)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                read.append(read_trial(path, min_samples=min_samples))
            notes += caught  # a file read whole: its warnings are the user's to see
        except (tf.TrialFormatError, ValueError) as exc:
            from .nldat import read_nldat_trials
            found = read_nldat_trials(path, min_samples=min_samples) \
                if Path(path).suffix.lower() == ".mat" else None
            if not found:
                raise DiagnosisInputError(str(exc)) from None
            read.extend(found)
        for trial in read[n_before:]:
            check_signals(trial, path)
            trial._source = source_label(trial, path)
    _say_notes(notes)
    for trial in read:
        for key in HIDDEN_KEYS:
            trial.meta.pop(key, None)
        # float32 storage (a .mat) is a representation, not a working precision
        for s in tf.SIGNALS + ("theta_ref",):
            if getattr(trial, s, None) is not None:
                setattr(trial, s, np.asarray(trial.signal(s), dtype=float))
        trial.t = np.asarray(trial.t, dtype=float)
        trials.append(trial)
    names = [t.name for t in trials]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise DiagnosisInputError(f"{source}: trial name(s) {dup} given twice")
    if check:
        check_consistent(trials)
    return trials


#: signal -> unit, of the measured signals a diagnosis compares (a constant one is refused)
MEASURED_UNITS = {"theta": "rad", "tau_h": "N m", "theta_ref": "rad"}


def source_label(trial, path) -> str:
    """The file a trial came from, as the user gave it (``FILE:NAME`` for one trial of a
    .mat of several)."""
    if Path(path).suffix.lower() == ".mat" and trial.name != Path(path).stem:
        return f"{path}:{trial.name}"
    return str(path)


#: a measured channel whose standard deviation is at most this fraction of its largest
#: magnitude is "numerically constant": its variation is at the rounding level of the
#: numbers as stored (1e-6 is ~ 17 float32 steps, the last of 6 printed digits), far below
#: any encoder or sensor resolution, and carries no perturbation or response to diagnose
NUMERICALLY_CONSTANT_REL_STD = 1e-6


def check_signals(trial, path) -> None:
    """Refuse a trial with a measured channel that is constant (every sample equal) or
    numerically constant (standard deviation <= :data:`NUMERICALLY_CONSTANT_REL_STD` times
    its largest magnitude): an angle or torque that does not change carries no response to
    diagnose, and the spectral estimates divide by its (rounding-level) power. The test is
    relative, so it holds in any units (position trials are scale-free).

    Raises
    ------
    DiagnosisInputError
        ``"FILE: tau_h[1] is constant (0 N m): nothing to diagnose"`` (file as given,
        the channel 1-based, its value and unit; ``FILE:NAME`` for a trial of a .mat of
        several), or ``"FILE: theta[1] is numerically constant (std 5.77e-09 rad around
        0.1 rad, 5.8e-08 of its largest magnitude, at most 1e-06): ..."``.
    """
    where = source_label(trial, path)
    for s, unit in MEASURED_UNITS.items():
        x = getattr(trial, s, None)
        if x is None:
            continue
        x = np.asarray(x, dtype=float).reshape(len(x), -1)
        for j in range(x.shape[1]):
            if not x.shape[0] or _held_reference(trial, s, j):
                continue
            if np.all(x[:, j] == x[0, j]):
                raise DiagnosisInputError(
                    f"{where}: {s}[{j + 1}] is constant ({x[0, j]:.6g} {unit}): nothing to "
                    f"diagnose")
            peak = float(np.max(np.abs(x[:, j])))
            if not np.isfinite(peak) or peak == 0.0:
                continue  # non-finite values: the format's and the later checks' to name
            rel = float(np.std(x[:, j] / peak))  # scaled first: no overflow at 1e200
            if rel <= NUMERICALLY_CONSTANT_REL_STD:
                mean = float(np.mean(x[:, j] / peak)) * peak
                raise DiagnosisInputError(
                    f"{where}: {s}[{j + 1}] is numerically constant (std {rel * peak:.3g} "
                    f"{unit} around {mean:.6g} {unit}, {rel:.2g} of its largest magnitude, "
                    f"at most {NUMERICALLY_CONSTANT_REL_STD:g}): its variation is at "
                    f"rounding level and carries no perturbation or response; nothing to "
                    f"diagnose (record the channel with its variation)")


def split_conditions(trials) -> dict:
    """Trials grouped by the one grouping rule shared with ``estimate`` and ``figures``
    (:func:`estimation.grouping.trial_sets`: one set per ``condition`` label; unlabelled
    trials together only one per perturbed joint at one declared set-up and level, else
    each alone), each group checked to declare one set-up (:func:`check_consistent`). A
    single set has the key None; several are keyed by their labels.

    Raises
    ------
    DiagnosisInputError
        What the rule refuses (a non-string label, ...), naming the trials.
    """
    from estimation.errors import EstimationError
    from estimation.grouping import trial_sets
    try:
        sets = trial_sets(trials)
    except EstimationError as exc:
        raise DiagnosisInputError(str(exc)) from None
    if len(sets) == 1:
        groups = {None: sets[0].trials}
    else:
        groups = {}
        for s in sets:  # an unlabelled recording named like a label keeps both
            key = s.label
            while key in groups:
                key += " (unlabelled)" if not s.labelled else "'"
            groups[key] = s.trials
    for group in groups.values():
        check_consistent(group)
    return groups


def check_consistent(trials) -> None:
    """Refuse trials whose declared set-ups (DECLARED_KEYS; POSITION_DECLARED_KEYS for
    position perturbations) or perturbation kinds differ."""
    first = trials[0]
    keys = POSITION_DECLARED_KEYS if first.perturbation_kind == "position" else DECLARED_KEYS
    for trial in trials[1:]:
        if trial.perturbation_kind != first.perturbation_kind:
            raise DiagnosisInputError(
                f"trial {trial.name!r} is a {trial.perturbation_kind} perturbation but trial "
                f"{first.name!r} a {first.perturbation_kind} one: one diagnosis takes "
                f"trials of one experiment")
        for key in keys:
            a, b = first.meta.get(key), trial.meta.get(key)
            if json.dumps(a, sort_keys=True) != json.dumps(b, sort_keys=True):
                raise DiagnosisInputError(
                    f"trial {trial.name!r} declares {key}={json.dumps(b, sort_keys=True)} but "
                    f"trial {first.name!r} declares {key}={json.dumps(a, sort_keys=True)}: "
                    f"one diagnosis takes trials of one declared set-up")


def _held_reference(trial, signal: str, j: int) -> bool:
    """A servo reference of a joint the trial does not perturb: held (constant, or absent
    from the file and read as 0, log-format.md), so not a channel to refuse."""
    k = getattr(trial, "perturbed_dof", None)
    return signal == "theta_ref" and k is not None and j != k - 1


def _say_notes(caught) -> None:
    """Re-issue the readers' warnings, one per text: the same note on many files is said
    once with their count (trialformat.cliargs.merged_notes)."""
    from trialformat.cliargs import merged_notes
    kept = [w for w in caught if not issubclass(w.category, (DeprecationWarning, FutureWarning))]
    category = {str(w.message): w.category for w in kept}
    first = {str(w.message): w for w in kept}
    for text in merged_notes(list(category)):
        w = first.get(text)
        warnings.warn_explicit(text, w.category if w else UserWarning,
                               w.filename if w else __file__, w.lineno if w else 0)

