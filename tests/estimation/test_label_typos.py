"""Condition labels spelt alike (lab session tester): ``relaxd`` / ``relaxed`` and
``co-contarct`` / ``co-contract`` are named in one note and kept apart; labels whose digits
differ (``PF10`` / ``PF20``, ``day1`` / ``day2``) are distinct, never named."""

from types import SimpleNamespace

import pytest

from estimation.grouping import near_duplicate_labels, trial_sets
from estimation.synthetic import position_trial


def _labelled(*labels):
    return [SimpleNamespace(meta={"condition": label}) for label in labels]


def test_close_spellings_named_in_one_note_and_kept_apart():
    labels = ("relaxed", "relaxd", "co-contract", "co-contarct", "cocontract", "co contract")
    note = near_duplicate_labels(_labelled(*labels))
    assert note.count("condition labels") == 1
    assert "'relaxed', 'relaxd': kept apart as 2 limb states" in note
    assert ("'co-contract', 'co-contarct', 'cocontract', 'co contract': kept apart as 4"
            in note)
    trials = [position_trial(K=80.0, B=1.2, I=0.012, duration_s=10, seed=i, condition=c,
                             name=f"r{i}") for i, c in enumerate(("relaxed", "relaxd"))]
    assert [s.label for s in trial_sets(trials)] == ["relaxd", "relaxed"]  # grouping as before


@pytest.mark.parametrize("labels", [("PF10", "PF20"), ("day1", "day2"), ("day 1", "day 2"),
                                    ("active", "passive"), ("left", "right"),
                                    ("relaxed", "co-contract")])
def test_distinct_labels_are_not_named(labels):
    assert near_duplicate_labels(_labelled(*labels)) is None


def test_case_and_spaces_only_keep_their_note():
    note = near_duplicate_labels(_labelled("Relaxed", "relaxed ", "relaxed"))
    assert note.startswith("condition labels that differ only by case or surrounding spaces")
    assert "case counts, surrounding spaces do not" in note
