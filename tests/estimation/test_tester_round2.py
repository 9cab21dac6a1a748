"""Defects of the tester's second round (each test fails without its fix): a small
perturbation stored in degrees, the band-sensitivity digits, the switching count, the
moving joint's band advice that works when followed."""

import re

import numpy as np
import pytest

import trialformat as tf
from estimation.synthetic import position_trial
from orchestrator.cli import main

ANKLE = dict(duration_s=20.0, fs=1000.0, K=80.0, B=1.2, I=0.012)


def _deg(trial):
    return tf.Trial(**{**trial.__dict__, "theta": np.degrees(trial.theta),
                       "theta_ref": np.degrees(trial.theta_ref)})


def test_a_small_perturbation_in_degrees_is_named(tmp_path, capsys):
    trial = position_trial(**ANKLE, ref_rms_rad=0.005, seed=8, name="deg")
    tf.write_trial(tmp_path / "deg", _deg(trial))
    main(["estimate", str(tmp_path / "deg.csv"), "--segments", "0"])
    out = capsys.readouterr().out
    k = float(re.search(r"K=([\d.]+)±", out).group(1))
    assert k < 2, out  # the fit in "rad" of an angle in degrees: 80 / 57.3
    m = re.search(r"angles in degrees\? deg: theta\[1\] gives K = [\d.]+ N m/rad and I = "
                  r"[\d.e-]+ kg m\^2, both implausibly small.*57\.3.*K about ([\d.]+) N m/rad"
                  r".*\"units\": \{\"theta\": \"deg\", \"theta_ref\": \"deg\"\} or the CSV "
                  r"headers theta\[1\] \(deg\) and theta_ref\[1\] \(deg\)",
                  out)
    assert m, out
    assert abs(float(m.group(1)) - ANKLE["K"]) < 0.15 * ANKLE["K"]
    # declared in a header: read in rad, the right K, no warning
    text = (tmp_path / "deg.csv").read_text().replace("theta[1],", "theta[1] (deg),", 1)
    (tmp_path / "hdr").mkdir()
    (tmp_path / "hdr" / "deg.csv").write_text(text)
    (tmp_path / "hdr" / "deg.json").write_text((tmp_path / "deg.json").read_text())
    main(["estimate", str(tmp_path / "hdr" / "deg.csv"), "--segments", "0"])
    out = capsys.readouterr().out
    assert "angles in degrees" not in out, out
    assert abs(float(re.search(r"K=([\d.]+)±", out).group(1)) - 80) < 12, out


def test_the_example_ankle_in_radians_is_not_told_degrees(tmp_path, capsys):
    from estimation.examples import write_ankle
    write_ankle(tmp_path)
    main(["estimate", str(tmp_path), "--segments", "0"])
    out = capsys.readouterr().out
    assert "relaxed" in out and "angles in degrees" not in out, out


def test_band_sensitive_values_print_with_digits_enough_to_differ():
    from types import SimpleNamespace
    from estimation.lab import sensitivity_warnings
    one = np.ones((1, 1))
    fit = SimpleNamespace(K=80 * one, B=1.2 * one, M=0.012 * one, K_ci=0.5 * one,
                          B_ci=1e-5 * one, M_ci=1e-4 * one)
    variants = [{"band_hz": [1.0, 30.0], "weighting": "smoothed",
                 "K": [[80.2]], "B": [[1.20004]], "M": [[0.012]],
                 "K_ci": [[0.5]], "B_ci": [[1e-5]], "M_ci": [[1e-4]]}]
    sens = {"variants": variants,
            "range": {"K": [[[80.0]], [[80.2]]], "B": [[[1.2]], [[1.20004]]],
                      "M": [[[0.012]], [[0.012]]]},
            "exceeds": {"K": [[False]], "B": [[True]], "M": [[False]]}}
    out = sensitivity_warnings(SimpleNamespace(sensitivity=sens, n_dof=1, fit=fit))
    assert len(out) == 1, out
    assert "moves over 1.2...1.20004 with the band" in out[0], out
    assert "1-30 Hz smoothed: 1.20004" in out[0], out
    from estimation.numbers import distinct
    assert distinct([1.23456, 1.23456]) == ["1.235", "1.235"]  # equal values stay short
    assert distinct([80.0, 80.2]) == ["80", "80.2"]
