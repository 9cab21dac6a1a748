"""Files of other writers read like their plain copies (log-format.md, "Lab data").

Each writer is a third-party library or a dialect people meet (pandas, the csv module, R's
write.csv layout, spreadsheets' "CSV UTF-8", scipy.io v4/v5, hdf5storage v7.3). The
expected values are what the writer printed or stored, computed independently of the reader.
"""

import csv
import json
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import io as sio

import trialformat as tf
from trialformat import MatFileError, TrialFormatError

INGEST = Path(__file__).parent / "data" / "ingest"
SHARED_INGEST = Path(__file__).resolve().parents[3] / "shared" / "cases" / "ingest"
N = 8200


def values(n_dof=2, fs=1000.0, n=N, seed=3):
    """Columns of a trial as a name -> float64 array dict (t first)."""
    rng = np.random.default_rng(seed)
    cols = {"t": np.arange(n) / fs}
    for s in tf.SIGNALS:
        for j in range(1, n_dof + 1):
            cols[f"{s}[{j}]"] = rng.standard_normal(n) * 10.0 ** rng.integers(-6, 2)
    return cols


def metadata(n_dof=2, fs=1000.0, **keys):
    meta = tf.default_metadata(n_dof)
    meta.update(fs=fs, perturbed_dof=1, **keys)
    return meta


def write_json(stem, meta):
    stem.with_suffix(".json").write_text(json.dumps(meta))


def assert_reads_as(trial, cols, fs):
    n = trial.n_dof
    np.testing.assert_array_equal(trial.t, np.arange(len(cols["t"])) / fs)
    for s in tf.SIGNALS:
        expected = np.column_stack([cols[f"{s}[{j}]"] for j in range(1, n + 1)])
        np.testing.assert_array_equal(trial.signal(s), expected, err_msg=s)


def _printed(cols, fmt):
    """What a writer printing with ``fmt`` stored (parsed back by Python's float)."""
    return {k: np.array([float(fmt % v) for v in a]) for k, a in cols.items()}


# ---------------------------------------------------------------------------- CSV writers


def w_pandas(fmt):
    def write(stem, cols):
        pd.DataFrame(cols).to_csv(stem.with_suffix(".csv"), index=False, float_format=fmt)
        return _printed(cols, fmt)
    return write


def w_pandas_kw(**kw):
    def write(stem, cols):
        pd.DataFrame(cols).to_csv(stem.with_suffix(".csv"), index=False, **kw)
        return cols
    return write


def w_csv_module(quoting, delimiter=",", lineterminator="\r\n"):
    def write(stem, cols):
        with open(stem.with_suffix(".csv"), "w", newline="", encoding="utf-8") as fh:
            out = csv.writer(fh, quoting=quoting, delimiter=delimiter,
                             lineterminator=lineterminator)
            out.writerow(list(cols))
            out.writerows(zip(*[a.tolist() for a in cols.values()]))
        return cols
    return write


def w_r_write_csv(stem, cols):
    """R's write.csv layout: a quoted row-name column with an empty ("") header."""
    with open(stem.with_suffix(".csv"), "w", newline="", encoding="utf-8") as fh:
        out = csv.writer(fh, quoting=csv.QUOTE_ALL, lineterminator="\n")
        out.writerow([""] + list(cols))
        for i, row in enumerate(zip(*[a.tolist() for a in cols.values()]), start=1):
            out.writerow([str(i)] + [repr(v) for v in row])
    return cols


def w_float32(stem, cols):
    frame = pd.DataFrame({k: a.astype(np.float32) for k, a in cols.items()})
    frame.to_csv(stem.with_suffix(".csv"), index=False)
    # printed as the shortest decimal that identifies each float32
    return {k: np.array([float(str(v)) for v in a.astype(np.float32)]) for k, a in cols.items()}


def w_t_decimals(decimals):
    def write(stem, cols):
        out = dict(cols)
        frame = pd.DataFrame(cols)
        frame["t"] = frame["t"].map(lambda v: f"{v:.{decimals}f}")
        frame.to_csv(stem.with_suffix(".csv"), index=False)
        return out
    return write


