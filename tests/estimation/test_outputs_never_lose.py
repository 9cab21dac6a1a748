"""Outputs never replace inputs or other reports (the breaker's cases of issue 16)."""

import json

import pytest

import trialformat as tf
from estimation.cli import main
from estimation.synthetic import position_trial

ANKLE = dict(K=80.0, B=1.2, I=0.012)


@pytest.fixture()
def folder(tmp_path):
    d = tmp_path / "rec"
    tf.write_trial(d / "rec1", position_trial(**ANKLE, seed=1, duration_s=20.0))
    return d


def test_json_onto_a_recording_is_refused_and_the_recording_kept(folder, capsys):
    data = (folder / "rec1.csv").read_bytes()
    assert main(["estimate", str(folder), "--json", str(folder / "rec1.csv")]) == 1
    assert "not an earlier results file" in capsys.readouterr().err
    assert (folder / "rec1.csv").read_bytes() == data


def test_json_replaces_its_own_earlier_results(folder, tmp_path):
    out = tmp_path / "r.json"
    assert main(["estimate", str(folder), "--json", str(out)]) == 0
    assert main(["estimate", str(folder), "--json", str(out)]) == 0
    assert json.loads(out.read_text())[0]["condition"]


def test_figures_onto_a_diagnosis_report_is_refused(folder, tmp_path, capsys):
    diag = tmp_path / "diag"
    diag.mkdir()
    (diag / "report.md").write_text("diagnosis")
    (diag / tf.logs.REPORT_MARK).write_text(json.dumps(
        {"format": tf.logs.REPORT_FORMAT, "kind": "diagnosis"}))
    assert main(["figures", str(folder), "--kind", "lab", "--out", str(diag)]) == 1
    assert "diagnosis report" in capsys.readouterr().err
    assert (diag / "report.md").read_text() == "diagnosis"


def test_same_name_from_two_sources_keeps_both(tmp_path):
    for sub, seed in (("a", 1), ("b", 2)):
        tf.write_trial(tmp_path / sub / "rec", position_trial(**ANKLE, seed=seed,
                                                                duration_s=20.0))
    out = tmp_path / "report"
    assert main(["figures", str(tmp_path / "a"), str(tmp_path / "b"), "--kind", "lab",
                 "--out", str(out)]) == 0
    frfs = sorted(p.name for p in out.glob("frf_*.csv"))
    assert len(frfs) == 2, frfs


def test_the_same_recording_twice_is_refused(folder, capsys):
    assert main(["estimate", str(folder), str(folder)]) == 1
    assert "given twice" in capsys.readouterr().err


def test_a_cut_gzip_trial_is_refused_naming_the_file(tmp_path, capsys):
    import gzip
    tf.write_trial(tmp_path / "a", position_trial(**ANKLE, seed=1, duration_s=20.0))
    data = (tmp_path / "a.csv").read_bytes()
    (tmp_path / "a.csv").unlink()
    (tmp_path / "a.csv.gz").write_bytes(gzip.compress(data)[:50_000])
    assert main(["estimate", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "a.csv.gz" in err and "gzip" in err


def test_an_empty_effect_list_is_refused(tmp_path, capsys):
    from orchestrator.cli import main as armimp
    assert armimp(["diagnose", str(tmp_path), "--out", str(tmp_path / "o"),
                   "--effects", ","]) == 1
    assert "names no effect" in capsys.readouterr().err
