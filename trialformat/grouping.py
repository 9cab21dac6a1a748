"""One grouping rule for every tool (``estimate``, ``figures``, ``diagnose``): which trials
are one limb state (docs/spec/log-format.md, "condition"; issue 22).

The rule, in order:

1. Trials with the same ``condition`` label (a non-empty string) are one set.
2. Unlabelled trials are grouped by their experiment (joints, rate, perturbation kind,
   whether a ``theta_ref`` is recorded; a tool then refuses, or estimates apart, declared
   set-ups that disagree within a set). Such a group is one set when it holds at most one trial per
   perturbed joint and perturbation level (a decomposition set, an amplitude series), or when this project simulated every trial of
   it (one simulated set-up is one arm).
3. Otherwise each unlabelled recording is a set of its own when it suffices alone (one
   joint, or all joints perturbed at once); several unlabelled recordings of one joint of
   a multi-joint set-up are refused, asking for labels.

Labelled and unlabelled trials may be mixed: an unlabelled recording is never pooled
with a labelled one. The tools say the rule's outcome in one line (:func:`describe`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from .errors import TrialFormatError

#: ``source`` beginning of the trials the orchestrator simulates (a simulated session)
SIMULATED_SOURCES = ("simulated: orchestrator",)


@dataclass
class TrialSet:
    """Trials taken as one limb state: ``label`` (the condition label, or for an
    unlabelled set its trials' names), ``trials`` and ``why`` (the rule that made it)."""

    label: str
    trials: list
    why: str
    labelled: bool = False


def condition_label(trial) -> str | None:
    """The trial's ``condition`` label, or None when absent, null or blank.

    Raises
    ------
    TrialFormatError
        A label that is not a string (``["a"]``, 3), naming the trial, key and value.
    """
    value = trial.meta.get("condition")
    if value is None:
        return None
    if not isinstance(value, str):
        raise TrialFormatError(
            f"{trial.name or '(trial)'}: key 'condition' must be a string (the condition "
            f"label), got {json.dumps(value)[:60]}; write e.g. \"condition\": "
            f"{json.dumps(str(value[0]) if isinstance(value, list) and value else str(value))}")
    return value.strip() or None


def _setup_key(trial) -> str:
    key = {"n_dof": trial.n_dof, "fs": trial.fs, "kind": trial.perturbation_kind,
           "theta_ref": trial.theta_ref is not None}
    return json.dumps(key, sort_keys=True, default=str)


def simulated_here(trial) -> bool:
    """True when this project simulated the trial (its declared ``source``)."""
    return str(trial.meta.get("source", "")).startswith(SIMULATED_SOURCES)


def trial_sets(trials, *, pool: bool = False) -> list[TrialSet]:
    """The trials split by the rule of the module docstring, in the order first met.

    ``pool``: every group of one declared set-up is one set (the user's request).

    Raises
    ------
    TrialFormatError
        A ``condition`` that is not a string; several unlabelled recordings of one joint
        of a multi-joint set-up (naming them).
    """
    labelled: dict = {}
    unlabelled: dict = {}
    for t in trials:
        label = condition_label(t)
        if label is not None:
            labelled.setdefault(label, []).append(t)
        else:
            unlabelled.setdefault(_setup_key(t), []).append(t)
    sets = [TrialSet(label, group, f"condition label {label!r}: {len(group)} trial(s)",
                     labelled=True) for label, group in labelled.items()]
    for group in unlabelled.values():
        by_joint: dict = {}
        for t in group:
            level = (t.meta.get("perturbation") or {}).get("level")
            by_joint.setdefault((t.perturbed_dof, level), []).append(t)
        name = "+".join(t.name for t in group)
        if pool:
            sets.append(TrialSet(name, group, f"pooled on request: {len(group)} trial(s)"))
        elif all(len(v) == 1 for v in by_joint.values()):
            sets.append(TrialSet(name, group, "one trial per perturbed joint"
                                 if len(group) > 1 else "single recording"))
        elif all(simulated_here(t) for t in group):
            sets.append(TrialSet(name, group, f"simulated by this project from one "
                                 f"set-up: {len(group)} trial(s)"))
        elif group[0].n_dof == 1 or all(k[0] is None for k in by_joint):
            sets += [TrialSet(t.name, [t], "unlabelled recording, taken alone")
                     for t in group]
        else:
            dup = {k[0]: [t.name for t in v] for k, v in by_joint.items() if len(v) > 1}
            raise TrialFormatError(
                f"several unlabelled recordings perturb the same joint ({dup}); they are "
                f"separate recordings and are not averaged silently: give each set of one "
                f"trial per joint its own 'condition' label in the metadata, or pool them "
                f"on purpose (--pool)")
    return sets


def describe(sets) -> str:
    """The rule's outcome in one line, e.g. ``grouping: 3 set(s): relaxed (condition
    label, 2 trials), relaxed_noref (unlabelled, alone); same label = one limb state,
    unlabelled recordings pooled only one per joint or when simulated here``."""
    parts = []
    for s in sets:
        what = "condition label" if s.labelled else "unlabelled"
        parts.append(f"{s.label} ({what}, {len(s.trials)} trial(s))")
    return (f"grouping: {len(sets)} set(s): {', '.join(parts)}; one label = one limb "
            f"state, unlabelled trials pooled only one per joint or when simulated here")


def unique_file_names(labels, safe) -> tuple[list[str], list[str]]:
    """One file name per label, unique in its folder (issue 22: one name, one output).

    ``safe(label)`` is the tool's file-name form of a label; names equal to an earlier one
    (compared without case: case-insensitive file systems) get ``_2``, ``_3``, ...

    Returns
    -------
    names : list of str, one per label, in order
    notes : list of str, one per renamed label (``"labels 'day1/left' and 'day1_left'
        both give the file name 'day1_left': the second is written as 'day1_left_2'"``)
    """
    names, notes, taken = [], [], {}
    for label in labels:
        base = safe(label)
        name, k = base, 1
        while name.lower() in taken:
            k += 1
            name = f"{base}_{k}"
        if name != base:
            notes.append(f"labels {taken[base.lower()]!r} and {label!r} both give the file "
                         f"name {base!r}: {label!r} is written as {name!r}")
        taken.setdefault(base.lower(), label)
        taken[name.lower()] = label
        names.append(name)
    return names, notes
