"""NLID ``nldat`` objects in .mat files (trialformat.nlid), written here by mat-io, and the
measured ankle recordings of ../shared/data/reklab-ankle when present."""

import json
from pathlib import Path

import numpy as np
import pytest

import trialformat as tf
from trialformat import MatFileError

matio = pytest.importorskip("matio")
from matio.utils.matclass import MatlabOpaque  # noqa: E402

# ../shared beside the clone (CI); ../../shared for a git worktree kept one level deeper
SHARED = next((p for p in (Path(__file__).resolve().parents[k] / "shared" / "data" /
                           "reklab-ankle" / "experimental_data.mat" for k in (3, 4))
               if p.is_file()), Path(__file__).resolve().parents[3] / "shared")
N = 9000


def _cell(strings):
    c = np.empty((1, len(strings)), dtype=object)
    for i, s in enumerate(strings):
        c[0, i] = np.array([s])
    return c


def _nldat(data, names, incr=0.001, comment="test"):
    return MatlabOpaque({"dataSet": np.asarray(data, dtype=float), "chanNames": _cell(names),
                         # units in channel order (they are read: issue 22)
                         "chanUnits": _cell([
                             "Nm" if n.lower().startswith(("tq", "moment")) else "rad"
                             for n in names]),
                         "domainIncr": np.array([[incr]]), "domainStart": np.array([[0.0]]),
                         "comment": np.array([comment])}, "nldat")


def _signals(seed):
    rng = np.random.default_rng(seed)
    pos = 0.01 * rng.standard_normal(N)
    return pos, 50 * pos + 0.1 * rng.standard_normal(N)


@pytest.fixture(params=["v7", "v7.3"])
def two_objects(tmp_path, request):
    pos_a, tq_a = _signals(1)
    pos_b, tq_b = _signals(2)
    path = tmp_path / "rec.mat"
    matio.save_to_mat(str(path), {"z_a": _nldat(np.column_stack([pos_a, tq_a]), ["pos1", "tq1"]),
                                  "z_b": _nldat(np.column_stack([tq_b, pos_b]), ["tq1", "pos1"],
                                                incr=0.002),
                                  "note": np.arange(3.0)}, version=request.param)
    return path, (pos_a, tq_a), (pos_b, tq_b)


def test_one_trial_per_object(two_objects):
    path, (pos_a, tq_a), (pos_b, tq_b) = two_objects
    with pytest.warns(UserWarning, match="filled from the documented 1-joint defaults"):
        trials = tf.read_trials(path, min_samples=1000)
    assert [t.name for t in trials] == ["z_a", "z_b"]
    a, b = trials
    assert a.fs == 1000.0 and b.fs == 500.0 and a.n_dof == 1
    np.testing.assert_array_equal(a.theta[:, 0], pos_a)
    np.testing.assert_array_equal(a.tau_h[:, 0], tq_a)
    np.testing.assert_array_equal(b.theta[:, 0], pos_b)  # mapped by name, not by column
    np.testing.assert_array_equal(b.tau_h[:, 0], tq_b)
    assert a.perturbation_kind == "position" and a.theta_ref is None and a.tau_delta is None
    assert "NLID nldat rec.mat:z_a (test)" in a.meta["source"]
    one = tf.read_trial(f"{path}:z_b", min_samples=1000)
    assert one.name == "z_b" and one.fs == 500.0
    with pytest.raises(MatFileError, match=r"holds 2 nldat recordings \(z_a, z_b\).*rec.mat:z_a"):
        tf.read_trial(path, min_samples=1000)
    with pytest.raises(MatFileError, match="no nldat variable 'z_c'.*z_a, z_b"):
        tf.read_trial(f"{path}:z_c", min_samples=1000)


def test_sidecar_maps_channels_and_sign(tmp_path):
    pos, tq = _signals(3)
    path = tmp_path / "exp.mat"
    matio.save_to_mat(str(path), {"r1": _nldat(np.column_stack([pos, tq, tq]),
                                               ["ang", "moment", "emg"])}, version="v7")
    with pytest.raises(MatFileError, match=r"no channel maps to theta\[j\].*'ang', 'moment'"):
        tf.read_trials(path, min_samples=1000)
    path.with_suffix(".json").write_text(json.dumps({
        "channels": {"ang": "theta[1]", "moment": "tau_h[1]"}, "torque_sign": -1,
        "meta": {"condition": "relaxed"}, "variables": {"r1": {"meta": {"posture_deg": [5]}}}}))
    t, = tf.read_trials(path, min_samples=1000)
    np.testing.assert_array_equal(t.tau_h[:, 0], -tq)  # the declared sign applied
    assert t.meta["condition"] == "relaxed" and t.meta["posture_deg"] == [5]
    assert t.meta["sensors"]["torque_sign"] == -1 and "emg" in t.extra
    path.with_suffix(".json").write_text(json.dumps({"channels": {"ang": "angle[1]"}}))
    with pytest.raises(MatFileError, match=r"channels.ang' must be one of tau_delta\[j\], theta\[j\]"):
        tf.read_trials(path, min_samples=1000)
    path.with_suffix(".json").write_text(json.dumps({"torque_sign": 2}))
    with pytest.raises(MatFileError, match="'torque_sign' must be 1 or -1, got 2"):
        tf.read_trials(path, min_samples=1000)
    path.with_suffix(".json").write_text(json.dumps({"fs": 1000}))
    with pytest.raises(MatFileError, match=r"unknown key\(s\) \['fs'\].*under 'meta'"):
        tf.read_trials(path, min_samples=1000)


