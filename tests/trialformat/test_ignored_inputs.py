"""Issue 22 item 4: inputs a reader used to ignore silently are used or refused by name."""

import json

import numpy as np
import pytest

import trialformat as tf
from estimation.synthetic import position_trial

N = 9000


def _trial():
    return position_trial(K=80.0, B=1.2, I=0.012, duration_s=N / 1000, seed=5,
                          record_reference=False, name="a")


def _rename(csv, mapping):
    lines = csv.read_text().splitlines()
    head = [mapping.get(h, h) for h in lines[0].split(",")]
    csv.write_text("\n".join([",".join(head)] + lines[1:]) + "\n")


def _meta(csv, **keys):
    path = csv.with_suffix(".json")
    meta = json.loads(path.read_text())
    meta.update(keys)
    path.write_text(json.dumps(meta))


def test_channels_in_a_csv_trials_json_map_its_columns(tmp_path):
    t = _trial()
    csv = tf.write_trial(tmp_path / "a", t)
    _rename(csv, {"t": "time", "theta[1]": "pos (rad)", "tau_h[1]": "tq"})
    _meta(csv, channels={"time": "t", "pos": "theta[1]", "tq": "tau_h[1]"})
    back = tf.read_trial(csv, min_samples=1000)
    np.testing.assert_array_equal(back.theta, t.theta)
    np.testing.assert_array_equal(back.tau_h, t.tau_h)
    assert back.meta["channels_read"]["pos"] == "theta[1]"


def test_channels_naming_no_column_or_no_target_is_refused(tmp_path):
    csv = tf.write_trial(tmp_path / "a", _trial())
    _meta(csv, channels={"angle": "theta[1]"})
    with pytest.raises(tf.TrialFormatError, match=r"a\.json: key 'channels' names \['angle'\]"):
        tf.read_trial(csv, min_samples=1000)
    _meta(csv, channels={"theta[1]": "pos"})
    with pytest.raises(tf.TrialFormatError, match=r"key 'channels.theta\[1\]' must be one of"):
        tf.read_trial(csv, min_samples=1000)


def test_top_level_torque_sign_is_the_sensors_sign(tmp_path):
    t = _trial()
    t.meta.setdefault("sensors", {}).pop("torque_sign", None)
    csv = tf.write_trial(tmp_path / "a", t)
    _meta(csv, torque_sign=-1)
    back = tf.read_trial(csv, min_samples=1000)
    np.testing.assert_array_equal(back.tau_h, -t.tau_h)
    assert back.meta["sensors"]["torque_sign"] == -1 and "torque_sign" not in back.meta
    _meta(csv, torque_sign=-1, sensors={"torque_sign": 1})
    with pytest.raises(tf.TrialFormatError, match=r"key 'torque_sign' \(-1\) and key "
                                                  r"'sensors.torque_sign' \(1\) disagree"):
        tf.read_trial(csv, min_samples=1000)


def test_a_json_beside_a_mat_with_its_own_meta_is_refused(tmp_path):
    path = tf.write_trial_mat(tmp_path / "m.mat", _trial())
    tf.read_trial(path, min_samples=1000)  # alone: read
    (tmp_path / "m.json").write_text('{"condition": "relaxed"}')
    with pytest.raises(tf.MatFileError, match=r"m\.json: not read, .*m\.mat holds its own "
                                              r"metadata"):
        tf.read_trial(path, min_samples=1000)
