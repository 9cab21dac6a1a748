"""A MATLAB struct array of trials with more than one row and column (2x2) is refused
naming what was found (its size, element count, fields) and what is accepted; the same
trials as a 1-by-N struct array (what the message suggests) are read."""

import json

import numpy as np
import pytest
import scipy.io as sio

import trialformat as tf
from trialformat.matlab import MatFileError, read_trials_mat


def _trial():
    t = np.arange(3000) / 1000.0
    th = 0.01 * np.sin(2 * np.pi * 2 * t)
    meta = {"format": tf.FORMAT, "fs": 1000.0, "n_dof": 1, "perturbed_dof": 1,
            "perturbation": {"kind": "position"}}
    return t, th, 50 * th, meta


def _structs(shape):
    t, th, tq, meta = _trial()
    S = np.zeros(shape, dtype=[("t", "O"), ("theta", "O"), ("tau_h", "O"), ("meta", "O")])
    for e in S.flat:
        e["t"], e["theta"], e["tau_h"], e["meta"] = t, th[:, None], tq[:, None], json.dumps(meta)
    return S


def test_2x2_struct_array_refused_saying_what_and_what_works(tmp_path):
    path = tmp_path / "grid.mat"
    sio.savemat(path, {"S": _structs((2, 2))})
    with pytest.raises(MatFileError) as exc:
        tf.read_trials(path, min_samples=256)
    msg = str(exc.value)
    assert "struct array 'S' is 2x2 (4 elements with fields meta, t, tau_h, theta)" in msg
    assert "1-by-N (or N-by-1) struct array" in msg and "S(:)'" in msg
    assert "neither a trial" not in msg


def test_the_suggested_1_by_n_layout_reads(tmp_path):
    path = tmp_path / "row.mat"
    sio.savemat(path, {"S": _structs((2, 2)).reshape(1, -1, order="F")})  # S(:)'
    trials = read_trials_mat(path, min_samples=256)
    assert [t.name for t in trials] == [f"row.S({i})" for i in range(1, 5)]
    assert all(t.n_samples == 3000 for t in trials)