def test_sensors_block_of_the_sidecar_declares_the_sign_as_the_warning_says(tmp_path):
    """``{"sensors": {"torque_sign": -1}}``, the form the torque-sign warning names."""
    pos, tq = _signals(3)
    path = tmp_path / "exp.mat"
    matio.save_to_mat(str(path), {"r1": _nldat(np.column_stack([pos, tq]), ["pos1", "tq1"])},
                      version="v7")
    path.with_suffix(".json").write_text(json.dumps(
        {"sensors": {"torque_sign": -1, "torque_resolution_nm": 0.01}}))
    t, = tf.read_trials(path, min_samples=1000)
    np.testing.assert_array_equal(t.tau_h[:, 0], -tq)
    assert t.meta["sensors"]["torque_resolution_nm"] == 0.01
    path.with_suffix(".json").write_text(json.dumps({"sensors": {"torque_sign": -1},
                                                     "torque_sign": 1}))
    with pytest.raises(MatFileError, match="'torque_sign' 1 and 'sensors.torque_sign' -1"):
        tf.read_trials(path, min_samples=1000)


def test_bad_objects_and_foreign_files_are_refused_with_their_contents(tmp_path):
    pos, tq = _signals(4)
    path = tmp_path / "bad.mat"
    matio.save_to_mat(str(path), {"z": _nldat(np.column_stack([pos, tq]), ["pos1", "tq1"],
                                              incr=0.0)}, version="v7")
    with pytest.raises(MatFileError, match="variable 'z' .*'domainIncr' must be a positive"):
        tf.read_trials(path, min_samples=1000)
    other = tmp_path / "other.mat"
    from scipy import io as sio
    sio.savemat(other, {"angle": pos, "torque": tq})
    with pytest.raises(MatFileError, match=r"neither a trial .* nor NLID nldat.*angle \(1x9000 "
                                           r"double\), torque \(1x9000 double\)"):
        tf.read_trials(other, min_samples=1000)
    part = tmp_path / "part.mat"
    sio.savemat(part, {"t": np.arange(N) / 1000.0, "angle": pos,
                       "meta": json.dumps({"n_dof": 1, "fs": 1000.0})})
    with pytest.raises(MatFileError, match=r"variable 'tau_delta' missing .*the file holds t "
                                           r"\(9000 float64\), angle \(9000 float64\), meta"):
        tf.read_trials(part, min_samples=1000)


def test_folder_with_nldat_and_names_repeated_across_files(tmp_path):
    pos, tq = _signals(5)
    for stem in ("day1", "day2"):
        matio.save_to_mat(str(tmp_path / f"{stem}.mat"),
                          {"z_pf": _nldat(np.column_stack([pos, tq]), ["pos1", "tq1"])},
                          version="v7")
    with pytest.warns(UserWarning):
        trials = tf.read_trials(tmp_path, min_samples=1000)
    assert [t.name for t in trials] == ["day1:z_pf", "day2:z_pf"]


needs_shared = pytest.mark.skipif(not SHARED.is_file(), reason=f"the measured ankle "
                                  f"recordings are not at ../shared ({SHARED.name} absent)")


@needs_shared
def test_the_five_ankle_recordings():
    with pytest.warns(UserWarning):
        trials = tf.read_trials(SHARED)
    assert [t.name for t in trials] == ["z_df", "z_pf", "z_df2", "z_df3", "z_pf2"]
    for t in trials:
        assert t.fs == 1000.0 and t.n_samples == 60000 and t.n_dof == 1
        assert t.perturbation_kind == "position"
        assert 0.01 < t.theta.std() < 0.03  # about 0.015 rad (the data's README)


@needs_shared
def test_estimate_reads_the_file_and_its_folder(capsys):
    from orchestrator.cli import main
    for source in (SHARED, SHARED.parent):
        assert main(["estimate", str(source)]) == 0
        out = capsys.readouterr().out
        for name in ("z_df:", "z_pf:", "z_df2:", "z_df3:", "z_pf2:"):
            assert name in out


# ------------------------------------------------- auxiliary variables (scheduling, issue 20)


