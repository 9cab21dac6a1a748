"""Issue 22 item 3: units read wherever a file states them (trialformat.units).

The independent answer is the trial as written in SI: a copy stored in degrees / N mm with
the unit stated must read back to it."""

import json

import numpy as np
import pytest

import trialformat as tf
from estimation.synthetic import position_trial

matio = pytest.importorskip("matio")
from matio.utils.matclass import MatlabOpaque  # noqa: E402

N = 9000


def _si_trial():
    return position_trial(K=80.0, B=1.2, I=0.012, duration_s=N / 1000, seed=3,
                          record_reference=False, name="a")


def _rewrite_header(csv, mapping):
    text = csv.read_text().splitlines()
    head = text[0].split(",")
    head = [mapping.get(h, h) for h in head]
    csv.write_text("\n".join([",".join(head)] + text[1:]) + "\n")


def _scale_columns(trial, theta=1.0, tau=1.0):
    t = tf.Trial(meta=dict(trial.meta), name=trial.name, t=trial.t,
                 theta=trial.theta * theta, tau_h=trial.tau_h * tau)
    return t


def test_column_header_units_are_applied(tmp_path):
    si = _si_trial()
    stored = _scale_columns(si, theta=180 / np.pi, tau=1000.0)
    csv = tf.write_trial(tmp_path / "a", stored)
    _rewrite_header(csv, {"theta[1]": "theta[1] (deg)", "tau_h[1]": "tau_h[1] [N mm]"})
    back = tf.read_trial(csv, min_samples=1000)
    np.testing.assert_allclose(back.theta, si.theta, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(back.tau_h, si.tau_h, rtol=1e-12, atol=1e-15)
    assert back.meta["units_read"]["theta[1]"]["unit"] == "deg"
    assert back.meta["units_read"]["tau_h[1]"]["stated_by"] == "column header"


def test_metadata_units_apply_to_every_channel_they_name(tmp_path):
    si = _si_trial()
    stored = _scale_columns(si, theta=180 / np.pi)
    stored.meta["units"] = {"theta": "degrees", "t": "s"}
    csv = tf.write_trial(tmp_path / "a", stored)
    back = tf.read_trial(csv, min_samples=1000)
    np.testing.assert_allclose(back.theta, si.theta, rtol=1e-12, atol=1e-15)
    assert "units" not in back.meta and back.meta["units_read"]["theta[1]"]["unit"] == \
        "degrees"
    again = tf.read_trial(tf.write_trial(tmp_path / "b", back), min_samples=1000)
    np.testing.assert_allclose(again.theta, si.theta, rtol=1e-12)  # not converted twice
    assert "units_read" not in again.meta  # written in SI: nothing stated, nothing applied


def test_an_unknown_or_conflicting_unit_is_refused_by_name(tmp_path):
    si = _si_trial()
    si.meta["units"] = {"theta": "furlong"}
    csv = tf.write_trial(tmp_path / "a", si)
    with pytest.raises(tf.TrialFormatError, match=r"a\.csv: column theta\[1\]: unit "
                                                  r"'furlong' is not known"):
        tf.read_trial(csv, min_samples=1000)
    si.meta["units"] = {"theta": "rad"}
    csv = tf.write_trial(tmp_path / "b", si)
    _rewrite_header(csv, {"theta[1]": "theta[1] (deg)"})
    with pytest.raises(tf.TrialFormatError, match=r"states 'deg' but key 'units.theta'"):
        tf.read_trial(csv, min_samples=1000)


def _cell(strings):
    c = np.empty((1, len(strings)), dtype=object)
    for i, s in enumerate(strings):
        c[0, i] = np.array([s])
    return c


def test_nldat_chanunits_deg_is_read_as_degrees(tmp_path):
    si = _si_trial()
    data = np.column_stack([si.theta[:, 0] * 180 / np.pi, si.tau_h[:, 0]])
    obj = MatlabOpaque({"dataSet": data, "chanNames": _cell(["pos1", "tq1"]),
                        "chanUnits": _cell(["(deg)", "Nm"]),
                        "domainIncr": np.array([[0.001]]),
                        "domainStart": np.array([[0.0]]), "comment": np.array(["t"])},
                       "nldat")
    path = tmp_path / "rec.mat"
    matio.save_to_mat(str(path), {"z": obj}, version="v7")
    (trial,) = tf.read_trials(path, min_samples=1000)
    np.testing.assert_allclose(trial.theta, si.theta, rtol=1e-12, atol=1e-15)
    assert trial.meta["units_read"]["theta[1]"] == {
        "unit": "deg", "stated_by": "chanUnits of z", "factor": np.pi / 180}
    assert "tau_h[1]" in trial.meta["units_read"]  # "Nm": stated, factor 1


def test_estimate_records_the_units_it_read(tmp_path, capsys):
    from estimation.cli import main
    si = position_trial(K=80.0, B=1.2, I=0.012, duration_s=30, seed=3, name="a")
    stored = tf.Trial(meta=dict(si.meta), name="a", t=si.t, theta=si.theta * 180 / np.pi,
                      tau_h=si.tau_h, theta_ref=si.theta_ref * 180 / np.pi)
    stored.meta["units"] = {"theta": "deg", "theta_ref": "deg"}
    tf.write_trial(tmp_path / "in" / "a", stored)
    out = tmp_path / "r.json"
    assert main(["estimate", str(tmp_path / "in"), "--json", str(out)]) == 0
    (result,) = json.loads(out.read_text())
    assert result["parameters"]["K"]["value"][0][0] == pytest.approx(80.0, rel=0.05)
    assert result["corrections"]["units_read"]["a"]["theta[1]"]["unit"] == "deg"


def test_a_header_tail_that_is_no_unit_stays_an_extra_column(tmp_path):
    si = _si_trial()
    csv = tf.write_trial(tmp_path / "a", si)
    text = csv.read_text().splitlines()
    text = [text[0] + ",tau_h[1] (raw)"] + [line + ",0" for line in text[1:]]
    csv.write_text("\n".join(text) + "\n")
    back = tf.read_trial(csv, min_samples=1000)
    np.testing.assert_array_equal(back.tau_h, si.tau_h)
    assert "units_read" not in back.meta
