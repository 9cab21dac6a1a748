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


def _constant(trial, column, value):
    x = getattr(trial, column).copy()
    x[:] = value
    return tf.Trial(**{**trial.__dict__, column: x})


@pytest.mark.parametrize("reflex", [[], ["--reflex"]])
@pytest.mark.parametrize("column,value,text", [
    ("tau_h", 1.5, "bad: tau_h[1] is constant (1.5 N m): nothing to estimate"),
    ("theta", 0.1 + 1e-12 * np.arange(20000)[:, None],
     "bad: theta[1] is numerically constant (0.1, range 2e-08 rad): nothing to estimate")])
def test_a_constant_signal_fails_its_recording_only(tmp_path, capsys, column, value, text,
                                                     reflex):
    good = _trial()
    _write(tmp_path, "good", good)
    _write(tmp_path, "bad", _constant(_trial(), column, value))
    status = main(["estimate", str(tmp_path), "--segments", "0"] + reflex)
    cap = capsys.readouterr()
    assert status == 1
    assert f"error: {text}" in cap.err, cap.err
    assert "DLASCL" not in cap.err and "SVD" not in cap.err
    assert re.search(r"good: method=", cap.out), cap.out  # the good recording estimated
    if reflex:
        assert "reflex" in cap.out.lower()


def test_a_singular_reflex_design_is_skipped_not_raised():
    from estimation.reflex import reflex_of_trials
    fitted, skipped = reflex_of_trials([_constant(_trial(), "theta", 0.0)])
    assert not fitted and skipped[0]["kind"] == "constant", skipped
    assert "theta[1] is constant (0 rad)" in skipped[0]["reason"]


def test_torque_sign_is_recorded_in_the_header_the_json_and_results_json(tmp_path, capsys):
    trial = _trial()
    _write(tmp_path / "in", "rec", tf.Trial(**{**trial.__dict__, "tau_h": -trial.tau_h}))
    main(["estimate", str(tmp_path / "in"), "--torque-sign", "-1", "--segments", "0",
          "--json", str(tmp_path / "r.json")])
    assert "torque sign -1 (--torque-sign" in capsys.readouterr().out
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc[0]["options"]["torque_sign"] == -1
    main(["figures", str(tmp_path / "in"), "--out", str(tmp_path / "rep"), "--segments", "0",
          "--torque-sign", "-1"])
    assert "torque sign -1 (--torque-sign" in capsys.readouterr().out
    doc = json.loads((tmp_path / "rep" / "results.json").read_text())
    assert doc["options"]["torque_sign"] == -1
    main(["estimate", str(tmp_path / "in"), "--segments", "0", "--json",
          str(tmp_path / "r.json")])
    assert json.loads((tmp_path / "r.json").read_text())[0]["options"]["torque_sign"] is None


def test_reflex_delay_edge_names_the_option_that_widens_it(tmp_path, capsys):
    from estimation.synthetic_reflex import parallel_cascade_trial
    tf.write_trial(tmp_path / "late", parallel_cascade_trial("late", delay_s=0.2,
                                                             duration_s=30.0, G=6.0))
    args = ["estimate", str(tmp_path / "late.csv"), "--reflex", "--segments", "0"]
    main(args)
    out = capsys.readouterr().out
    assert "delay_ms = 120 is at the edge of its search range 10-120: widen the range " \
           "(e.g. --reflex-delay-ms 10 240" in out, out
    main(args + ["--reflex-delay-ms", "10", "300"])
    out = capsys.readouterr().out
    delay = float(re.search(r"delay=([\d.]+)±", out).group(1))
    assert abs(delay - 200) < 5, out
    assert "edge of its search range" not in out


