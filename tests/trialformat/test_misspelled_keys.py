"""Misspelled metadata keys (lab session tester): an unknown key close to a known one is
named with the key it probably means, and a refusal the default of that key caused says so."""

import json
import warnings

import numpy as np
import pytest

import trialformat as tf
from trialformat import TrialFormatError


def _position_trial(stem, n=1200, **replace):
    """A 1-joint position-perturbation trial (t, theta, tau_h only); ``replace`` renames
    metadata keys ``{old: new}`` and sets others."""
    rng = np.random.default_rng(3)
    cols = {"t": np.arange(n) / 1000.0, "theta[1]": rng.standard_normal(n),
            "tau_h[1]": rng.standard_normal(n)}
    with open(stem.with_suffix(".csv"), "w") as fh:
        fh.write(",".join(cols) + "\n")
        for row in zip(*cols.values()):
            fh.write(",".join(repr(float(v)) for v in row) + "\n")
    meta = tf.default_metadata(1)
    meta["perturbation"] = {"kind": "position"}
    for old, new in replace.items():
        meta[new] = meta.pop(old)
    stem.with_suffix(".json").write_text(json.dumps(meta))
    return stem.with_suffix(".csv")


def _read(path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        trial = tf.read_trial(path, min_samples=1000)
    return trial, [str(w.message) for w in caught]


def test_misspelled_perturbation_named_in_the_refusal_it_caused(tmp_path):
    """The refusal pointed at the CSV's missing columns only."""
    path = _position_trial(tmp_path / "r1", perturbation="perturbaton")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(TrialFormatError, match="missing columns") as info:
            tf.read_trial(path, min_samples=1000)
    text = str(info.value)
    assert "r1.json has the unknown key 'perturbaton': did you mean 'perturbation'?" in text
    assert any("r1.json: unknown key 'perturbaton': did you mean 'perturbation'?"
               in str(w.message) for w in caught)


def test_misspelled_sensors_and_fs_are_named_not_just_filled(tmp_path):
    path = _position_trial(tmp_path / "r2", sensors="sensor", fs="Fs")
    trial, notes = _read(path)
    assert "r2.json: unknown key 'sensor': did you mean 'sensors'?" in notes
    assert "r2.json: unknown key 'Fs': did you mean 'fs'?" in notes


def test_misspelled_nested_key_is_named_dotted(tmp_path):
    path = _position_trial(tmp_path / "r3")
    meta = json.loads(path.with_suffix(".json").read_text())
    meta["sensors"]["torque_sgn"] = -1
    path.with_suffix(".json").write_text(json.dumps(meta))
    _, notes = _read(path)
    assert ("r3.json: unknown key 'sensors.torque_sgn': did you mean 'sensors.torque_sign'?"
            in notes)


def test_fs_default_disagreeing_with_t_says_the_misspelled_key(tmp_path):
    """fs filled (1000 Hz) where the file has "FS": 500 and t at 500 Hz."""
    path = _position_trial(tmp_path / "r4")
    meta = json.loads(path.with_suffix(".json").read_text())
    meta["FS"] = meta.pop("fs")
    path.with_suffix(".json").write_text(json.dumps(meta))
    lines = path.read_text().splitlines()
    rows = [line.split(",") for line in lines[1:]]
    path.write_text("\n".join([lines[0]] + [",".join([repr(i / 500.0)] + r[1:])
                                            for i, r in enumerate(rows)]) + "\n")
    with pytest.raises(TrialFormatError) as info:
        _read(path)
    assert "did you mean 'fs'?" in str(info.value)


def test_extra_keys_far_from_known_ones_and_the_projects_own_keys_say_nothing(tmp_path):
    path = _position_trial(tmp_path / "r5")
    meta = json.loads(path.with_suffix(".json").read_text())
    meta.update(subject="S07", date="2026-12-03", notes="ok", condition="relaxed",
                units_read={}, scheduling=None, device="wrist robot")
    meta["perturbation"]["signal"] = "prbs"
    path.with_suffix(".json").write_text(json.dumps(meta))
    _, notes = _read(path)
    assert not [n for n in notes if "unknown key" in n]
    assert tf.misspelled_keys(tf.default_metadata(2)) == []
    assert tf.misspelled_keys(tf.default_metadata(1)) == []