def _one(values, channel, units, incr=0.001, start=0.0):
    """A one-channel nldat object (the NLID lab's scheduling variable ``sv``)."""
    return MatlabOpaque({"dataSet": np.asarray(values, dtype=float)[:, None],
                         "chanNames": _cell([channel]), "chanUnits": _cell([units]),
                         "domainIncr": np.array([[incr]]), "domainStart": np.array([[start]]),
                         "comment": np.array(["Default comment"])}, "nldat")


@pytest.fixture(params=["v7", "v7.3"])
def pilot_like(tmp_path, request):
    """The moving-ankle recording's layout: io (posPert1, tqPert1) and sv, plus a second
    one-channel variable of another length."""
    pos, tq = _signals(6)
    sv = 0.3 * np.sin(2 * np.pi * 0.06 * np.arange(N) / 1000.0)
    path = tmp_path / "pilot.mat"
    matio.save_to_mat(str(path), {
        "io": _nldat(np.column_stack([pos, tq]), ["posPert1", "tqPert1"]),
        "sv": _one(sv, "Scheduling Variable (SV) - Ankle Position (rad)", "(rad)"),
        "emg": _one(sv[:5000], "TA EMG", "Default Units")}, version=request.param)
    return path, pos, tq, sv


def test_auxiliary_variables_are_columns_of_the_recording(pilot_like):
    path, pos, tq, sv = pilot_like
    with pytest.warns(UserWarning) as caught:
        trial = tf.read_trial(path, min_samples=1000)  # one recording: io
    assert trial.name == "io"
    np.testing.assert_array_equal(trial.theta[:, 0], pos)  # posPert1 -> theta[1]
    np.testing.assert_array_equal(trial.tau_h[:, 0], tq)  # tqPert1 -> tau_h[1]
    np.testing.assert_array_equal(trial.extra["sv"], sv)
    assert "emg" not in trial.extra
    assert trial.meta["auxiliary"]["sv"] == {
        "units": "rad", "description": "Scheduling Variable (SV) - Ankle Position (rad)",
        "source": "nldat variable 'sv' of pilot.mat"}
    assert trial.meta["auxiliary"]["emg"]["skipped"] == (
        "5000 samples at 1000 Hz, the recording 9000 at 1000 Hz")
    assert any("pilot.mat:io: nldat variable 'emg' of pilot.mat not attached (5000 samples"
               in str(w.message) for w in caught)
    s = tf.scheduling_of(trial)
    assert (s.name, s.units, s.source) == ("sv", "rad", "nldat variable 'sv' of pilot.mat")
    assert "taken by default" in s.note
    with pytest.raises(tf.SchedulingError, match=r"'emg' requested.*could not be attached: "
                                                 r"5000 samples"):
        tf.scheduling_of(trial, "emg")
    with pytest.warns(UserWarning):
        one, = tf.read_trials(f"{path}:io", min_samples=1000)
    assert "sv" in one.extra
    with pytest.raises(MatFileError, match=r"'sv' is an auxiliary variable.*pilot.mat:io"):
        tf.read_trial(f"{path}:sv", min_samples=1000)


def test_a_channel_named_scheduling_and_the_sidecar_key(tmp_path):
    pos, tq = _signals(7)
    ramp = np.linspace(0.0, 5.0, N)
    path = tmp_path / "bg.mat"
    matio.save_to_mat(str(path), {"z": _nldat(np.column_stack([pos, tq]), ["pos", "tq"]),
                                  "bg": _one(ramp, "scheduling: background torque", "Nm"),
                                  "late": _one(ramp, "x", "", start=1.0)}, version="v7")
    with pytest.warns(UserWarning, match="'late' of bg.mat not attached.*starts at 1 s"):
        trial = tf.read_trial(path, min_samples=1000)
    s = tf.scheduling_of(trial)
    assert (s.name, s.units) == ("bg", "Nm") and "taken by default" in s.note
    path.with_suffix(".json").write_text(json.dumps({"scheduling": "time"}))
    with pytest.warns(UserWarning):
        trial = tf.read_trial(path, min_samples=1000)
    s = tf.scheduling_of(trial)
    assert s.name == "time" and s.note is None


def test_a_file_of_auxiliary_variables_only_is_refused_as_before(tmp_path):
    path = tmp_path / "only.mat"
    matio.save_to_mat(str(path), {"sv": _one(np.arange(N, dtype=float), "ankle", "rad")},
                      version="v7")
    with pytest.raises(MatFileError, match=r"no channel maps to theta\[j\].*'ankle'"):
        tf.read_trials(path, min_samples=1000)


def test_suffixed_names_that_collide_are_refused_with_the_mapping_to_declare(tmp_path):
    pos, tq = _signals(8)
    path = tmp_path / "two.mat"
    matio.save_to_mat(str(path), {"z": _nldat(np.column_stack([pos, pos, tq]),
                                              ["pos1", "posPert1", "tqPert1"])}, version="v7")
    with pytest.raises(MatFileError, match=r"'pos1' and 'posPert1' both map to theta\[1\]; "
                                           r"declare the mapping"):
        tf.read_trials(path, min_samples=1000)
