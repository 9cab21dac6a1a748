"""labsim's writers round-trip through trialformat's readers within each representation's
precision; the truth file; the CLI; labsim imports nothing of diagnosis or estimation."""

import gzip
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import labsim
import trialformat

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def rec():
    spec = labsim.RecordingSpec(duration_s=9.0, movement=labsim.Movement(period_s=4.0),
                                reflex=labsim.Reflex(),
                                limb=labsim.Limb(K_var=labsim.Variation(angle="exp",
                                                                        angle_coef=2.0)),
                                sensors=labsim.Sensors(torque_sign=-1))
    return labsim.simulate(spec)


def _rel(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


# representation -> (relative tolerance of the values, absolute tolerance)
PRECISION = {
    "csv": (0, 0), "csv17": (0, 0), "pandas": (0, 0), "semicolon": (0, 0), "tab": (0, 0),
    "quoted": (0, 0),
    "gzip": (0, 0), "mat5": (0, 0), "mat5_struct": (0, 0), "mat73": (0, 0),
    "excel": (1e-14, 0), "sig6": (5e-6, 0), "sig8": (5e-8, 0), "fixed6": (0, 5.01e-7),
    # float32 text: the float32's rounding (half an ulp, 2^-24) plus the text's (as much)
    "float32": (1.2e-7, 0), "float32_9": (1.2e-7, 0), "mat5_float32": (6e-8, 0),
}


@pytest.mark.parametrize("rep", list(PRECISION))
def test_round_trip_through_trialformat(tmp_path, rec, rep):
    paths = labsim.write(rec, tmp_path, f"w_{rep}", rep)
    trial = trialformat.read_trial(paths["data"])
    rel, ab = PRECISION[rep]
    for s in ("theta", "tau_h", "theta_ref"):
        got, want = trial.signal(s), rec.trial.signal(s)
        if rel == 0 and ab == 0:
            np.testing.assert_array_equal(got, want, err_msg=s)
        else:
            np.testing.assert_allclose(got, want, rtol=rel, atol=ab, err_msg=s)
    assert trial.perturbation_kind == "position" and trial.fs == 1000.0
    np.testing.assert_array_equal(trial.t, rec.trial.t)
    if not rep.startswith("mat"):
        np.testing.assert_allclose(trial.extra["sv"], rec.trial.extra["sv"], rtol=max(rel, 1e-15),
                                   atol=ab)


def test_file_stores_the_declared_torque_sign(tmp_path, rec):
    paths = labsim.write(rec, tmp_path, "signed", "csv17")
    raw = np.genfromtxt(paths["data"], delimiter=",", names=True)
    np.testing.assert_array_equal(raw["tau_h1"], -rec.trial.tau_h[:, 0])
    meta = json.loads(paths["meta"].read_text())
    assert meta["sensors"]["torque_sign"] == -1
    assert meta["perturbation"]["kind"] == "position"


def test_decimal_comma_is_refused_by_trialformat_with_its_hint(tmp_path, rec):
    paths = labsim.write(rec, tmp_path, "comma", "decimal_comma")
    assert b";" in paths["data"].read_bytes().splitlines()[1]
    with pytest.raises(trialformat.TrialFormatError, match="decimal comma"):
        trialformat.read_trial(paths["data"])


def test_gzip_and_excel_bytes(tmp_path, rec):
    gz = labsim.write(rec, tmp_path, "g", "gzip")["data"]
    assert gz.name == "g.csv.gz" and gzip.decompress(gz.read_bytes()).startswith(b"t,theta[1]")
    ex = labsim.write(rec, tmp_path, "e", "excel")["data"].read_bytes()
    assert ex.startswith(b"\xef\xbb\xbft,") and b"\r\n" in ex


def test_unknown_representation_names_the_known_ones(tmp_path, rec):
    with pytest.raises(ValueError, match="unknown representation 'sig2'.*csv17"):
        labsim.write(rec, tmp_path, "x", "sig2")


def test_truth_file_beside_the_trial(tmp_path, rec):
    paths = labsim.write(rec, tmp_path, "dotted.name", "csv17", truth_fs=100.0)
    assert paths["truth"].name == "dotted.name.truth.json"
    assert paths["data"].name == "dotted.name.csv"
    truth = labsim.read_truth(paths["truth"])
    assert truth["arrays_fs"] == 100.0
    np.testing.assert_allclose(truth["arrays"]["K"], rec.truth["arrays"]["K"][::10])
    np.testing.assert_allclose(truth["arrays"]["sv"], rec.truth["arrays"]["sv"][::10])
    assert {e["name"] for e in truth["effects"]} >= {"reflex", "movement",
                                                    "angle_dependent_K", "servo_dynamics"}
    assert labsim.spec_from_dict(truth["spec"]) == rec.spec
    # the trial's metadata tells nothing of the truth
    meta = json.loads(paths["meta"].read_text())
    assert "reflex" not in json.dumps(meta) and "K" not in meta
    # trialformat reads the folder without taking the truth file for a trial
    assert [t.name for t in trialformat.read_trials(tmp_path)] == ["dotted.name"]


def test_cli_writes_one_recording(tmp_path):
    out = tmp_path / "runs" / "x"
    res = subprocess.run([sys.executable, "-m", "labsim", "--kind", "saturating_drift",
                          "--seed", "3", "--duration", "3", "--out", str(out)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "varies: K" in res.stdout
    trial = trialformat.read_trial(out / "saturating_drift_s3.csv", min_samples=1000)
    truth = labsim.read_truth(out / "saturating_drift_s3.truth.json")
    assert truth["kind"] == "saturating_drift" and trial.n_samples == 3000
    bad = subprocess.run([sys.executable, "-m", "labsim", "--kind", "nope", "--out", str(out)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "unknown kind 'nope'" in bad.stderr


def test_labsim_imports_neither_diagnosis_nor_estimation(tmp_path):
    code = ("import sys, numpy as np, labsim; "
            "rec = labsim.simulate(labsim.draw('nominal+reflex', np.random.default_rng(1), "
            "duration_s=2)); labsim.write(rec, sys.argv[1], 'x', 'mat73'); "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('diagnosis', 'estimation', "
            "'orchestrator')]; print(bad); sys.exit(1 if bad else 0)")
    res = subprocess.run([sys.executable, "-c", code, str(tmp_path)], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    for path in (ROOT / "labsim").glob("*.py"):
        text = path.read_text()
        assert "import diagnosis" not in text and "from diagnosis" not in text, path
        assert "import estimation" not in text and "from estimation" not in text, path


def test_write_set_mixed_representations_read_as_trials(tmp_path):
    entries = labsim.write_set(tmp_path, ["nominal", "linear_drift+reflex"], 2, seed=4,
                               representation="mixed", duration_s=2.0)
    assert [e["kind"] for e in entries] == ["nominal"] * 2 + ["linear_drift+reflex"] * 2
    manifest = json.loads((tmp_path / "_labsim_set.truth.json").read_text())
    assert manifest["recordings"] == entries
    trials = trialformat.read_trials(tmp_path, min_samples=1000)
    assert sorted(t.name for t in trials) == sorted(e["name"] for e in entries)
    # blind: neither the names nor the metadata tell the kind
    assert all(e["name"].startswith("rec_") for e in entries)
    for t in trials:
        assert "drift" not in json.dumps(t.meta) and "nominal" not in json.dumps(t.meta)
    for e in entries:
        truth = labsim.read_truth(tmp_path / e["truth"])
        assert truth["kind"] == e["kind"]
        assert e["representation"] in labsim.LAB_REPRESENTATIONS
    # the same seed gives the same set
    again = labsim.write_set(tmp_path / "again", ["nominal", "linear_drift+reflex"], 2, seed=4,
                             representation="mixed", duration_s=2.0)
    assert again == entries
    for e in entries:
        a, b = tmp_path / e["data"], tmp_path / "again" / e["data"]
        if a.suffix == ".mat":  # MATLAB's header holds the creation time: compare arrays
            ta, tb = (trialformat.read_trial(p, min_samples=1000) for p in (a, b))
            assert np.array_equal(ta.tau_h, tb.tau_h) and np.array_equal(ta.theta, tb.theta)
        else:
            assert a.read_bytes() == b.read_bytes()


def test_the_scheduling_variable_reads_as_declared(tmp_path, rec):
    from trialformat.scheduling import scheduling_of
    paths = labsim.write(rec, tmp_path, "moving", "sig8")
    trial = trialformat.read_trial(paths["data"], min_samples=1000)
    sched = scheduling_of(trial)
    assert sched.name == "sv" and sched.units == "rad"
    np.testing.assert_allclose(sched.values, rec.truth["arrays"]["sv"], rtol=5e-8, atol=1e-12)
