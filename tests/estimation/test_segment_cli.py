"""``estimate`` / ``figures`` report the piecewise-constant K, B, I of a switching
one-joint recording (estimation.segmentlab, ``--track``): a labsim recording whose K
switches between 40 and 160 N m/rad every 2 s gets ``time_segments`` with one change per
true switch inside the tracked span, and segments_rec.png/.csv; a stationary recording
gets none (auto) or one segment (``--track segments``); too short a recording is
answered with a warning naming why."""

import csv
import json

import numpy as np
import pytest

import trialformat as tf
from labsim_switching import switching_trial
from estimation.cli import main
from estimation.synthetic import position_trial

SWITCH_S = 0.37 + 2.0 * np.arange(7)  # labsim switching: period 4 s, phase 0.37 s


@pytest.fixture(scope="module")
def switching(tmp_path_factory):
    """14 s at 1 kHz, PD servo, noise perturbation to 40 Hz, K 40 <-> 160 N m/rad;
    torque noise at 15 dB SNR (as tests/estimation/test_segmentfit.py)."""
    trial = switching_trial()
    rng = np.random.default_rng(5)
    trial.tau_h = trial.tau_h + np.std(trial.tau_h) * 10 ** (-15 / 20) * \
        rng.standard_normal(trial.tau_h.shape)
    out = tmp_path_factory.mktemp("switching")
    tf.write_trial(out / "rec", trial)
    return out


def test_a_switching_recording_gets_its_segments_in_figures(switching, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["figures", str(switching), "--out", str(out), "--nperseg", "4096"]) == 0
    text = capsys.readouterr().out
    doc = json.loads((out / "results.json").read_text())["results"][0]
    seg = doc["time_segments"]
    lo, hi = seg["segments"][0]["start_s"], seg["segments"][-1]["stop_s"]
    # a level the change-point test can see lasts 2 windows of 0.25 s (segmentfit)
    inside = SWITCH_S[(SWITCH_S > lo + 0.5) & (SWITCH_S < hi - 0.5)]
    assert len(seg["change_times_s"]) == inside.size >= 4, (seg["change_times_s"], inside)
    assert np.max(np.abs(np.array(seg["change_times_s"]) - inside)) <= 0.06
    assert len(seg["segments"]) == inside.size + 1
    for s in seg["segments"][1:-1]:  # the full 2 s levels: truth inside the interval
        k, klo, khi = s["K"]
        truth = 160.0 if k > 100 else 40.0
        assert klo < k < khi and abs(k - truth) <= 12.0, s
    assert f"time segments (rec): {inside.size} changes at" in text
    rows = list(csv.reader((out / "segments_rec.csv").open()))
    assert rows[0][:3] == ["start_s", "stop_s", "K [N m/rad]"]
    assert len(rows) == len(seg["segments"]) + 1
    assert (out / "segments_rec.png").stat().st_size > 10_000


def _write(folder, trial):
    folder.mkdir()
    tf.write_trial(folder / "rec", trial)
    return folder


def test_a_stationary_recording_gets_none_or_one_segment(tmp_path, capsys):
    folder = _write(tmp_path / "still", position_trial(K=80.0, B=1.2, I=0.015,
                                                       duration_s=14.0, name="rec"))
    js = tmp_path / "r.json"
    assert main(["estimate", str(folder), "--nperseg", "4096", "--json", str(js)]) == 0
    assert "time_segments" not in json.loads(js.read_text())[0]
    assert main(["estimate", str(folder), "--nperseg", "4096", "--track", "segments",
                 "--json", str(js)]) == 0
    seg = json.loads(js.read_text())[0]["time_segments"]
    assert seg["change_times_s"] == [] and len(seg["segments"]) == 1
    assert seg["trigger"] == "requested (--track segments)"
    k, klo, khi = seg["segments"][0]["K"]
    assert klo < 80.0 < khi
    assert "time segments (rec): 0 changes;" in capsys.readouterr().out


def test_too_short_a_recording_is_answered_naming_why(tmp_path, capsys):
    folder = _write(tmp_path / "short", position_trial(K=80.0, B=1.2, I=0.015,
                                                       duration_s=1.5, name="rec"))
    js = tmp_path / "r.json"
    assert main(["estimate", str(folder), "--nperseg", "128", "--track", "segments",
                 "--json", str(js)]) == 0
    doc = json.loads(js.read_text())[0]
    assert "time_segments" not in doc
    why = [w for w in doc["warnings"] if w.startswith("time-segment track not done")]
    assert why == ["time-segment track not done for rec (1.5 s at 1000 Hz): the recording "
                   "(1.5 s) is too short for the time-variation test: it needs 8 windows "
                   "of 0.25 s"], doc["warnings"]
    assert why[0] in capsys.readouterr().out