def w_extra_columns(stem, cols):
    frame = pd.DataFrame(cols)
    frame["EMG soleus"] = np.where(np.arange(len(frame)) % 7 == 0, np.nan, 1.0)
    frame["event"] = ""
    frame.loc[0, "event"] = "go, now"
    frame.insert(3, "comment", "text")
    frame.to_csv(stem.with_suffix(".csv"), index=False)
    return cols


CSV_WRITERS = {
    "pandas %.6g": w_pandas("%.6g"),
    "pandas %.7g": w_pandas("%.7g"),
    "pandas %.8g": w_pandas("%.8g"),
    "pandas %.10g": w_pandas("%.10g"),
    "pandas %.9f": w_pandas("%.9f"),
    "pandas default": w_pandas_kw(),
    "pandas CRLF": w_pandas_kw(lineterminator="\r\n"),
    "pandas BOM (spreadsheet CSV UTF-8)": w_pandas_kw(encoding="utf-8-sig",
                                                      lineterminator="\r\n"),
    "pandas ';' separator": w_pandas_kw(sep=";"),
    "pandas tab separator": w_pandas_kw(sep="\t"),
    "pandas quote all": w_pandas_kw(quoting=csv.QUOTE_ALL),
    "csv module QUOTE_ALL": w_csv_module(csv.QUOTE_ALL),
    "csv module QUOTE_NONNUMERIC ';'": w_csv_module(csv.QUOTE_NONNUMERIC, delimiter=";"),
    "R write.csv (row names)": w_r_write_csv,
    "float32": w_float32,
    "extra text/blank/NaN columns": w_extra_columns,
    "t with 3 decimals": w_t_decimals(3),
}


@pytest.mark.parametrize("writer", list(CSV_WRITERS), ids=list(CSV_WRITERS))
def test_csv_writers_read_like_the_plain_copy(tmp_path, writer):
    cols = values()
    expected = CSV_WRITERS[writer](tmp_path / "w", cols)
    write_json(tmp_path / "w", metadata())
    trial = tf.read_trial(tmp_path / "w.csv")
    assert_reads_as(trial, expected, 1000.0)


@pytest.mark.parametrize("fs, decimals", [(2048.0, 6), (1024.0, 6), (500.0, 3), (1000.0, 4)])
def test_t_at_printed_resolution_is_uniform(tmp_path, fs, decimals):
    cols = values(fs=fs)
    w_t_decimals(decimals)(tmp_path / "w", cols)
    write_json(tmp_path / "w", metadata(fs=fs))
    assert_reads_as(tf.read_trial(tmp_path / "w.csv"), cols, fs)


def test_t_printed_coarser_than_its_jitter_is_refused(tmp_path):
    cols = values(fs=2048.0)
    cols["t"] = cols["t"].copy()
    cols["t"][100] += 2e-6  # 4 % of a sample: outside half the 6th decimal
    w_t_decimals(6)(tmp_path / "w", cols)
    write_json(tmp_path / "w", metadata(fs=2048.0))
    with pytest.raises(TrialFormatError, match=r"not uniform at data row 101"):
        tf.read_trial(tmp_path / "w.csv")


@pytest.mark.parametrize("n_dof", [1, 3])
def test_any_joint_count(tmp_path, n_dof):
    cols = values(n_dof=n_dof)
    w_pandas_kw()(tmp_path / "w", cols)
    write_json(tmp_path / "w", metadata(n_dof=n_dof))
    trial = tf.read_trial(tmp_path / "w.csv")
    assert trial.n_dof == n_dof
    assert_reads_as(trial, cols, 1000.0)


