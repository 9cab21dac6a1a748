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
