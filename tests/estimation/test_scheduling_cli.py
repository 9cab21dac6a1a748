"""``--scheduling NAME`` on estimate, figures and diagnose (issue 20): the scheduling
variable found per recording is printed and recorded; an unusable name is refused before
any work, naming the variable and what is available."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import trialformat as tf
from estimation.synthetic import position_trial
from orchestrator.cli import build_parser, main

PILOT = next((p for p in (Path(__file__).resolve().parents[k] / "shared" / "data" /
                          "reklab-pilot" / "IEEETBME2022_PilotData_AV_PT1_UT2.mat"
                          for k in (3, 4)) if p.is_file()), None)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A position trial with an extra column ``load`` (a slow ramp 2..4 N m)."""
    trial = position_trial(K=50.0, B=1.0, I=0.01, duration_s=20.0, name="rec")
    trial.extra["load"] = np.linspace(2.0, 4.0, trial.n_samples)
    out = tmp_path_factory.mktemp("sched")
    tf.write_trial(out / "rec", trial)
    return out


def test_estimate_prints_and_records_the_requested_variable(folder, tmp_path, capsys):
    assert main(["estimate", str(folder), "--scheduling", "load",
                 "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert "rec: scheduling variable load (units not stated) (column 'load'): 2..4" in out
    assert json.loads((tmp_path / "r.json").read_text())[0]["options"]["scheduling"] == "load"
    assert main(["estimate", str(folder)]) == 0  # stationary, nothing declared: no line
    assert "scheduling variable" not in capsys.readouterr().out


def test_an_unknown_name_is_refused_by_estimate_and_diagnose(folder, tmp_path, capsys):
    for argv in (["estimate", str(folder)],
                 ["diagnose", str(folder), "--out", str(tmp_path / "d")]):
        assert main(argv + ["--scheduling", "speed"]) == 1
        err = capsys.readouterr().err
        assert "scheduling variable 'speed' requested (--scheduling): no such variable; " \
               "available: load (column); time; angle, angle[1]" in err
    assert not (tmp_path / "d").exists()  # refused before any work


def test_figures_takes_the_option():
    args = build_parser().parse_args(["figures", "x", "--out", "y", "--scheduling", "time"])
    assert args.scheduling == "time"


@pytest.mark.skipif(PILOT is None, reason="the moving-ankle recording is not at "
                    "../shared/data/reklab-pilot (GPL data, not in the repository)")
def test_estimate_reads_the_pilot_recording_and_says_its_scheduling_variable(capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["estimate", str(PILOT)]) == 0
    out = capsys.readouterr().out
    assert (f"io: scheduling variable sv [rad] (nldat variable 'sv' of {PILOT.name}): "
            f"-0.4117..0.2028 rad, taken by default") in out
