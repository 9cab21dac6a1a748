"""Issue 22: one name, one output in ``figures``; one grouping rule said in the output."""

from pathlib import Path

import trialformat as tf
from estimation.cli import main
from estimation.synthetic import position_trial


def test_colliding_labels_keep_both_figures(tmp_path, capsys):
    src = tmp_path / "in"
    for i, label in enumerate(("day1/left", "day1_left")):
        t = position_trial(K=80.0 + 70 * i, B=1.2, I=0.012, duration_s=20, seed=i,
                           condition=label, name=f"r{i}")
        tf.write_trial(src / f"r{i}", t)
    assert main(["figures", str(src), "--out", str(tmp_path / "rep")]) == 0
    cap = capsys.readouterr()
    err = cap.err
    files = sorted(p.name for p in Path(tmp_path / "rep").iterdir())
    assert "frf_day1_left.csv" in files and "frf_day1_left_2.csv" in files, files
    assert "bode_day1_left_2.png" in files
    assert "day1_left_2" in err and "grouping: 2 set(s)" in cap.out


def test_estimate_refuses_a_condition_that_is_not_a_string():
    import pytest

    from estimation.errors import EstimationError
    from estimation.lab import estimation_units
    t = position_trial(K=80.0, B=1.2, I=0.012, duration_s=10, seed=1, name="x")
    t.meta["condition"] = ["a"]  # was read as the label "['a']"
    with pytest.raises(EstimationError, match=r"x: key 'condition' must be a string"):
        estimation_units([t])


def test_labels_differing_by_case_or_spaces_are_grouped_as_before_and_named_once(
        tmp_path, capsys):
    """'Relaxed', 'relaxed ' and 'relaxed': grouped as before (case counts, surrounding
    spaces do not: 2 sets), and one note names the near-duplicate spellings."""
    from estimation.grouping import near_duplicate_labels, trial_sets
    trials = []
    for i, label in enumerate(("Relaxed", "relaxed ", "relaxed", "active")):
        t = position_trial(K=80.0, B=1.2, I=0.012, duration_s=10, seed=i,
                           condition=label, name=f"r{i}")
        trials.append(t)
        tf.write_trial(tmp_path / f"r{i}", t)
    sets = trial_sets(trials)
    assert [(s.label, [t.name for t in s.trials]) for s in sets] == [
        ("Relaxed", ["r0"]), ("active", ["r3"]), ("relaxed", ["r1", "r2"])]
    note = near_duplicate_labels(trials)
    assert "'Relaxed', 'relaxed ', 'relaxed'" in note and "kept apart as 2" in note
    assert "active" not in note
    assert near_duplicate_labels(trials[2:]) is None  # 'relaxed' and 'active' only
    assert "taken as one" in near_duplicate_labels(trials[1:3])
    assert main(["estimate", str(tmp_path)]) == 0
    cap = capsys.readouterr()
    assert cap.err.count("differ only by case or surrounding spaces") == 1, cap.err
    assert "grouping: 3 set(s)" in cap.out