def test_integral_floats_for_integer_keys(tmp_path):
    cols = values()
    w_pandas_kw()(tmp_path / "w", cols)
    meta = metadata()
    meta.update(n_dof=2.0, perturbed_dof=1.0)
    meta["perturbation"]["level"] = 3.0
    write_json(tmp_path / "w", meta)
    trial = tf.read_trial(tmp_path / "w.csv")
    assert trial.meta["n_dof"] == 2 and isinstance(trial.meta["n_dof"], int)
    assert trial.perturbed_dof == 1 and trial.meta["perturbation"]["level"] == 3
    meta["n_dof"] = 2.5
    write_json(tmp_path / "w", meta)
    with pytest.raises(TrialFormatError, match="'n_dof' must be an integer, got 2.5"):
        tf.read_trial(tmp_path / "w.csv")


# ---------------------------------------------------------------------------- ingest cases


@pytest.mark.parametrize("case", ["bom3", "quoted3", "event3"])
def test_ingest_cases_read_like_the_plain_copy(tmp_path, case):
    trial = tf.read_trial(INGEST / f"{case}.csv", min_samples=1)
    plain = pd.read_csv(INGEST / "quoted3.csv")  # pandas' reading, independent of ours
    np.testing.assert_array_equal(trial.theta, plain[["theta[1]", "theta[2]"]].to_numpy())
    np.testing.assert_array_equal(trial.tau_m, plain[["tau_m[1]", "tau_m[2]"]].to_numpy())
    assert "event" not in trial.extra
    with pytest.raises(TrialFormatError, match="fewer than one spectral segment"):
        tf.read_trial(INGEST / f"{case}.csv")


@pytest.mark.skipif(not SHARED_INGEST.is_dir(), reason="shared cases folder not beside the repo")
@pytest.mark.parametrize("case", ["bom3", "quoted3", "event3", "t6dec_8192"])
def test_shared_ingest_cases(case):
    trial = tf.read_trial(SHARED_INGEST / f"{case}.csv", min_samples=1)
    plain = pd.read_csv(SHARED_INGEST / f"{case}.csv", encoding="utf-8-sig")
    np.testing.assert_array_equal(trial.tau_h, plain[["tau_h[1]", "tau_h[2]"]].to_numpy())
    np.testing.assert_array_equal(trial.t, np.arange(len(plain)) / trial.fs)


# ---------------------------------------------------------------------------- MATLAB writers


def _mat_data(cols, n_dof, dtype=float):
    data = {"t": cols["t"].astype(dtype)[:, None]}
    for s in tf.SIGNALS:
        data[s] = np.column_stack([cols[f"{s}[{j}]"] for j in range(1, n_dof + 1)]).astype(dtype)
    return data


def _v73(path, data):
    hdf5storage = pytest.importorskip("hdf5storage")
    hdf5storage.savemat(str(path), data, format="7.3", oned_as="column",
                        store_python_metadata=False, matlab_compatible=True)


MAT_WRITERS = {
    "scipy v5, meta JSON": lambda p, d, m: sio.savemat(p, {**d, "meta": json.dumps(m)}),
    "scipy v5 compressed, meta struct": lambda p, d, m: tf.write_trial_mat(
        p, _trial(d, m), meta_as="struct"),
    "scipy v4, meta JSON": lambda p, d, m: sio.savemat(p, {**d, "meta": json.dumps(m)},
                                                      format="4"),
    "scipy v5 float32": lambda p, d, m: sio.savemat(
        p, {**{k: v.astype(np.float32) for k, v in d.items()}, "meta": json.dumps(m)}),
    "hdf5storage v7.3, meta JSON": lambda p, d, m: _v73(p, {**d, "meta": json.dumps(m)}),
    "hdf5storage v7.3 float32, meta struct": lambda p, d, m: _v73(
        p, {**{k: v.astype(np.float32) for k, v in d.items()}, "meta": _struct(m)}),
}


def _trial(data, meta):
    return tf.Trial(meta=meta, t=data["t"].ravel(), **{s: data[s] for s in tf.SIGNALS})


def _struct(meta):
    """Metadata as a MATLAB struct would hold it: numbers as doubles, null as []."""
    out = {}
    for k, v in meta.items():
        if isinstance(v, dict):
            out[k] = _struct(v)
        elif v is None:
            out[k] = np.zeros((0, 0))
        elif isinstance(v, (bool, int, float)):
            out[k] = np.float64(v)
        elif isinstance(v, list):
            out[k] = np.asarray(v, dtype=float)
        else:
            out[k] = v
    return out


