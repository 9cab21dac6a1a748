"""The .mat reader: round trips, layout variants and refusals."""

import json

import numpy as np
import pytest
from scipy import io as sio

import trialformat as tf
from estimation import MatFileError, read_trial, read_trial_mat, read_trials, write_trial_mat


def make_trial(n=9000, k=1, seed=0):
    rng = np.random.default_rng(seed)
    sig = {s: rng.standard_normal((n, 2)) for s in tf.SIGNALS}
    meta = tf.default_metadata(2)
    meta["perturbed_dof"] = k
    return tf.Trial(meta=meta, t=np.arange(n) / 1000.0, name="a", **sig)


@pytest.mark.parametrize("meta_as", ["json", "struct"])
def test_round_trip(tmp_path, meta_as):
    trial = make_trial()
    path = write_trial_mat(tmp_path / "a.mat", trial, meta_as=meta_as)
    back = read_trial(path)
    for s in tf.SIGNALS:
        np.testing.assert_array_equal(back.signal(s), trial.signal(s))
    np.testing.assert_array_equal(back.t, trial.t)
    assert back.perturbed_dof == 1 and back.fs == 1000.0 and back.filled_defaults == []
    assert back.meta["friction"]["Fc"] == trial.meta["friction"]["Fc"]


def test_all_joints_trial_null_survives_a_struct(tmp_path):
    trial = make_trial(k=None)
    back = read_trial_mat(write_trial_mat(tmp_path / "a", trial, meta_as="struct"))
    assert back.perturbed_dof is None


def test_metadata_from_a_json_beside(tmp_path):
    trial = make_trial()
    sio.savemat(tmp_path / "b.mat", {"t": trial.t, **{s: trial.signal(s) for s in tf.SIGNALS}})
    (tmp_path / "b.json").write_text(json.dumps(trial.meta))
    assert read_trial_mat(tmp_path / "b.mat").perturbed_dof == 1
    (tmp_path / "b.json").unlink()
    with pytest.raises(MatFileError, match="no variable 'meta' and no b.json"):
        read_trial_mat(tmp_path / "b.mat")


def _save(tmp_path, trial, **override):
    data = {"t": trial.t, "meta": json.dumps(trial.meta),
            **{s: trial.signal(s) for s in tf.SIGNALS}}
    data.update(override)
    data = {k: v for k, v in data.items() if v is not None}
    sio.savemat(tmp_path / "c.mat", data)
    return tmp_path / "c.mat"


@pytest.mark.parametrize("override, error, match", [
    ({"theta": None}, MatFileError, "variable 'theta' missing"),
    ({"tau_h": np.zeros((9000, 3))}, MatFileError, r"'tau_h' has shape \(9000, 3\)"),
    ({"meta": "{not json"}, MatFileError, "JSON does not parse"),
    ({"t": np.arange(9000) / 500.0}, tf.TrialFormatError, "disagrees with column 't'"),
    ({"t": np.arange(9000.0)[::-1] / 1000}, tf.TrialFormatError, "'t'"),
    ({"theta": np.full((9000, 2), np.nan)}, tf.TrialFormatError, "non-finite"),
    ({"tau_delta": np.zeros((9000, 2))}, tf.TrialFormatError, "identically zero"),
])
def test_refusals_name_the_file_and_variable(tmp_path, override, error, match):
    path = _save(tmp_path, make_trial(), **override)
    with pytest.raises(error, match=match) as info:
        read_trial_mat(path)
    assert "c.mat" in str(info.value)


def test_refuses_bad_perturbed_dof_and_short_trial(tmp_path):
    trial = make_trial()
    trial.meta["perturbed_dof"] = 3
    with pytest.raises(tf.TrialFormatError, match="perturbed_dof"):
        read_trial_mat(_save(tmp_path, trial))
    short = make_trial(n=5000)
    with pytest.raises(tf.TrialFormatError, match="fewer than one spectral segment"):
        read_trial_mat(_save(tmp_path, short))


def test_not_a_mat_file(tmp_path):
    (tmp_path / "d.mat").write_text("hello")
    with pytest.raises(MatFileError, match="not a readable MATLAB file"):
        read_trial_mat(tmp_path / "d.mat")


def test_folder_reads_csv_and_mat_and_refuses_ambiguous_stems(tmp_path):
    tf.write_trial(tmp_path / "one", make_trial(k=1))
    write_trial_mat(tmp_path / "two.mat", make_trial(k=2))
    trials = read_trials(tmp_path)
    assert sorted(t.perturbed_dof for t in trials) == [1, 2]
    write_trial_mat(tmp_path / "one.mat", make_trial(k=1))
    with pytest.raises(tf.TrialFormatError, match="both as .csv and .mat"):
        read_trials(tmp_path)
