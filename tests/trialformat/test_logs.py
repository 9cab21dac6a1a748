"""Round trip and refusals of the trial format (docs/spec/log-format.md)."""

import json
from pathlib import Path

import numpy as np
import pytest

import trialformat as tf
from trialformat import TrialFormatError

SHARED_REFERENCE = Path(__file__).resolve().parents[3] / "shared" / "spec" / "reference.json"


def make_trial(n_samples=9000, n_dof=2, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) / 1000.0
    sig = {s: rng.standard_normal((n_samples, n_dof)) for s in tf.SIGNALS}
    meta = tf.default_metadata(n_dof)
    return tf.Trial(meta=meta, t=t, **sig)


def test_round_trip_is_bit_exact(tmp_path):
    trial = make_trial()
    trial.extra["omega[1]"] = np.linspace(0, 1, trial.n_samples)
    tf.write_trial(tmp_path / "a", trial)
    back = tf.read_trial(tmp_path / "a.csv")
    for s in tf.SIGNALS:
        np.testing.assert_array_equal(back.signal(s), trial.signal(s))
    np.testing.assert_array_equal(back.t, trial.t)
    np.testing.assert_array_equal(back.extra["omega[1]"], trial.extra["omega[1]"])
    assert back.meta == json.loads(json.dumps(trial.meta))
    assert back.filled_defaults == []


def test_absent_keys_filled_and_said(tmp_path):
    tf.write_trial(tmp_path / "a", make_trial())
    meta = json.loads((tmp_path / "a.json").read_text())
    del meta["friction"], meta["sensors"]["torque_resolution_nm"]
    (tmp_path / "a.json").write_text(json.dumps(meta))
    with pytest.warns(UserWarning, match="friction"):
        back = tf.read_trial(tmp_path / "a.csv")
    assert "friction" in back.filled_defaults
    assert "sensors.torque_resolution_nm" in back.filled_defaults
    assert back.meta["friction"]["Fc"] == [0.0, 0.0]


def _corrupt_csv(path, row, col, text):
    lines = path.read_text().splitlines()
    cells = lines[row].split(",")
    cells[col] = text
    lines[row] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("mutate, match", [
    (lambda p: _corrupt_csv(p.with_suffix(".csv"), 5, 3, "abc"), "non-numeric"),
    (lambda p: _corrupt_csv(p.with_suffix(".csv"), 5, 3, "nan"), "non-finite.*row 5"),
    (lambda p: _corrupt_csv(p.with_suffix(".csv"), 7, 0, "0.0001"), "not increasing|not uniform"),
    (lambda p: p.with_suffix(".json").write_text("{not json"), "JSON does not parse"),
    (lambda p: _set_meta(p, perturbed_dof=3), "perturbed_dof"),
    (lambda p: _set_meta(p, fs=500.0), "fs"),
    (lambda p: _drop_column(p.with_suffix(".csv"), "tau_h[2]"), r"missing columns.*tau_h\[2\]"),
])
def test_refusals_name_the_file(tmp_path, mutate, match):
    stem = tmp_path / "bad"
    tf.write_trial(stem, make_trial())
    mutate(stem)
    with pytest.raises(TrialFormatError, match=match) as info:
        tf.read_trial(stem.with_suffix(".csv"))
    assert "bad." in str(info.value)


def test_too_short_and_zero_perturbation(tmp_path):
    tf.write_trial(tmp_path / "short", make_trial(n_samples=8000))
    with pytest.raises(TrialFormatError, match="fewer than one spectral segment"):
        tf.read_trial(tmp_path / "short.csv")
    trial = make_trial()
    trial.tau_delta[:, 0] = 0.0
    tf.write_trial(tmp_path / "zero", trial)
    with pytest.raises(TrialFormatError, match=r"tau_delta\[1\].*identically zero"):
        tf.read_trial(tmp_path / "zero.csv")


def test_empty_folder_refused(tmp_path):
    with pytest.raises(TrialFormatError, match="no trial"):
        tf.read_trials(tmp_path)


def _set_meta(stem, **keys):
    path = stem.with_suffix(".json")
    meta = json.loads(path.read_text())
    meta.update(keys)
    path.write_text(json.dumps(meta))


def _drop_column(path, name):
    rows = [line.split(",") for line in path.read_text().splitlines()]
    i = rows[0].index(name)
    path.write_text("\n".join(",".join(r[:i] + r[i + 1:]) for r in rows) + "\n")


@pytest.mark.skipif(not SHARED_REFERENCE.is_file(), reason="shared spec folder not beside the repo")
def test_own_reference_copy_matches_shared():
    assert tf.reference.reference() == json.loads(SHARED_REFERENCE.read_text())