def test_reflex_range_without_reflex_or_reversed_is_refused(tmp_path, capsys):
    _write(tmp_path, "rec", _trial())
    assert main(["estimate", str(tmp_path / "rec.csv"), "--reflex-delay-ms", "10", "300"]) != 0
    assert "--reflex-delay-ms sets a search range of the reflex fit: add --reflex" in \
        capsys.readouterr().err
    assert main(["estimate", str(tmp_path / "rec.csv"), "--reflex", "--reflex-damping",
                 "2", "1"]) != 0
    assert "--reflex-damping 2 1: LO must be below HI" in capsys.readouterr().err


def test_a_slow_recording_is_told_to_record_faster_not_to_raise_work_fs():
    from estimation import lab
    from estimation.synthetic_reflex import parallel_cascade_trial
    trial = parallel_cascade_trial("slow", duration_s=60.0, fs=99.0, f_max_hz=10.0)
    res = lab.analyse(lab.Unit("slow", [trial], "single recording"),
                      lab.AnalysisOptions(reflex=True, nperseg=1024, segments=0,
                                          sensitivity=False))
    text = " ".join(res.warnings)
    assert "record at 100 Hz or faster" in text and "work_fs" not in text, text


def test_a_short_recording_is_told_the_nperseg_that_works(tmp_path, capsys):
    _write(tmp_path, "fs333", _trial(fs=333.0))  # 20 s: 6660 samples
    assert main(["estimate", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    hint = re.search(r"6660 samples, 20 s: fewer than one spectral segment \(--nperseg "
                     r"8192\): use --nperseg (\d+)", err)
    assert hint, err
    assert main(["estimate", str(tmp_path), "--nperseg", hint.group(1)]) == 0
    out = capsys.readouterr().out
    assert "few Welch averages" not in out and "fs333: method=" in out


def test_a_narrow_band_is_named_as_the_cause_and_one_joint_says_i(tmp_path, capsys):
    _write(tmp_path, "rec", _trial())
    main(["estimate", str(tmp_path / "rec.csv"), "--band", "399", "400"])
    out = capsys.readouterr().out
    assert "M poorly determined" not in out and "non-physical fit: M" not in out
    assert re.search(r"warning: (I|K|B) poorly determined", out), out
    assert "is too short" not in out
    got = re.search(r"fixed time segments not fitted for rec: the band 399-400 Hz is too "
                    r"narrow: .*\(e\.g\. --band ([\d.]+) ([\d.]+)\)", out)
    assert got, out
    main(["estimate", str(tmp_path / "rec.csv"), "--band", *got.groups()])
    assert "fixed time segments not fitted" not in capsys.readouterr().out


def test_window_refused_at_parse_time_naming_valid_ones(tmp_path, capsys):
    from scipy import signal

    from estimation.cli import WINDOW_EXAMPLES
    for name in WINDOW_EXAMPLES:  # every name the refusal offers works
        signal.get_window(name, 16)
    with pytest.raises(SystemExit) as exc:  # argparse: before any file is read
        main(["estimate", str(tmp_path / "absent"), "--window", "nonsense"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "argument --window: 'nonsense' is not a scipy.signal window name" in err
    assert "hamming" in err and "absent" not in err
    _write(tmp_path, "rec", _trial())
    assert main(["estimate", str(tmp_path / "rec.csv"), "--window", "hamming",
                 "--segments", "0"]) == 0


@pytest.mark.parametrize("encoding,text", [("utf-16", "UTF-16 encoded (byte-order mark FF FE)"),
                                           ("utf-16-be", "UTF-16 encoded (NUL bytes"),
                                           ("utf-32", "UTF-32 encoded (byte-order mark FF FE 00 00)")])
def test_a_utf16_csv_is_named_as_such(tmp_path, encoding, text):
    src = _write(tmp_path / "a", "rec", _trial())
    (tmp_path / "rec.csv").write_bytes(src.read_text().encode(encoding))
    (tmp_path / "rec.json").write_text((tmp_path / "a" / "rec.json").read_text())
    with pytest.raises(tf.TrialFormatError, match="save it as UTF-8") as exc:
        tf.read_trial(tmp_path / "rec.csv")
    assert text in str(exc.value) and "missing" not in str(exc.value)
