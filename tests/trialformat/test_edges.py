"""Files at the edges of the format (issue 16): dotted names, gzip, MATLAB structs, a
header without a newline, absurd sizes, wrong JSON types, binary headers."""

import gzip
import json
import shutil

import numpy as np
import pytest
from scipy import io as sio

import trialformat as tf
from trialformat import MatFileError, TrialFormatError


def make_trial(n_samples=2000, n_dof=2, seed=0):
    rng = np.random.default_rng(seed)
    sig = {s: rng.standard_normal((n_samples, n_dof)) for s in tf.SIGNALS}
    return tf.Trial(meta=tf.default_metadata(n_dof), t=np.arange(n_samples) / 1000.0, **sig)


def read(path):
    return tf.read_trial(path, min_samples=1000)


# ----------------------------------------------------------------------------- dotted names
def test_dotted_name_writes_and_reads_its_own_files(tmp_path):
    a, b = make_trial(seed=1), make_trial(seed=2)
    tf.write_trial(tmp_path / "S1", a)
    tf.write_trial(tmp_path / "S1.dof1", b)  # not cut to S1
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "S1.csv", "S1.dof1.csv", "S1.dof1.json", "S1.json"]
    for name in ("S1.dof1", "S1.dof1.csv", "S1.dof1.json"):
        back = read(tmp_path / name)
        assert back.name == "S1.dof1"
        np.testing.assert_array_equal(back.tau_h, b.tau_h)
    np.testing.assert_array_equal(read(tmp_path / "S1").tau_h, a.tau_h)
    assert [t.name for t in tf.read_trials(tmp_path, min_samples=1000)] == ["S1", "S1.dof1"]


def test_dotted_name_json_missing_names_its_own_json(tmp_path):
    tf.write_trial(tmp_path / "S1.dof1", make_trial())
    (tmp_path / "S1.dof1.json").unlink()
    with pytest.raises(TrialFormatError, match=r"S1\.dof1\.json: metadata file missing"):
        read(tmp_path / "S1.dof1.csv")


def test_level_stem_keeps_its_decimal_point(tmp_path):
    path = tf.write_trial(tmp_path / "level_0.5", make_trial())
    assert path.name == "level_0.5.csv" and tf.trial_exists(tmp_path / "level_0.5")
    assert not (tmp_path / "level_0.csv").exists()


# ----------------------------------------------------------------------------- gzip
def _gzip(tmp_path, name="trial"):
    tf.write_trial(tmp_path / name, make_trial(seed=5))
    csv = tmp_path / f"{name}.csv"
    with open(csv, "rb") as src, gzip.open(tmp_path / f"{name}.csv.gz", "wb") as dst:
        shutil.copyfileobj(src, dst)
    csv.unlink()
    return tmp_path / f"{name}.csv.gz"


def test_gzip_trial_read_from_folder_by_name_and_by_stem(tmp_path):
    gz = _gzip(tmp_path, "S1.day2")
    ref = make_trial(seed=5)
    for source in (gz, tmp_path / "S1.day2", tmp_path / "S1.day2.json"):
        back = read(source)
        assert back.name == "S1.day2"
        np.testing.assert_array_equal(back.theta, ref.theta)
    (trial,) = tf.read_trials(tmp_path, min_samples=1000)
    assert trial.name == "S1.day2" and tf.trial_exists(tmp_path / "S1.day2")


def test_gzip_and_plain_csv_of_one_trial_refused_as_ambiguous(tmp_path):
    _gzip(tmp_path)
    tf.write_trial(tmp_path / "trial", make_trial())
    with pytest.raises(TrialFormatError, match="more than one form: trial both as .csv and .csv.gz"):
        tf.read_trials(tmp_path, min_samples=1000)
    with pytest.raises(TrialFormatError, match="both as trial.csv and trial.csv.gz"):
        read(tmp_path / "trial")


def test_gz_that_is_not_gzip_refused_by_name(tmp_path):
    tf.write_trial(tmp_path / "x", make_trial())
    (tmp_path / "x.csv").rename(tmp_path / "x.csv.gz")
    with pytest.raises(TrialFormatError, match=r"x\.csv\.gz: not readable as gzip"):
        read(tmp_path / "x.csv.gz")


# ----------------------------------------------------------------------------- MATLAB structs
def _mat_fields(trial):
    return {"t": trial.t[:, None], **{s: trial.signal(s) for s in tf.SIGNALS},
            "meta": json.dumps(trial.meta)}


def test_mat_holding_one_struct_is_read(tmp_path):
    trial = make_trial(seed=7)
    sio.savemat(tmp_path / "rec.mat", {"S": _mat_fields(trial)})
    back = read(tmp_path / "rec.mat")
    assert back.name == "rec"
    np.testing.assert_array_equal(back.tau_m, trial.tau_m)


def test_mat_struct_array_gives_one_trial_per_element_or_is_refused_by_name(tmp_path):
    trials = [make_trial(seed=s) for s in (1, 2, 3)]
    rec = np.empty((1, 3), dtype=[(k, object) for k in _mat_fields(trials[0])])
    for i, tr in enumerate(trials):
        for k, v in _mat_fields(tr).items():
            rec[0, i][k] = v
    sio.savemat(tmp_path / "sess.mat", {"trials": rec})
    got = tf.read_trials(tmp_path, min_samples=1000)
    assert [t.name for t in got] == ["sess.trials(1)", "sess.trials(2)", "sess.trials(3)"]
    for tr, back in zip(trials, got):
        np.testing.assert_array_equal(back.theta, tr.theta)
    with pytest.raises(MatFileError, match="struct array 'trials' holds 3 trials"):
        read(tmp_path / "sess.mat")


