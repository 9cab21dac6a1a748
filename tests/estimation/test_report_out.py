"""``figures --out``: a report never replaces what this project did not write (issue 16).

Each case builds its trials in the test; a refusal must leave every file in place.
"""

import os

import pytest

import trialformat as tf
from estimation.cli import main
from estimation.synthetic import synthetic_trial


@pytest.fixture(scope="module")
def trial():
    return synthetic_trial(perturbed_dof=None, duration_s=10.0, seed=3)  # alone: one result


def _files(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def _figures(sources, out, *extra):
    return main(["figures", *map(str, sources), "--out", str(out), "--kind", "lab",
                 "--nperseg", "2048", *extra])


def _refused(capsys, sources, out, match):
    capsys.readouterr()
    assert _figures(sources, out) == 1
    err = capsys.readouterr().err
    assert match in err and err.strip().count("\n") == 0, err


@pytest.mark.parametrize("where", ["same", "parent", "grandparent"])
def test_out_that_is_or_holds_the_input_is_refused_and_keeps_every_trial(
        tmp_path, trial, capsys, where):
    trials = tmp_path / "lab" / "trials"
    tf.write_trial(trials / "S1", trial)
    tf.write_trial(trials / "S2", trial)
    before = _files(tmp_path)
    out = {"same": trials, "parent": trials.parent, "grandparent": tmp_path}[where]
    _refused(capsys, [trials], out, "is or holds the input")
    assert _files(tmp_path) == before
    assert tf.read_trial(trials / "S1", min_samples=2048).n_samples == 10000


def test_out_holding_a_named_input_file_is_refused(tmp_path, trial, capsys):
    tf.write_trial(tmp_path / "S1", trial)
    before = _files(tmp_path)
    _refused(capsys, [tmp_path / "S1.csv"], tmp_path, "holds the input")
    assert _files(tmp_path) == before


def test_unrelated_non_empty_folder_and_existing_file_are_refused(tmp_path, trial, capsys):
    tf.write_trial(tmp_path / "in" / "S1", trial)
    other = tmp_path / "thesis"
    other.mkdir()
    (other / "chapter1.tex").write_text("keep me")
    _refused(capsys, [tmp_path / "in"], other, "not a report of this project")
    assert (other / "chapter1.tex").read_text() == "keep me"
    notes = tmp_path / "notes.txt"
    notes.write_text("keep me too")
    _refused(capsys, [tmp_path / "in"], notes, "existing file")
    assert notes.read_text() == "keep me too"


def test_cli_refusal_is_one_line_and_exit_1(tmp_path, trial, capsys):
    from orchestrator.cli import main as armimp
    tf.write_trial(tmp_path / "S1", trial)
    assert armimp(["figures", str(tmp_path), "--out", str(tmp_path), "--kind", "lab",
                   "--nperseg", "2048"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "is or holds the input" in err
    assert tf.trial_exists(tmp_path / "S1")


def test_report_replaces_only_its_own_earlier_report(tmp_path, trial, capsys):
    tf.write_trial(tmp_path / "in" / "S1", trial)
    out = tmp_path / "report"
    out.mkdir()  # an empty folder is accepted
    assert _figures([tmp_path / "in"], out) == 0
    assert (out / tf.logs.REPORT_MARK).is_file()
    first = set(os.listdir(out))
    (out / "stale.txt").write_text("from the first report")  # part of our folder now
    assert _figures([tmp_path / "in"], out) == 0
    assert set(os.listdir(out)) == first  # replaced whole, marker kept
    # the marker (or an older report's index) is what makes it ours: without them the
    # same folder is refused
    os.unlink(out / tf.logs.REPORT_MARK)
    os.unlink(out / "results.json")
    _refused(capsys, [tmp_path / "in"], out, "not a report of this project")
    with pytest.raises(tf.OutputError, match="not a report"):  # the library refuses too
        tf.logs.replace_dir(tmp_path / "in", out)


def test_out_inside_the_input_folder_is_accepted_and_keeps_the_trials(tmp_path, trial):
    tf.write_trial(tmp_path / "S1", trial)
    assert _figures([tmp_path], tmp_path / "report") == 0
    assert tf.trial_exists(tmp_path / "S1") and (tmp_path / "report" / "parameters.csv").is_file()


def test_dotted_condition_labels_write_distinct_files(tmp_path, trial):
    for name in ("day1.left", "day1.right"):
        tf.write_trial(tmp_path / "in" / name, trial)
    assert _figures([tmp_path / "in"], tmp_path / "out") == 0
    names = os.listdir(tmp_path / "out")
    assert {"frf_day1.left.csv", "frf_day1.right.csv", "frf_day1.left.json",
            "frf_day1.right.json"} <= set(names)


def test_estimate_json_onto_a_trial_metadata_refused(tmp_path, trial, capsys):
    tf.write_trial(tmp_path / "S1", trial)
    before = (tmp_path / "S1.json").read_bytes()
    assert main(["estimate", str(tmp_path), "--json", str(tmp_path / "S1.json"),
                 "--nperseg", "2048"]) == 1
    assert "is a trial's metadata" in capsys.readouterr().err
    assert (tmp_path / "S1.json").read_bytes() == before


def test_cli_error_escapes_terminal_control_bytes(tmp_path, capsys):
    from orchestrator.cli import main as armimp
    name = tmp_path / "evil\x1b]0;title\x07.csv"
    name.write_bytes(b"\x1b[2Jt,x\n0,1\n")
    (tmp_path / "evil\x1b]0;title\x07.json").write_text("{}")
    assert armimp(["estimate", str(name)]) == 1
    err = capsys.readouterr().err
    assert "\x1b" not in err and "\x07" not in err and "\\x1b[2J" in err


def test_unmarked_report_of_an_earlier_version_is_still_replaced(tmp_path, trial):
    tf.write_trial(tmp_path / "in" / "S1", trial)
    out = tmp_path / "old_report"
    out.mkdir()
    (out / "results.json").write_text('{"options": {}, "results": []}')
    (out / "parameters.csv").write_text("old")
    assert _figures([tmp_path / "in"], out) == 0
    assert (out / tf.logs.REPORT_MARK).is_file()
    assert (out / "parameters.csv").read_text() != "old"
