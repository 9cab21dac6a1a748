"""The scheduling variable (trialformat.scheduling): named, declared, taken by default from
an extra column ``sv`` or from the slow part of a moving angle, and each refusal."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import trialformat as tf
from trialformat import Scheduling, SchedulingError, check_range, narrow_range, scheduling_of
from trialformat.scheduling import MOVING_RATIO, request

FS = 1000.0
N = 20000  # 20 s
T = np.arange(N) / FS
PILOT = next((p for p in (Path(__file__).resolve().parents[k] / "shared" / "data" /
                          "reklab-pilot" / "IEEETBME2022_PilotData_AV_PT1_UT2.mat"
                          for k in (3, 4)) if p.is_file()), None)


def _perturbation(seed=0, std=0.02):
    """Broadband (white) position perturbation of ``std`` rad."""
    return std * np.random.default_rng(seed).standard_normal(N)


def _trial(theta, extra=None, **meta):
    m = {"fs": FS, "n_dof": 1, "perturbation": {"kind": "position"}, **meta}
    return tf.Trial(meta=m, t=T.copy(), theta=np.asarray(theta, float).reshape(N, -1),
                    tau_h=50 * np.asarray(theta, float).reshape(N, -1),
                    extra=dict(extra or {}), name="rec")


def _moving():
    return 0.3 * np.sin(2 * np.pi * 0.06 * T)


def test_a_moving_joint_is_scheduled_on_the_slow_part_of_its_angle():
    truth = _moving()
    s = scheduling_of(_trial(truth + _perturbation()))
    assert s.name == "angle[1]" and s.units == "rad" and s.source.startswith("slow part")
    assert "taken by default" in s.note and "moves beyond its perturbation" in s.note
    inner = slice(2000, N - 2000)  # away from the filter's ends
    # the 0.06 Hz movement passes the 0.5 Hz low-pass; the perturbation's slow part is
    # about 0.02 * sqrt(0.5 / 500) = 6e-4 rad
    assert np.max(np.abs(s.values[inner] - truth[inner])) < 0.005
    assert s.noise_std == pytest.approx(0.02, rel=0.05)
    assert narrow_range(s) is None


def test_a_stationary_joint_has_no_scheduling():
    assert scheduling_of(_trial(_perturbation())) is None
    # a slow movement within a few perturbation std is not "beyond" it either
    small = 0.2 * MOVING_RATIO * 0.02 * np.sin(2 * np.pi * 0.06 * T)
    assert scheduling_of(_trial(small + _perturbation())) is None


def test_absolute_angles_add_the_posture():
    t = _trial(_moving() + _perturbation() + np.deg2rad(30.0), angles="absolute",
               posture_deg=[30.0])
    t.theta = t.theta - np.deg2rad(30.0)  # as the reader returns it: the deviation
    s = scheduling_of(t, "angle")
    assert "posture added" in s.source
    inner = slice(2000, N - 2000)
    np.testing.assert_allclose(s.values[inner], _moving()[inner] + np.deg2rad(30.0),
                               atol=0.005)


def test_requested_and_declared_names():
    sv = np.linspace(1.0, 2.0, N)
    t = _trial(_perturbation(), {"sv": sv, "load": sv[::-1].copy()}, scheduling="load")
    s = scheduling_of(t)  # declared beats the default 'sv'
    assert s.name == "load" and s.note is None and s.source == "column 'load'"
    assert scheduling_of(t, "time").units == "s"
    np.testing.assert_array_equal(scheduling_of(t, "time").values, T)
    t.meta["scheduling"] = {"name": "sv", "units": "N m"}
    s = scheduling_of(t)
    assert (s.name, s.units) == ("sv", "N m")
    np.testing.assert_array_equal(s.values, sv)
    del t.meta["scheduling"]
    s = scheduling_of(t)  # the default: an extra column named sv, with a note
    assert s.name == "sv" and "taken by default" in s.note
    assert request(t, "load").name == "load" and t.meta["scheduling"] == "load"


def test_refusals_name_the_variable_and_what_works():
    sv = np.linspace(1.0, 2.0, N)
    t = _trial(_perturbation(), {"sv": sv})
    with pytest.raises(SchedulingError, match=r"trial 'rec'.*'speed' requested.*available: "
                                              r"sv \(column\); time; angle, angle\[1\]"):
        scheduling_of(t, "speed")
    with pytest.raises(SchedulingError, match=r"'angle\[2\]'.*1 joint\(s\)"):
        scheduling_of(t, "angle[2]")
    t.extra["flat"] = np.full(N, 0.25)
    with pytest.raises(SchedulingError, match=r"'flat'.*constant \(0.25 at every sample\)"):
        scheduling_of(t, "flat")
    bad = sv.copy()
    bad[1234] = np.nan
    bad[5000] = np.inf
    t.extra["gappy"] = bad
    with pytest.raises(SchedulingError, match=r"'gappy'.*NaN at sample 1234 \(0-based; 2 "
                                              r"non-finite"):
        scheduling_of(t, "gappy")
    t.extra["short"] = sv[:100]
    with pytest.raises(SchedulingError, match=r"'short'.*100 values for the trial's 20000"):
        scheduling_of(t, "short")
    t.meta["scheduling"] = {"units": "rad"}
    with pytest.raises(SchedulingError, match=r"metadata key 'scheduling' must be a name"):
        scheduling_of(t)
    t.meta["scheduling"] = "flat"  # declared: refused as requested
    with pytest.raises(SchedulingError, match=r"'flat'.*declared.*constant"):
        scheduling_of(t)


def test_a_bad_default_never_sinks_the_trial():
    sv = np.linspace(1.0, 2.0, N)
    sv[7] = np.nan
    moving = _trial(_moving() + _perturbation(), {"sv": sv})
    s = scheduling_of(moving)  # passed over for the moving angle, said in the note
    assert s.name == "angle[1]" and "'sv' passed over" in s.note and "sample 7" in s.note
    still = _trial(_perturbation(), {"sv": sv})
    with pytest.warns(UserWarning, match=r"no scheduling variable: 'sv' passed over.*NaN"):
        assert scheduling_of(still) is None


def test_a_narrow_range_is_said_or_refused():
    wobble = 10.0 + 0.1 * np.sin(2 * np.pi * 0.06 * T)  # 2 % of its magnitude
    t = _trial(_perturbation(), {"torque_bg": wobble})
    s = scheduling_of(t, "torque_bg")
    assert "less than 5 % of its mean magnitude 10" in narrow_range(s)
    with pytest.raises(SchedulingError, match=r"'torque_bg' of trial 'rec': range too narrow"
                                              r".*keep the time-invariant"):
        check_range(s, t)
    noisy = 0.01 * np.sin(2 * np.pi * 0.06 * T) + _perturbation(1, 0.02)
    s = scheduling_of(_trial(_perturbation(), {"x": noisy}), "x")
    assert "within 5 times its fast part's std" in narrow_range(s)
    # the slow angle of a stationary joint, requested: within its perturbation
    s = scheduling_of(_trial(_perturbation()), "angle")
    assert "within 5 times" in narrow_range(s)
    check_range(scheduling_of(t, "time"))  # time always varies


def test_csv_trial_with_an_sv_column_and_the_json_key(tmp_path):
    theta = _perturbation()
    sv = -0.4 + 0.3 * (1 - np.cos(2 * np.pi * 0.06 * T))
    table = np.column_stack([T, theta, 50 * theta, sv])
    np.savetxt(tmp_path / "rec.csv", table, delimiter=",", header="t,theta[1],tau_h[1],sv",
               comments="", fmt="%.17g")
    meta = {"format": tf.FORMAT, "fs": FS, "n_dof": 1, "perturbation": {"kind": "position"},
            "scheduling": {"name": "sv", "units": "rad"}}
    (tmp_path / "rec.json").write_text(json.dumps(meta))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        trial = tf.read_trial(tmp_path / "rec.csv")
    s = scheduling_of(trial)
    assert (s.name, s.units, s.source, s.note) == ("sv", "rad", "column 'sv'", None)
    np.testing.assert_allclose(s.values, sv, rtol=0, atol=1e-15)
    assert s.describe() == "sv [rad] (column 'sv'): -0.4..0.2 rad"
    meta["scheduling"] = "speed"
    (tmp_path / "rec.json").write_text(json.dumps(meta))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        trial = tf.read_trial(tmp_path / "rec.csv")
    with pytest.raises(SchedulingError, match=r"'speed' declared.*available: sv \(column\)"):
        scheduling_of(trial)


def test_the_dataclass_keeps_the_contract():
    s = Scheduling("time", "s", T, "time", None)
    assert (s.name, s.units, s.source, s.note) == ("time", "s", "time", None)
    with pytest.raises(Exception):
        s.name = "x"  # frozen


@pytest.mark.skipif(PILOT is None, reason="the moving-ankle recording is not at "
                    "../shared/data/reklab-pilot (GPL data, not in the repository)")
def test_the_pilot_recording_reads_with_its_scheduling_variable():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        trial = tf.read_trial(PILOT)  # one recording: sv is attached to io, not a trial
    assert trial.name == "io" and trial.n_samples == 106000
    s = scheduling_of(trial)
    assert (s.name, s.units) == ("sv", "rad") and "taken by default" in s.note
    assert s.source == f"nldat variable 'sv' of {PILOT.name}"
    # the data's README: the ankle moved through -0.41 .. +0.20 rad
    assert s.values.min() == pytest.approx(-0.41, abs=0.01)
    assert s.values.max() == pytest.approx(0.20, abs=0.01)
    assert narrow_range(s) is None
    # io's theta is the perturbation alone: its slow part is no scheduling variable
    assert "within 5 times" in narrow_range(scheduling_of(trial, "angle"))