def test_mat_struct_without_t_refused_naming_the_struct_and_fields(tmp_path):
    sio.savemat(tmp_path / "bad.mat", {"S": {"time": np.arange(3.0), "angle": np.ones(3)}})
    with pytest.raises(MatFileError, match=r"struct 'S' with fields angle, time"):
        read(tmp_path / "bad.mat")


def test_mat_struct_element_fault_names_the_element(tmp_path):
    fields = _mat_fields(make_trial())
    fields["theta"] = fields["theta"][:, :1]
    sio.savemat(tmp_path / "one.mat", {"S": fields})
    with pytest.raises(MatFileError, match=r"one.mat struct 'S': variable 'theta' has shape"):
        read(tmp_path / "one.mat")


# ----------------------------------------------------------------------------- sizes, types
def test_header_without_newline_refused_in_bounded_memory(tmp_path):
    tf.write_trial(tmp_path / "big", make_trial())
    (tmp_path / "big.csv").write_bytes(b"t" * (tf.logs.csvtable.MAX_HEADER_CHARS + 10))
    with pytest.raises(TrialFormatError, match=r"big\.csv: first line .* longer than 1048576"):
        read(tmp_path / "big")


def test_header_of_one_huge_field_refused_not_traceback(tmp_path):
    tf.write_trial(tmp_path / "f", make_trial())
    (tmp_path / "f.csv").write_bytes(b'"' + b"x" * 300000 + b'"\n1\n')
    with pytest.raises(TrialFormatError, match=r"f\.csv: header row does not parse"):
        read(tmp_path / "f")


@pytest.mark.parametrize("n_dof", [1e9, 65, 0, -3])
def test_absurd_n_dof_refused_up_front(tmp_path, n_dof):
    tf.write_trial(tmp_path / "a", make_trial())
    meta = json.loads((tmp_path / "a.json").read_text())
    meta["n_dof"] = n_dof
    (tmp_path / "a.json").write_text(json.dumps(meta))
    with pytest.raises(TrialFormatError, match=r"a\.json: key 'n_dof' must be an integer in "
                                               r"1\.\.64"):
        read(tmp_path / "a")


@pytest.mark.parametrize("key, value, kind", [("perturbation", [1, 2], "array"),
                                               ("controller", None, "null"),
                                               ("sensors", "ideal", "string"),
                                               ("friction", 3, "number")])
def test_wrong_json_type_refused_naming_key_and_type(tmp_path, key, value, kind):
    tf.write_trial(tmp_path / "a", make_trial())
    meta = json.loads((tmp_path / "a.json").read_text())
    meta[key] = value
    (tmp_path / "a.json").write_text(json.dumps(meta))
    with pytest.raises(TrialFormatError,
                       match=rf"a\.json: key '{key}' must be a JSON object .*got {kind}"):
        read(tmp_path / "a")


def test_escape_sequence_header_never_echoed_raw(tmp_path):
    tf.write_trial(tmp_path / "e", make_trial())
    text = (tmp_path / "e.csv").read_bytes().split(b"\n", 1)[1]
    (tmp_path / "e.csv").write_bytes(b"\x1b]0;pwned\x07\x1b[2J,\x00\x9b,theta[1]\n" + text)
    with pytest.raises(TrialFormatError, match="missing columns") as info:
        read(tmp_path / "e")
    message = str(info.value)
    assert "\x1b" not in message and "\x07" not in message and "\x00" not in message
    assert "\\x1b]0;pwned\\x07" in message


# ----------------------------------------------------------------------------- .mat shapes
def _mat_with(tmp_path, name, fields, meta):
    sio.savemat(tmp_path / name, {**fields, "meta": json.dumps(meta)})
    return tmp_path / name


def test_mat_t_one_sample_short_names_t_and_the_signals(tmp_path):
    trial = make_trial()
    fields = _mat_fields(trial)
    fields["t"] = fields["t"][:-1]
    n = trial.n_samples
    path = _mat_with(tmp_path, "short.mat", fields, trial.meta)
    with pytest.raises(MatFileError) as info:
        read(path)
    text = str(info.value)
    signals = ", ".join(tf.SIGNALS)  # every signal, t named as the short one
    assert f"t has {n - 1} samples but {signals} have {n} rows" in text
    assert "t is 1 sample short" in text and "variable 'theta' has shape" not in text


def test_mat_signals_of_different_lengths_all_named(tmp_path):
    trial = make_trial()
    fields = _mat_fields(trial)
    fields["tau_m"] = fields["tau_m"][:-5]
    n = trial.n_samples
    path = _mat_with(tmp_path, "mixed.mat", fields, trial.meta)
    rest = ", ".join(s for s in tf.SIGNALS if s != "tau_m")
    with pytest.raises(MatFileError, match=rf"disagree in length: t {n} samples; tau_m "
                                           rf"{n - 5} rows; {rest} {n} rows"):
        read(path)


def test_mat_vector_where_two_joints_are_declared_says_one_column(tmp_path):
    trial = make_trial()
    assert trial.n_dof == 2 and trial.meta["n_dof"] == 2
    fields = _mat_fields(trial)
    fields["theta"] = fields["theta"][:, 0]  # a plain vector
    n = trial.n_samples
    path = _mat_with(tmp_path, "vec.mat", fields, trial.meta)
    with pytest.raises(MatFileError, match=rf"variable 'theta' has shape \({n}, ?1?\): 1 "
                                           rf"column where the metadata's n_dof: 2 needs 2"):
        read(path)
    fields["theta"] = _mat_fields(trial)["theta"].T  # one row per joint
    path = _mat_with(tmp_path, "rows.mat", fields, trial.meta)
    with pytest.raises(MatFileError, match=rf"shape \(2, {n}\): one row per joint; save it "
                                           rf"transposed, {n} x 2"):
        read(path)