@pytest.mark.parametrize("writer", list(MAT_WRITERS), ids=list(MAT_WRITERS))
@pytest.mark.parametrize("n_dof", [1, 2, 3])
def test_mat_writers_read_like_the_plain_copy(tmp_path, writer, n_dof):
    cols = values(n_dof=n_dof)
    meta = metadata(n_dof=n_dof)
    path = tmp_path / "m.mat"
    MAT_WRITERS[writer](path, _mat_data(cols, n_dof), meta)
    trial = tf.read_trial(path)
    if "float32" in writer:
        cols = {k: v.astype(np.float32).astype(float) for k, v in cols.items()}
    assert trial.n_dof == n_dof and trial.perturbed_dof == 1
    assert_reads_as(trial, cols, 1000.0)
    assert trial.meta["friction"]["sigma0"] == meta["friction"]["sigma0"]


def test_mat_folder_and_ambiguous_stem(tmp_path):
    cols = values()
    tf.write_trial_mat(tmp_path / "a.mat", _trial(_mat_data(cols, 2), metadata()))
    w_pandas_kw()(tmp_path / "b", cols)
    write_json(tmp_path / "b", metadata())
    assert [t.name for t in tf.read_trials(tmp_path)] == ["b", "a"]
    w_pandas_kw()(tmp_path / "a", cols)
    write_json(tmp_path / "a", metadata())
    with pytest.raises(TrialFormatError, match="both as .csv and .mat"):
        tf.read_trials(tmp_path)


def test_mat_not_a_matlab_file(tmp_path):
    (tmp_path / "x.mat").write_bytes(b"not a mat file at all" * 20)
    with pytest.raises(MatFileError, match="x.mat"):
        tf.read_trial(tmp_path / "x.mat")


# ---------------------------------------------------------------------------- bad input


def _plain(tmp_path, n=N):
    stem = tmp_path / "bad"
    cols = values(n=n)
    w_pandas_kw()(stem, cols)
    write_json(stem, metadata())
    return stem.with_suffix(".csv")


def _edit(path, fn):
    lines = path.read_text().splitlines()
    fn(lines)
    path.write_text("\n".join(lines) + "\n")


def test_header_only_file(tmp_path):
    path = _plain(tmp_path)
    _edit(path, lambda lines: lines.__delitem__(slice(1, None)))
    with pytest.raises(TrialFormatError, match=r"bad.csv: 0 samples, fewer than one spectral"):
        tf.read_trial(path)


def test_empty_file(tmp_path):
    path = _plain(tmp_path)
    path.write_text("")
    with pytest.raises(TrialFormatError, match=r"bad.csv: file is empty"):
        tf.read_trial(path)


def test_duplicated_column_refused(tmp_path):
    path = _plain(tmp_path)
    _edit(path, lambda lines: [lines.__setitem__(i, lines[i] + "," + lines[i].split(",")[3])
                               for i in range(len(lines))])
    with pytest.raises(TrialFormatError, match=r"theta\[1\] appear more than once"):
        tf.read_trial(path)


def test_short_row_names_row_without_numpy_advice(tmp_path):
    path = _plain(tmp_path)
    _edit(path, lambda lines: lines.__setitem__(40, lines[40].rsplit(",", 1)[0]))
    with pytest.raises(TrialFormatError, match=r"bad.csv: data row 40 has 8 fields, the "
                                               r"header has 9") as info:
        tf.read_trial(path)
    assert "usecols" not in str(info.value)


