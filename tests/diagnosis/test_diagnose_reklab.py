"""The five measured ankle recordings (reklab, ../shared/data/reklab-ankle, GPL: read from
there, never copied): ``diagnose`` ends with a verdict and a report on each, alone or
together, from the ``.mat`` of ``nldat`` objects and from lab-format files."""

import json
import os
from pathlib import Path

import pytest

import trialformat as tf
from diagnosis import DiagnosisSet, diagnose
from diagnosis.nldat import read_nldat_trials

DATA = Path(os.environ.get("ARMIMP_SHARED_DATA", Path(__file__).resolve().parents[3]
                           / "shared" / "data")) / "reklab-ankle"
MAT = DATA / "experimental_data.mat"
NAMES = ("z_df", "z_pf", "z_df2", "z_df3", "z_pf2")
needs_data = pytest.mark.skipif(not MAT.is_file(), reason=f"{MAT} absent (the reklab "
                                "recordings are not part of the project; CI has them)")


def _lab_folder(tmp_path, names):
    """The recordings as lab-format CSV + JSON in a temp folder (never committed)."""
    folder = tmp_path / "lab"
    folder.mkdir()
    for t in read_nldat_trials(MAT):
        if t.name in names:
            tf.write_trial(folder / t.name, t)
    return folder


def _check(report, name):
    assert report.verdict in ("effect", "partly explained", "unexplained",
                              "no significant gap", "convention mismatch")
    assert report.experiment["class"] == "PositionServo"
    # the torque sign of these files is reversed relative to the angle: found, said
    assert any(c["name"] == "torque sign reversed" for c in report.conventions), name
    assert report.arm["K_h"][0][0] > 0
    for row in report.ranking:
        assert row["held_out_reduction"] is not None
    out = report.out_dir
    for f in ("report.md", "report.json", "frf_compare.png", "gap_where.png"):
        assert (out / f).is_file(), f
    assert "torque sign reversed" in (out / "report.md").read_text()


@needs_data
def test_nldat_reader_gives_five_position_trials():
    trials = read_nldat_trials(MAT)
    assert [t.name for t in trials] == list(NAMES)
    for t in trials:
        assert t.fs == 1000.0 and t.n_samples == 60000 and t.n_dof == 1
        assert t.perturbation_kind == "position" and t.theta_ref is None
        assert t.meta["condition"] == t.name


@needs_data
def test_plantarflexor_active_recording_alone(tmp_path):
    report = diagnose(_lab_folder(tmp_path, ("z_pf2",)), tmp_path / "out", workers=1,
                      progress=False)
    _check(report, "z_pf2")


@pytest.mark.slow
@needs_data
def test_the_five_recordings_together_and_each_alone(tmp_path):
    both = tmp_path / "mat"
    both.mkdir()
    os.symlink(MAT, both / MAT.name)
    result = diagnose(both, tmp_path / "all", workers=1, progress=False)
    assert isinstance(result, DiagnosisSet) and list(result.reports) == list(NAMES)
    for name, report in result.reports.items():
        _check(report, name)
    index = json.loads((tmp_path / "all" / "report.json").read_text())
    assert sorted(index["conditions"]) == sorted(NAMES)
    lab = _lab_folder(tmp_path, NAMES)
    for name in NAMES:
        alone = diagnose([lab / f"{name}.csv"], tmp_path / f"alone_{name}", workers=1,
                         progress=False)
        _check(alone, name)
        assert alone.verdict == result.reports[name].verdict


@needs_data
def test_one_recording_of_the_file_by_name():
    """``FILE.mat:VAR`` names one recording, as for ``estimate`` and ``figures``."""
    from diagnosis.inputs import load_trials
    trials = load_trials(f"{MAT}:z_pf2")
    assert [t.name for t in trials] == ["z_pf2"]
    assert trials[0].meta["perturbation"]["kind"] == "position"


def test_a_killed_multi_condition_run_may_be_resumed(tmp_path):
    """The out folder a killed diagnosis of several conditions leaves (one finished
    report, one resume store) is accepted by a re-run; a folder of the user's is not."""
    from diagnosis.errors import DiagnosisInputError
    from diagnosis.pipeline.report import check_out_dir
    from diagnosis.pipeline.resume import CACHE_DIR
    out = tmp_path / "out"
    (out / "z_df").mkdir(parents=True)
    (out / "z_df" / "report.json").write_text("{}")
    (out / "z_pf" / CACHE_DIR).mkdir(parents=True)
    check_out_dir(out, tmp_path / "in")
    (out / "notes.txt").write_text("mine")
    with pytest.raises(DiagnosisInputError, match="not a diagnosis"):
        check_out_dir(out, tmp_path / "in")
