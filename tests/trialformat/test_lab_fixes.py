"""Lab files an outside tester wrote (issue 11 follow-up): printed ``t`` judged per value,
any encoding in ignored columns, metadata values refused by name, plain numbers in messages.

Inputs are generated here with pandas / Python formatting at rates and precisions this
project does not write itself; the expected ``t`` is the exact grid ``arange(N) / fs``.
"""

import json
import warnings

import numpy as np
import pandas as pd
import pytest

import trialformat as tf
from trialformat import TrialFormatError


def _cols(fs, seconds, seed=5):
    n = int(round(fs * seconds))
    rng = np.random.default_rng(seed)
    cols = {"t": np.arange(n) / fs}
    for s in tf.SIGNALS:
        cols[f"{s}[1]"] = rng.standard_normal(n)
    return cols


def _write(stem, cols, fs, *, t_fmt=None, table_fmt=None, **meta_keys):
    frame = pd.DataFrame(cols)
    if t_fmt is not None:
        frame["t"] = [t_fmt % v for v in cols["t"]]
    frame.to_csv(stem.with_suffix(".csv"), index=False, float_format=table_fmt)
    meta = tf.default_metadata(1)
    meta.update(fs=fs, perturbed_dof=1, **meta_keys)
    stem.with_suffix(".json").write_text(json.dumps(meta))
    return stem.with_suffix(".csv")


# fs, printing of t (or of the whole table), seconds: long enough to reach the values
# where the old one-decimal-count rule failed (ties at 8.0078125 s, 10.0009765625 s)
UNIFORM = [
    (2048.0, "%.6f", None, 17),     # rounding ties: exactly half the 6th decimal off
    (1024.0, "%.6f", None, 17),
    (1024.0, None, "%.7g", 17),     # significant digits: 10.00098 is 3.4e-6 off
    (2048.0, None, "%.7g", 17),
    (1024.0, None, "%.6g", 17),
    (1024.0, None, "%.5e", 17),
    (1024.0, "%.3f", None, 12),     # 1 ms printing coarser than the step: repeats
    (2048.0, "%.3f", None, 12),
    (500.0, "%.2f", None, 20),
    (1000.0, "%.3f", None, 10),
]


@pytest.mark.parametrize("fs, t_fmt, table_fmt, seconds", UNIFORM,
                         ids=[f"{u[0]:g}Hz-{u[1] or u[2]}" for u in UNIFORM])
def test_t_correctly_printed_reads_as_the_grid(tmp_path, fs, t_fmt, table_fmt, seconds):
    cols = _cols(fs, seconds)
    path = _write(tmp_path / "w", cols, fs, t_fmt=t_fmt, table_fmt=table_fmt)
    trial = tf.read_trial(path)
    np.testing.assert_array_equal(trial.t, np.arange(len(cols["t"])) / fs)


def test_t_off_by_more_than_its_own_digit_is_refused(tmp_path):
    fs = 1024.0
    cols = _cols(fs, 12)
    path = _write(tmp_path / "w", cols, fs, table_fmt="%.7g")
    lines = path.read_text().splitlines()
    row = 10242                          # t = 10.0009765625, printed 10.00098
    cells = lines[row].split(",")
    assert cells[0] == "10.00098"
    cells[0] = "10.00099"               # 1.3e-5 off: beyond half its digit (5e-6)
    lines[row] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(TrialFormatError) as info:
        tf.read_trial(path)
    text = str(info.value)
    assert "w.csv" in text and "not uniform at data row 10242" in text
    assert "t=10.00099" in text and "np." not in text


