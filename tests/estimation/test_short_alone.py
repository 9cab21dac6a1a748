"""A recording shorter than one Welch segment among longer ones (lab session tester): it
is refused alone with its message, the others are estimated as before (README); the time
segments warning names only the recordings that limit it."""

import json

import trialformat as tf
from estimation import lab
from estimation.cli import main
from estimation.synthetic import position_trial


def _folder(path, durations, condition=None):
    trials = []
    for i, d in enumerate(durations):
        t = position_trial(K=80.0, B=1.2, I=0.012, duration_s=d, seed=i, name=f"r{i}",
                           condition=condition)
        tf.write_trial(path / f"r{i}", t)
        trials.append(t)
    return trials


def test_short_recording_refused_alone_the_others_estimated_as_before(tmp_path, capsys):
    _folder(tmp_path / "session", (30, 30, 5))
    assert main(["estimate", str(tmp_path / "session"), "--json",
                 str(tmp_path / "all.json")]) == 1  # one recording refused
    cap = capsys.readouterr()
    assert ("error: r2 (from " in cap.err and "5000 samples, 5 s: fewer than one spectral "
            "segment (--nperseg 8192): refused alone" in cap.err), cap.err
    assert "give it alone with --nperseg 1024" in cap.err
    assert "r0: method=" in cap.out and "r1: method=" in cap.out and "r2:" not in cap.out
    assert main(["estimate", str(tmp_path / "session" / "r0.csv"), "--json",
                 str(tmp_path / "r0.json")]) == 0
    capsys.readouterr()
    both = {r["condition"]: r for r in json.loads((tmp_path / "all.json").read_text())}
    alone = json.loads((tmp_path / "r0.json").read_text())[0]
    assert sorted(both) == ["r0", "r1"]
    for key in ("parameters", "n_segments", "welch", "warnings"):  # as without the short one
        assert both["r0"][key] == alone[key], key


def test_every_recording_short_is_still_refused_with_the_nperseg_that_works(tmp_path, capsys):
    _folder(tmp_path, (5,))
    assert main(["estimate", str(tmp_path)]) == 1
    assert "use --nperseg 1024" in capsys.readouterr().err


def test_time_segments_warning_names_only_the_shortest_recording():
    """'r0, r1, r2 (5 s) allows at most 2' listed 30 s recordings as 5 s."""
    trials = [position_trial(K=80.0, B=1.2, I=0.012, duration_s=d, seed=i, name=f"r{i}")
              for i, d in enumerate((30, 30, 5))]
    n, said = lab.time_segments(trials, (0.0, 40.0), lab.AnalysisOptions(nperseg=1024))
    assert n == 2 and len(said) == 1
    assert ": r2 (5 s) allows at most 2" in said[0] and "r0" not in said[0], said
