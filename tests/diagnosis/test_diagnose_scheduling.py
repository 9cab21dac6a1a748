"""``diagnose --scheduling NAME`` applies estimate's refusal of a scheduling variable
whose range is too narrow for a parameter-varying fit (one shared function,
trialformat.scheduling.varying_refusal, the same notice text), and says the variable
used (name, units, range, used or not) in its printed summary, report.md and
report.json. Before, diagnose fitted ``stiffness_angle`` over a stationary joint's
``angle`` that estimate refuses, and named no scheduling variable anywhere."""

import json
from pathlib import Path

import numpy as np
import pytest

import trialformat as tf
from estimation.synthetic import position_trial
from orchestrator.cli import main

PILOT = next((p for p in (Path(__file__).resolve().parents[k] / "shared" / "data" /
                          "reklab-pilot" / "IEEETBME2022_PilotData_AV_PT1_UT2.mat"
                          for k in (3, 4)) if p.is_file()), None)
NOTICE = ("scheduling variable 'angle[1]' of rec: range too narrow for a parameter-varying "
          "fit (")


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A stationary position trial (its angle's slow part within its perturbation) with an
    extra column ``load`` (a slow ramp 2..4)."""
    trial = position_trial(K=50.0, B=1.0, I=0.01, duration_s=20.0, name="rec")
    trial.extra["load"] = np.linspace(2.0, 4.0, trial.n_samples)
    out = tmp_path_factory.mktemp("sched")
    tf.write_trial(out / "rec", trial)
    return out


def _diagnose(folder, out, name, capsys):
    assert main(["diagnose", str(folder), "--scheduling", name, "--effects",
                 "stiffness_angle", "--workers", "1", "--out", str(out)]) == 0
    io = capsys.readouterr()
    return io.out, io.err, (out / "report.md").read_text(), \
        json.loads((out / "report.json").read_text())


def test_diagnose_refuses_the_narrow_angle_as_estimate_does(folder, tmp_path, capsys):
    assert main(["estimate", str(folder), "--scheduling", "angle"]) == 0
    est = capsys.readouterr().out
    notice = next(line.split("warning: ", 1)[1] for line in est.splitlines()
                  if NOTICE in line)
    assert notice.endswith("the time-invariant estimate is kept; a variable the joint's "
                           "state moves through (time, angle, or one spanning more) would "
                           "work")
    out, err, md, doc = _diagnose(folder, tmp_path / "d", "angle", capsys)
    assert notice in err  # the same notice, word for word
    (u,) = doc["scheduling"]
    assert (u["trial"], u["name"], u["units"], u["how"], u["used"]) == \
        ("rec", "angle[1]", "rad", "requested", False)
    assert u["refusal"] == notice and u["range"][0] < u["range"][1]
    line = next(x for x in out.splitlines() if x.startswith("Scheduling variable of rec"))
    assert line.startswith("Scheduling variable of rec: angle[1] [rad] (slow part of "
                           "theta[1] (< 0.5 Hz), requested): ")
    assert f"{u['range'][0]:.4g}..{u['range'][1]:.4g} rad; not used: {notice}" in line
    assert line in md
    # refused: the state-varying effect had no schedule to fit
    assert not [r for r in doc["ranking"] if "stiffness_angle" in str(r)]


def test_diagnose_says_a_usable_variable_it_used(folder, tmp_path, capsys):
    out, err, md, doc = _diagnose(folder, tmp_path / "d", "load", capsys)
    (u,) = doc["scheduling"]
    assert (u["name"], u["units"], u["used"], u["refusal"]) == ("load", "", True, None)
    assert u["range"] == pytest.approx([2.0, 4.0])
    line = ("Scheduling variable of rec: load (units not stated) (column 'load', "
            "requested): 2..4; used by the state-varying effects")
    assert line in out.splitlines() and line in md
    assert "range too narrow" not in err


@pytest.mark.skipif(PILOT is None, reason="the moving-ankle recording is not at "
                    "../shared/data/reklab-pilot (GPL data, not in the repository)")
def test_the_pilot_angle_gets_the_same_refusal_in_both_commands(capsys):
    """On the moving-ankle recording (its angle's slow part within 5 times its fast
    part: the perturbation) estimate's warning is the shared function's notice."""
    import warnings

    from diagnosis.limbfit import PositionRecord
    from trialformat.scheduling import request, usage
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (trial,) = tf.read_trials_mat(str(PILOT))
    assert PositionRecord.from_trial(trial).scheduling.name == "sv"  # the default: used
    request(trial, "angle")
    u = usage(trial)
    assert u["name"] == "angle[1]" and not u["used"]
    assert PositionRecord.from_trial(trial).scheduling is None  # refused for diagnose
    assert main(["estimate", str(PILOT), "--scheduling", "angle"]) == 0
    assert f"warning: {u['refusal']}" in capsys.readouterr().out