@pytest.mark.parametrize("fs, shift, match", [
    (1024.0, -1, "not increasing at data row 5001"),   # a step back by one sample
    (1000.0, 0, "not increasing at data row 5001"),    # a repeat finer printed than a step
])
def test_t_going_back_is_not_increasing(tmp_path, fs, shift, match):
    cols = _cols(fs, 9)
    t = np.round(cols["t"], 3)
    t[5000] = t[4999] + shift * 1e-3
    cols["t"] = t
    path = _write(tmp_path / "w", cols, fs, t_fmt="%.3f")
    with pytest.raises(TrialFormatError, match=match):
        tf.read_trial(path)


@pytest.mark.parametrize("encoding", ["latin-1", "cp1252"])
def test_any_encoding_in_an_ignored_text_column(tmp_path, encoding):
    fs = 1000.0
    cols = _cols(fs, 8.2)
    frame = pd.DataFrame(cols)
    frame["Proband"] = "Müller – Größe" if encoding == "cp1252" else "Müller"
    frame["Kommentar (µV)"] = ""
    frame.loc[3, "Kommentar (µV)"] = "Start"
    stem = tmp_path / "w"
    frame.to_csv(stem.with_suffix(".csv"), index=False, encoding=encoding)
    meta = tf.default_metadata(1)
    meta.update(fs=fs, perturbed_dof=1)
    stem.with_suffix(".json").write_text(json.dumps(meta))
    trial = tf.read_trial(stem.with_suffix(".csv"))
    np.testing.assert_array_equal(trial.theta[:, 0], cols["theta[1]"])


def test_encoding_fault_in_a_declared_cell_names_the_file(tmp_path):
    fs = 1000.0
    stem = tmp_path / "w"
    path = _write(stem, _cols(fs, 8.2), fs)
    lines = path.read_bytes().split(b"\n")
    cells = lines[7].split(b",")
    cells[2] = b"\xfc"
    lines[7] = b",".join(cells)
    path.write_bytes(b"\n".join(lines))
    with pytest.raises(TrialFormatError, match=r"w.csv: non-numeric value .* column "
                                               r"'theta\[1\]' at data row 7"):
        tf.read_trial(path)


@pytest.mark.parametrize("keys, match", [
    ({"perturbation": {"cutoff_hz": -5}}, r"'perturbation.cutoff_hz' must be a positive "
                                          r"number \[Hz\], got -5"),
    ({"perturbation": {"cutoff_hz": "15"}}, r"'perturbation.cutoff_hz' .* got '15'"),
    ({"perturbation": {"cutoff_hz": 900}}, r"'perturbation.cutoff_hz'=900 Hz is above the "
                                           r"Nyquist frequency fs/2=500.0 Hz"),
    ({"angles": "relative"}, r"'angles' must be one of \['absolute'\] .*got 'relative'"),
])
def test_bad_metadata_values_refused_by_name(tmp_path, keys, match):
    fs = 1000.0
    path = _write(tmp_path / "w", _cols(fs, 8.2), fs)
    meta = json.loads(path.with_suffix(".json").read_text())
    for k, v in keys.items():
        meta[k] = {**meta[k], **v} if isinstance(v, dict) else v
    path.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(TrialFormatError, match=match) as info:
        tf.read_trial(path)
    assert "w.json" in str(info.value)


