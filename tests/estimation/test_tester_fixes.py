"""Defects an outside tester found in ``estimate`` / ``figures`` (each test fails without
its fix): angles in degrees, constant signals, --torque-sign recorded, reflex advice the
CLI can follow, the --nperseg hint, one-joint I and the band in the messages, --window."""

import json
import re

import numpy as np
import pytest

import trialformat as tf
from estimation.synthetic import position_trial
from orchestrator.cli import main

ANKLE = dict(duration_s=20.0, fs=1000.0, K=80.0, B=1.2, I=0.012)


def _trial(**kw):
    return position_trial(**{**ANKLE, **kw}, seed=8)


def _write(folder, name, trial):
    folder.mkdir(parents=True, exist_ok=True)
    tf.write_trial(folder / name, trial)
    return folder / f"{name}.csv"


def test_angles_in_degrees_are_named_with_the_k_in_radians(tmp_path, capsys):
    trial = _trial()
    deg = tf.Trial(**{**trial.__dict__, "theta": np.degrees(trial.theta)})
    _write(tmp_path, "deg", deg)
    main(["estimate", str(tmp_path / "deg.csv")])
    out = capsys.readouterr().out
    assert "angles in degrees? deg: theta[1]" in out, out
    k = float(re.search(r"K about ([\d.]+)", out).group(1))
    assert abs(k - ANKLE["K"]) < 0.1 * ANKLE["K"], k  # the K in rad the warning names
    assert "absolute angles?" not in out
    _write(tmp_path / "rad", "rad", trial)
    main(["estimate", str(tmp_path / "rad" / "rad.csv")])
    assert "angles in degrees" not in capsys.readouterr().out
