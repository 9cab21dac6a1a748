"""One grouping rule for every tool (``estimate``, ``figures``, ``diagnose``): which trials
are one limb state (docs/spec/log-format.md, "condition"; issue 22).

Trials are first split by their experiment as declared: joints, rate, perturbation kind,
the friction and sensor levels, the perturbation level, the controller tuning
(:func:`estimation.conditions.condition_of`) and the ``condition`` label. Then:

1. A labelled group (a non-empty string label), or any group with ``pool``, is one set.
2. An unlabelled group with at most one trial per perturbed joint is one set (the
   decomposition's one trial per joint, or a single recording).
3. Otherwise the unlabelled recordings are separate: each is a set of its own when it
   suffices alone (one joint, or all joints perturbed at once); several unlabelled
   recordings of one joint of a multi-joint set-up are refused, asking for labels.

An unlabelled recording is never pooled with a labelled one, nor with another recording of
the same joint. The tools say the outcome in one line (:func:`describe`).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass

from .errors import EstimationError

#: the rule in a few words, ending the line every tool prints (:func:`describe`)
RULE = ("rule: one condition label = one limb state; unlabelled trials together only one "
        "per perturbed joint at one declared set-up and level, else each alone")


@dataclass
class TrialSet:
    """Trials taken as one limb state: ``label`` (the condition label; for an unlabelled
    set its condition name or its trials' names), ``trials``, ``why`` (the rule that made
    it) and ``labelled``."""

    label: str
    trials: list
    why: str
    labelled: bool = False


def condition_label(trial) -> str | None:
    """The trial's ``condition`` label, or None when absent, null or blank.

    Raises
    ------
    EstimationError
        A label that is not a string (``["a"]``, 3), naming the trial, key and value.
    """
    value = trial.meta.get("condition")
    if value is None:
        return None
    if not isinstance(value, str):
        hint = str(value[0]) if isinstance(value, list) and value else str(value)
        raise EstimationError(
            f"{trial.name or '(trial)'}: key 'condition' must be a string (the condition "
            f"label), got {json.dumps(value)[:60]}; write e.g. \"condition\": "
            f"{json.dumps(hint)}")
    return value.strip() or None


def _experiment(trial) -> tuple:
    from .conditions import condition_of
    cond = condition_of(trial)
    return (trial.n_dof, trial.fs, trial.perturbation_kind, str(cond.friction),
            str(cond.resolution), str(cond.perturbation), cond.tuning)


def _simulated_name(trial) -> str:
    """The condition name (``F0R0P3``) of a multi-joint trial simulated by this project,
    else ""."""
    from .conditions import condition_of
    source = str(trial.meta.get("source", ""))
    if trial.n_dof > 1 and source.startswith(("simulated: orchestrator",
                                             "estimation.synthetic: linear")):
        return condition_of(trial).label
    return ""


def _joined(group) -> str:
    return group[0].name if len(group) == 1 else "+".join(t.name for t in group)


def trial_sets(trials, *, pool: bool = False) -> list[TrialSet]:
    """The trials split by the rule of the module docstring, sorted by label.

    ``pool``: every group of one declared experiment is one set (the user's request).

    Raises
    ------
    EstimationError
        A ``condition`` that is not a string; several unlabelled recordings of one joint
        of a multi-joint set-up (naming them).
    """
    groups: dict = {}
    for t in trials:
        groups.setdefault(_experiment(t) + (condition_label(t) or "",), []).append(t)
    sets = []
    for key, group in groups.items():
        label = key[-1]
        base = label or _simulated_name(group[0])
        by_joint: dict = {}
        for t in group:
            by_joint.setdefault(t.perturbed_dof, []).append(t)
        if label or pool:
            why = (f"condition label {label!r}" if label else "pooled on request") + \
                f": {len(group)} trial(s) averaged"
            sets.append(TrialSet(base or "pooled", group, why, labelled=bool(label)))
        elif all(len(v) == 1 for v in by_joint.values()):
            sets.append(TrialSet(base or _joined(group), group,
                                 "one trial per perturbed joint" if len(group) > 1
                                 else "single recording"))
        elif group[0].n_dof == 1 or all(k is None for k in by_joint):
            sets += [TrialSet(t.name, [t], "unlabelled recording, estimated alone")
                     for t in group]
        else:
            dup = {k: [t.name for t in v] for k, v in by_joint.items() if len(v) > 1}
            raise EstimationError(
                f"several unlabelled recordings perturb the same joint ({dup}); they are "
                f"separate recordings and are not averaged silently: give each set of one "
                f"trial per joint its own 'condition' label in the metadata, or pool them "
                f"on purpose (--pool)")
    return sorted(sets, key=lambda s: s.label)


#: difflib ratio at or above which two labels (case, spaces and punctuation removed) are
#: taken for spellings of one another
LABEL_SIMILARITY = 0.85


def _bare_label(label: str) -> str:
    """A label without case, spaces and punctuation (``"Co-Contract "`` -> ``cocontract``)."""
    return "".join(c for c in label.casefold() if c.isalnum())


def _labels_alike(a: str, b: str) -> bool:
    """Whether two labels look like spellings of one label: equal but for case, spaces and
    punctuation, or close (difflib ratio >= LABEL_SIMILARITY) with the same digits, so
    ``relaxd``/``relaxed`` and ``cocontract``/``co contract`` are alike and ``PF10``/``PF20``
    or ``day1``/``day2`` never are."""
    import difflib
    import re
    x, y = _bare_label(a), _bare_label(b)
    if x == y:
        return True
    if re.findall(r"\d+", x) != re.findall(r"\d+", y):
        return False
    return difflib.SequenceMatcher(None, x, y).ratio() >= LABEL_SIMILARITY


def near_duplicate_labels(trials) -> str | None:
    """One note naming the ``condition`` labels of ``trials`` that differ only by case or
    surrounding spaces (``"Relaxed"``, ``"relaxed "``, ``"relaxed"``), or look like
    misspellings of one another (``relaxd``/``relaxed``, ``co-contarct``/``co-contract``,
    ``cocontract``/``co contract``: :func:`_labels_alike`), or None.

    The grouping is unchanged: labels are compared as written, surrounding spaces
    ignored (:func:`condition_label`), so ``"relaxed "`` and ``"relaxed"`` are one set and
    ``"Relaxed"`` or ``"relaxd"`` another; the note says which are kept apart and which
    taken as one."""
    raws: list = []
    for t in trials:
        value = t.meta.get("condition")
        if isinstance(value, str) and value.strip() and value not in raws:
            raws.append(value)
    group = list(range(len(raws)))  # union-find over the distinct spellings

    def root(i):
        while group[i] != i:
            i = group[i]
        return i
    for i in range(len(raws)):
        for j in range(i):
            if root(i) != root(j) and _labels_alike(raws[i], raws[j]):
                group[max(root(i), root(j))] = min(root(i), root(j))
    clusters: dict = {}
    for i, r in enumerate(raws):
        clusters.setdefault(root(i), []).append(r)
    parts, spelled = [], False
    for raw in (v for v in clusters.values() if len(v) > 1):
        sets = list(dict.fromkeys(r.strip() for r in raw))
        case_only = len({r.casefold() for r in sets}) == 1
        spelled = spelled or not case_only
        said = ", ".join(repr(r) for r in raw)
        if len(sets) > 1:
            why = ("case counts, surrounding spaces do not" if case_only else
                   "labels are compared as written")
            what = (f"kept apart as {len(sets)} limb states ("
                    + ", ".join(repr(x) for x in sets) + f"; {why})")
        else:
            what = f"taken as one ({sets[0]!r}: surrounding spaces do not count)"
        parts.append(f"{said}: {what}")
    if not parts:
        return None
    head = ("condition labels that differ only by case, spaces, punctuation or a close "
            "spelling" if spelled else
            "condition labels that differ only by case or surrounding spaces")
    return (head + ": " + "; ".join(parts) + "; if they name one limb state, write one "
            "spelling in every trial's metadata")


def describe(sets) -> str:
    """The rule's outcome in one line: ``grouping: 3 set(s): relaxed (label, 2 trials),
    co-contracted (label, 1 trial), relaxed_noref (unlabelled, 1 trial); rule: ...``."""
    parts = [f"{s.label} ({'label' if s.labelled else 'unlabelled'}, {len(s.trials)} "
             f"trial{'s' if len(s.trials) != 1 else ''})" for s in sets]
    return f"grouping: {len(sets)} set(s): {', '.join(parts)}; {RULE}"


def safe_name(label: str, default: str = "result") -> str:
    """The file-name form of a label, one for every tool (``figures``' ``frf_PF_10`` and
    ``diagnose``'s folder ``PF_10`` for ``"PF 10%"``): runs of characters other than ASCII
    letters, digits and ``._+-`` become one ``_``, leading and trailing ``_`` dropped;
    ``default`` when nothing is left."""
    return re.sub(r"[^A-Za-z0-9._+-]+", "_", str(label)).strip("_") or default


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