def test_unknown_format_warns(tmp_path):
    fs = 1000.0
    path = _write(tmp_path / "w", _cols(fs, 8.2), fs, format="other/2")
    with pytest.warns(UserWarning, match=r"w.json: unknown format 'other/2'"):
        tf.read_trial(path)
    path = _write(tmp_path / "v", _cols(fs, 8.2), fs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tf.read_trial(path)


def test_messages_print_plain_numbers(tmp_path):
    fs = 1000.0
    path = _write(tmp_path / "w", _cols(fs, 8.2), fs)
    lines = path.read_text().splitlines()
    cells = lines[9].split(",")
    cells[2] = "nan"
    lines[9] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(TrialFormatError, match=r"value nan in column 'theta\[1\]' "
                                               r"at data row 9") as info:
        tf.read_trial(path)
    assert "np." not in str(info.value)


def test_missing_path_says_so(tmp_path):
    with pytest.raises(TrialFormatError, match=r"nothing_here: no such file or folder"):
        tf.read_trials(tmp_path / "nothing_here")


def test_filled_n_dof_is_called_filled(tmp_path):
    fs = 1000.0
    cols = _cols(fs, 8.2)
    path = _write(tmp_path / "w", cols, fs)
    meta = json.loads(path.with_suffix(".json").read_text())
    del meta["n_dof"]
    path.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(TrialFormatError, match=r"missing columns for n_dof=2 \(filled from "
                                               r"the reference"):
        tf.read_trial(path)


def _mat_arrays(fs=1000.0, seconds=8.2):
    cols = _cols(fs, seconds)
    data = {"t": cols["t"][:, None]}
    data.update({s: cols[f"{s}[1]"][:, None] for s in tf.SIGNALS})
    return data


def test_v73_meta_with_python_lists_reads_like_scipy_v5(tmp_path):
    hdf5storage = pytest.importorskip("hdf5storage")
    from scipy import io as sio
    meta = tf.default_metadata(1)
    meta.update(perturbed_dof=1, posture_deg=[10.0], condition="slow")
    meta.setdefault("controller", {})["K_rd"] = [10.0]  # one joint: no reference block
    data = _mat_arrays()
    sio.savemat(tmp_path / "v5.mat", {**data, "meta": meta})
    hdf5storage.savemat(str(tmp_path / "v73.mat"), {**data, "meta": meta}, format="7.3",
                        oned_as="column", store_python_metadata=False,
                        matlab_compatible=True)
    a, b = tf.read_trial(tmp_path / "v5.mat"), tf.read_trial(tmp_path / "v73.mat")
    np.testing.assert_allclose(np.ravel(b.meta["posture_deg"]), [10.0])
    np.testing.assert_allclose(np.ravel(a.meta["posture_deg"]), [10.0])
    assert b.meta["condition"] == "slow"
    np.testing.assert_allclose(b.meta["controller"]["K_rd"], a.meta["controller"]["K_rd"])
    np.testing.assert_array_equal(b.theta, a.theta)


def test_v73_cell_of_text_still_refused_by_name(tmp_path):
    hdf5storage = pytest.importorskip("hdf5storage")
    meta = tf.default_metadata(1)
    meta.update(perturbed_dof=1, tags=["a", "b"])
    hdf5storage.savemat(str(tmp_path / "v73.mat"), {**_mat_arrays(), "meta": meta},
                        format="7.3", oned_as="column", store_python_metadata=False,
                        matlab_compatible=True)
    with pytest.raises(tf.MatFileError, match=r"v73.mat variable 'meta'.tags: cell arrays "
                                              r"are read only when every element is one"):
        tf.read_trial(tmp_path / "v73.mat")


def test_one_value_typed_finer_is_judged_at_its_own_digit(tmp_path):
    """A %.3f file at 1024 Hz with one value typed to 4 decimals: that value is refused at
    its own digit (1e-4), and the rest of the file is not made stricter by it."""
    fs = 1024.0
    cols = _cols(fs, 9)
    path = _write(tmp_path / "w", cols, fs, t_fmt="%.3f")
    lines = path.read_text().splitlines()
    cells = lines[5001].split(",")    # t = 4.8828125, printed 4.883
    cells[0] = "4.8832"               # 3.1e-4 off: inside half of 1 ms, not of its 0.1 ms
    lines[5001] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(TrialFormatError, match=r"not uniform at data row 5001 \(t=4.8832"):
        tf.read_trial(path)


def test_repeats_from_coarse_printing_are_not_called_not_increasing(tmp_path):
    """1 ms printing at 1024 Hz repeats values; with a wrong fs the fault is the fs."""
    cols = _cols(1024.0, 9)
    path = _write(tmp_path / "w", cols, 1000.0, t_fmt="%.3f")
    with pytest.raises(TrialFormatError, match=r"key 'fs'=1000.0 disagrees with column 't'"):
        tf.read_trial(path)


POSTURES = [  # (posture_deg in the JSON, or "absent"), the refusal's words
    ("absent", r"'posture_deg' is required with \"angles\": \"absolute\""),
    ([], r"'posture_deg' must be a list of 1 finite number\(s\) .* got array \[\]"),
    ([None], r"'posture_deg' must be a list of 1 .* got array \[null\]"),
    ([float("nan")], r"'posture_deg' must be a list of 1 .* got array \[NaN\]"),
    ([10, 20], r"'posture_deg' must be a list of 1 .*n_dof=1.* got array \[10, 20\]"),
    (["x"], r"'posture_deg' must be a list of 1 .* got array \[\"x\"\]"),
]


@pytest.mark.parametrize("posture, match", POSTURES, ids=[str(p[0]) for p in POSTURES])
def test_bad_posture_with_absolute_angles_refused_by_name(tmp_path, posture, match):
    """Absent, empty, null, NaN, too long or text: one message naming the key (these gave
    KeyError, IndexError, StopIteration, broadcast and float() tracebacks)."""
    path = _write(tmp_path / "w", _cols(1000.0, 9), 1000.0, angles="absolute")
    meta = json.loads(path.with_suffix(".json").read_text())
    meta.pop("posture_deg", None)
    if posture != "absent":
        meta["posture_deg"] = posture
    path.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(TrialFormatError, match=match):
        tf.read_trial(path)


def test_good_posture_with_absolute_angles_reads_as_deviation(tmp_path):
    cols = _cols(1000.0, 9)
    path = _write(tmp_path / "w", cols, 1000.0, angles="absolute", posture_deg=[10])
    trial = tf.read_trial(path)
    np.testing.assert_allclose(trial.theta[:, 0], cols["theta[1]"] - np.deg2rad(10.0))


def test_absent_fs_is_called_absent_when_t_disagrees(tmp_path):
    """The message named a key 'fs'=1000.0 that the file does not have."""
    path = _write(tmp_path / "w", _cols(2000.0, 9), 2000.0)
    meta = json.loads(path.with_suffix(".json").read_text())
    del meta["fs"]
    path.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(TrialFormatError, match=r"key 'fs' is absent and its reference value "
                       r"1000.0 disagrees with column 't' .*fs=2000.0\); declare fs"):
        tf.read_trial(path)


def test_three_joint_reference_posture_has_three_angles():
    assert len(tf.default_metadata(3)["posture_deg"]) == 3


def test_a_mat_named_by_its_stem_reads_like_a_csv_stem(tmp_path):
    """``estimate experimental_data`` said "no such file" where ``NAME`` of a CSV works."""
    trial = tf.read_trial(_write(tmp_path / "w", _cols(1000.0, 9), 1000.0))
    tf.write_trial_mat(tmp_path / "m.mat", trial)
    by_stem = tf.read_trials(str(tmp_path / "m"))
    assert len(by_stem) == 1
    np.testing.assert_array_equal(by_stem[0].tau_h, trial.tau_h)
    assert tf.read_trial(tmp_path / "m").n_samples == trial.n_samples
    with pytest.raises(TrialFormatError, match="no such file or folder"):
        tf.read_trial(tmp_path / "absent")


def test_theta_ref_without_a_perturbation_kind_suggests_position(tmp_path):
    cols = {k: v for k, v in _cols(1000.0, 9).items() if k in ("t", "theta[1]", "tau_h[1]")}
    cols["theta_ref[1]"] = cols["theta[1]"]
    path = _write(tmp_path / "w", cols, 1000.0)
    with pytest.raises(TrialFormatError, match=r"missing columns .*tau_delta\[1\].*declare "
                       r"\"perturbation\": \{\"kind\": \"position\"\}"):
        tf.read_trial(path)