@pytest.mark.parametrize("cell, match", [
    ("abc", r"non-numeric value 'abc' in column 'theta\[2\]' at data row 12"),
    ("", r"non-finite or blank value .* column 'theta\[2\]' at data row 12"),
    ("NaN", r"non-finite or blank value .* column 'theta\[2\]' at data row 12"),
    ("inf", r"non-finite or blank value .* column 'theta\[2\]' at data row 12"),
])
def test_bad_cell_names_file_row_column(tmp_path, cell, match):
    path = _plain(tmp_path)

    def put(lines):
        cells = lines[12].split(",")
        cells[4] = cell
        lines[12] = ",".join(cells)
    _edit(path, put)
    with pytest.raises(TrialFormatError, match=match) as info:
        tf.read_trial(path)
    assert "bad.csv" in str(info.value)


def test_nan_gaps_name_file_columns_rows_and_a_way_forward(tmp_path):
    """NaN gaps used to be refused at their first cell only, with no way forward: now
    every gap of every column (data rows and t), the longest finite stretch and what to do
    (cut there; nothing is interpolated) are named."""
    path = _plain(tmp_path, n=20_000)
    header = path.read_text().splitlines()[0].split(",")
    c_theta, c_tau = header.index("theta[2]"), header.index("tau_h[1]")

    def put(lines):
        for row, col, cell in [*((r, c_tau, "NaN") for r in range(100, 111)),
                               *((r, c_theta, "") for r in (3000, 3001)),
                               (6000, c_theta, "nan")]:
            cells = lines[row].split(",")
            cells[col] = cell
            lines[row] = ",".join(cells)
    _edit(path, put)
    with pytest.raises(TrialFormatError) as info:
        tf.read_trial(path)
    msg = str(info.value)
    assert "bad.csv" in msg
    assert "column 'tau_h[1]' at data row 100" in msg  # the first, as before
    assert "'tau_h[1]' rows 100-110 (t = 0.099-0.109 s): 11 row(s)" in msg
    assert "'theta[2]' rows 3000-3001 (t = 2.999-3 s), row 6000 (t = 5.999 s): 3 row(s)" \
        in msg
    assert "longest: rows 6001-20000, 14000 samples, 14 s" in msg
    assert "cut the trial at the gaps" in msg and "nothing is interpolated" in msg
    assert "record the trial again" not in msg  # a long enough stretch is left


