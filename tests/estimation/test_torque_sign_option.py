"""``--torque-sign``: the sign declared on the command line, for recordings one cannot add
a sidecar to (a read-only copy of a lab's .mat), as the torque-sign warning suggests."""

import re

import trialformat as tf
from estimation.synthetic import position_trial
from orchestrator.cli import main

ANKLE = dict(duration_s=20.0, fs=1000.0, K=80.0, B=1.2, I=0.012)


def _write(tmp_path):
    trial = position_trial(**ANKLE, seed=8)
    flipped = tf.Trial(**{**trial.__dict__, "tau_h": -trial.tau_h})
    tf.write_trial(tmp_path / "rec", flipped)
    return tmp_path / "rec.csv"




def test_the_warning_names_the_option_and_the_option_gives_the_physical_answer(tmp_path, capsys):
    _write(tmp_path)
    main(["estimate", str(tmp_path / "rec.csv")])
    printed = capsys.readouterr().out
    assert "torque sign reversed?" in printed and "--torque-sign -1" in printed
    main(["estimate", str(tmp_path / "rec.csv"), "--torque-sign", "-1"])
    printed = capsys.readouterr().out
    assert "torque sign reversed?" not in printed, printed
    k, ci = (float(v) for v in re.search(r"K=([-\d.]+)±([\d.]+)", printed).groups())
    assert abs(k - ANKLE["K"]) < ci, (k, ci)  # the true K inside its 95 % interval


def test_the_lab_report_states_the_sign_given_on_the_command_line(tmp_path):
    _write(tmp_path)
    out = tmp_path / "report"
    assert main(["figures", str(tmp_path / "rec.csv"), "--out", str(out),
                 "--torque-sign", "-1"]) == 0
    assert "given on the command line" in (out / "parameters.md").read_text().splitlines()[0]
    plain = tmp_path / "plain"
    assert main(["figures", str(tmp_path / "rec.csv"), "--out", str(plain)]) == 0
    assert "given on the command line" not in (plain / "parameters.md").read_text()