def test_nan_gaps_leaving_no_long_stretch_say_record_again(tmp_path):
    path = _plain(tmp_path)

    def put(lines):
        cells = lines[N // 2].split(",")
        cells[3] = "NaN"
        lines[N // 2] = ",".join(cells)
    _edit(path, put)
    with pytest.raises(TrialFormatError, match=r"shorter than one spectral segment .*no cut "
                                               r"is long enough, record the trial again"):
        tf.read_trial(path)


def test_decimal_comma_gets_a_hint(tmp_path):
    stem = tmp_path / "bad"
    pd.DataFrame(values()).to_csv(stem.with_suffix(".csv"), index=False, sep=";", decimal=",")
    write_json(stem, metadata())
    with pytest.raises(TrialFormatError, match="decimal comma"):
        tf.read_trial(stem.with_suffix(".csv"))


def test_written_files_get_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        cols = values()
        trial = tf.Trial(meta=metadata(), t=cols["t"],
                         **{s: np.column_stack([cols[f"{s}[1]"], cols[f"{s}[2]"]])
                            for s in tf.SIGNALS})
        path = tf.write_trial(tmp_path / "w", trial)
        assert (path.stat().st_mode & 0o777) == 0o644
        assert (path.with_suffix(".json").stat().st_mode & 0o777) == 0o644
        os.umask(0o077)
        path = tf.write_trial(tmp_path / "v", trial)
        assert (path.stat().st_mode & 0o777) == 0o600
    finally:
        os.umask(old)


def test_position_perturbation_trial(tmp_path):
    """kind "position": theta and tau_h required, theta_ref read when recorded."""
    cols = values(n_dof=1)
    for s in ("tau_delta[1]", "tau_m[1]"):
        del cols[s]
    cols["theta_ref[1]"] = np.sin(np.arange(N) / 50.0)
    w_pandas_kw()(tmp_path / "p", cols)
    meta = metadata(n_dof=1, perturbation={"kind": "position", "level": 1},
                    sensors={"torque_sign": -1, "torque_sampling": "instantaneous"})
    write_json(tmp_path / "p", meta)
    with pytest.warns(UserWarning, match="sensors.encoder_resolution_deg"):
        trial = tf.read_trial(tmp_path / "p.csv")
    assert trial.perturbation_kind == "position" and trial.tau_delta is None
    np.testing.assert_array_equal(trial.theta_ref[:, 0], cols["theta_ref[1]"])
    np.testing.assert_array_equal(trial.tau_h[:, 0], -cols["tau_h[1]"])  # torque_sign applied
    tf.write_trial(tmp_path / "q", trial)
    back = pd.read_csv(tmp_path / "q.csv")
    np.testing.assert_array_equal(back["tau_h[1]"], cols["tau_h[1]"])  # sign restored
    cols["theta_ref[1]"][:] = 0.0
    w_pandas_kw()(tmp_path / "p", cols)
    with pytest.raises(TrialFormatError, match=r"theta_ref\[1\].*identically zero"):
        tf.read_trial(tmp_path / "p.csv")


def test_absolute_angles_become_deviations(tmp_path):
    cols = values()
    posture = np.deg2rad([62.708, 77.26])
    absolute = dict(cols)
    for j in (1, 2):
        absolute[f"theta[{j}]"] = cols[f"theta[{j}]"] + posture[j - 1]
    w_pandas_kw()(tmp_path / "a", absolute)
    write_json(tmp_path / "a", metadata(angles="absolute", posture_deg=[62.708, 77.26]))
    trial = tf.read_trial(tmp_path / "a.csv")
    expected = np.column_stack([absolute["theta[1]"], absolute["theta[2]"]]) - posture
    np.testing.assert_array_equal(trial.theta, expected)
    tf.write_trial(tmp_path / "b", trial)  # written back in the file's convention
    back = pd.read_csv(tmp_path / "b.csv")
    np.testing.assert_allclose(back["theta[1]"], absolute["theta[1]"], rtol=0, atol=1e-15)


@pytest.mark.parametrize("version, meta_as", [("5", "json"), ("5", "struct"), ("4", "json")])
def test_mat_writer_restores_sign_and_angle_conventions(tmp_path, version, meta_as):
    """write_trial_mat stores the file's conventions like write_trial: every round trip
    (CSV -> .mat -> CSV) gives back the same arrays, with torque_sign -1 and absolute angles."""
    cols = values()
    posture = [62.708, 77.26]
    raw = dict(cols)
    for j in (1, 2):
        raw[f"theta[{j}]"] = cols[f"theta[{j}]"] + np.deg2rad(posture[j - 1])
    w_pandas_kw()(tmp_path / "a", raw)
    meta = metadata(angles="absolute", posture_deg=posture)
    meta["sensors"]["torque_sign"] = -1
    write_json(tmp_path / "a", meta)
    trial = tf.read_trial(tmp_path / "a.csv")
    path = tf.write_trial_mat(tmp_path / "a.mat", trial, meta_as=meta_as, version=version)
    stored = sio.loadmat(path)
    # the file holds the raw values, as the CSV did
    np.testing.assert_array_equal(stored["tau_h"][:, 0], raw["tau_h[1]"])
    np.testing.assert_allclose(stored["theta"][:, 1], raw["theta[2]"], rtol=0, atol=1e-15)
    back = tf.read_trial_mat(path)
    for s in tf.SIGNALS:
        np.testing.assert_allclose(back.signal(s), trial.signal(s), rtol=0, atol=1e-15,
                                   err_msg=s)
    assert back.tau_h[0, 0] == trial.tau_h[0, 0] == -raw["tau_h[1]"][0]
    tf.write_trial(tmp_path / "b", back)  # and on to CSV: the first file's values again
    again = pd.read_csv(tmp_path / "b.csv")
    np.testing.assert_array_equal(again["tau_h[1]"], raw["tau_h[1]"])
    np.testing.assert_allclose(again["theta[1]"], raw["theta[1]"], rtol=0, atol=1e-15)
