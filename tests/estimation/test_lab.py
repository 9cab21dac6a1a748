"""Lab data in, results out: known answers through the CLI, grouping, options, warnings.

Known answers come from estimation.synthetic: a 1-DOF limb on a position servo
(frequency-domain generation, exact at every DFT bin), the 1-DOF and 3-joint linear closed
loops simulated by scipy.signal.lsim. 50 s of data, realistic noise.
"""

import json

import numpy as np
import pytest

import trialformat as tf
from estimation import EstimationError, fit_second_order
from estimation.cli import main
from estimation.lab import AnalysisOptions, Unit, analyse, estimation_units
from estimation.synthetic import (ARM_3DOF, CONTROLLER_3DOF, PEAK_3DOF, position_trial,
                                  synthetic_trial)

ANKLE = {"K": 150.0, "B": 1.5, "I": 0.015}
ANKLE_CTRL = {"M_rd": [0.005], "B_rd": [0.5], "K_rd": [10.0], "theta_rd_deg": [0.0],
              "Mbar": [0.005], "wn": [150.0], "tuning": "ankle"}


def _ankle_torque(seed=3, **kw):
    arm = (np.array([[ANKLE["I"]]]), np.array([[ANKLE["B"]]]), np.array([[ANKLE["K"]]]))
    return synthetic_trial(perturbed_dof=1, arm=arm, controller=ANKLE_CTRL, peak=[10.0],
                           seed=seed, theta_noise_std_rad=2e-5, tau_noise_std_nm=0.1,
                           name=f"ankle_torque{seed}", **kw)


def _check_1dof(result, K=ANKLE["K"], B=ANKLE["B"], I=ANKLE["I"]):
    p = result["parameters"]
    assert p["K"]["value"][0][0] == pytest.approx(K, rel=0.02)
    assert p["M"]["value"][0][0] == pytest.approx(I, rel=0.02)
    assert p["B"]["value"][0][0] == pytest.approx(B, rel=0.05)
    assert p["K"]["unit"] == "N m/rad" and p["M"]["unit"] == "kg m^2"


@pytest.fixture(scope="module")
def ankle_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ankle")
    tf.write_trial(folder / "pos_ref", position_trial(**ANKLE, seed=1, torque_sign=-1))
    tf.write_trial(folder / "pos_noref", position_trial(**ANKLE, seed=2,
                                                       record_reference=False))
    tf.write_trial(folder / "torque", _ankle_torque())
    return folder


def test_1dof_position_and_torque_from_the_cli(ankle_folder, tmp_path, capsys):
    out = tmp_path / "est.json"
    assert main(["estimate", str(ankle_folder), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "I=" in text and "Z12" not in text
    results = {r["label"]: r for r in json.loads(out.read_text())}
    assert set(results) == {"pos_ref", "pos_noref", "torque"}  # never averaged together
    assert results["pos_ref"]["method"] == "full"
    assert results["pos_noref"]["method"] == "direct"
    assert results["torque"]["method"] == "full"
    for r in results.values():
        _check_1dof(r)
        assert r["corrections"]["left_limit_sampling"] is False  # lab data: instantaneous
    assert any("direct estimate" in w for w in results["pos_noref"]["warnings"])
    assert results["pos_ref"]["warnings"] == []


def test_figures_lab_report(ankle_folder, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["figures", str(ankle_folder), "--out", str(out)]) == 0
    names = {p.name for p in out.iterdir()}
    for label in ("pos_ref", "pos_noref", "torque"):
        assert {f"frf_{label}.csv", f"frf_{label}.json", f"bode_{label}.png"} <= names
    assert {"parameters.csv", "parameters.md", "results.json"} <= names
    frf = json.loads((out / "frf_pos_ref.json").read_text())
    assert frf["units"]["Z11_mag"] == "N m/rad" and frf["units"]["Z11_phase_deg"] == "deg"
    assert frf["units"]["Z11_coherence"] == "-"
    header = (out / "frf_pos_ref.csv").read_text().splitlines()[0]
    assert header.startswith("f_Hz [Hz],in_band [-],Z11_mag [N m/rad]")
    doc = json.loads((out / "results.json").read_text())
    assert doc["options"]["band_hz"] is None and len(doc["results"]) == 3


def test_three_joints_from_the_cli(tmp_path, capsys):
    for k in (1, 2, 3):
        tf.write_trial(tmp_path / "in" / f"arm3_dof{k}", synthetic_trial(
            perturbed_dof=k, arm=ARM_3DOF, controller=CONTROLLER_3DOF, peak=PEAK_3DOF,
            seed=10 + k, theta_noise_std_rad=1e-5, tau_noise_std_nm=0.02))
    out = tmp_path / "est.json"
    assert main(["estimate", str(tmp_path / "in"), "--truth", "reference-3dof",
                 "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert all(f"Z{i}{k}" in text for i in (1, 2, 3) for k in (1, 2, 3))
    (r,) = json.loads(out.read_text())
    err = {p: np.abs(np.array(v)) for p, v in r["errors_pct"].items()}
    diag = np.eye(3, dtype=bool)
    assert err["K"][diag].max() < 2 and err["M"][diag].max() < 2 and err["B"][diag].max() < 5
    assert err["K"].max() < 2 and err["M"].max() < 2  # off-diagonal too
    assert main(["figures", str(tmp_path / "in"), "--out", str(tmp_path / "rep")]) == 0
    frf = json.loads((tmp_path / "rep" / "frf_F0R0P3.json").read_text())
    assert "Z33_mag" in frf["columns"] and "Z13_coherence" in frf["columns"]


def test_unlabelled_recordings_are_never_averaged_silently():
    trials = [position_trial(**ANKLE, seed=s, name=f"rec{s}") for s in range(3)]
    units = estimation_units(trials)
    assert [u.label for u in units] == ["rec0", "rec1", "rec2"]
    for t in trials[:2]:
        t.meta["condition"] = "relaxed"
    units = estimation_units(trials)
    assert [(u.label, len(u.trials)) for u in units] == [("rec2", 1), ("relaxed", 2)]
    assert len(estimation_units(trials, pool=True)) == 2  # labels still separate
    assert len(estimation_units(trials[2:] * 1, pool=True)) == 1


def test_two_joint_duplicates_need_a_label():
    trials = [synthetic_trial(perturbed_dof=k, seed=s, duration_s=10.0, name=f"d{k}s{s}")
              for k in (1, 2) for s in (0, 1)]
    with pytest.raises(EstimationError, match=r"'condition' label.*--pool"):
        estimation_units(trials)
    for t in trials:
        t.meta["condition"] = f"session{t.name[-1]}"
    assert [len(u.trials) for u in estimation_units(trials)] == [2, 2]


def test_r2_reads_one_for_any_perfect_fit():
    f = np.linspace(0.1, 15, 120)
    for Z in (np.full(f.shape, 80.0 + 0j),                       # pure spring
              80.0 + 1j * 2 * np.pi * f * 0.8,                   # spring and damper
              -0.02 * (2 * np.pi * f) ** 2 + 0j):                # pure mass
        fit = fit_second_order(f, Z, band_hz=(0, 15))
        assert fit.r2 == pytest.approx(1.0, abs=1e-9)
    noisy = fit_second_order(f, np.full(f.shape, 80.0) * (1 + 0.1j * np.sin(9 * f)),
                             band_hz=(0, 15))
    assert 0.98 < noisy.r2 < 1.0


def test_options_band_segment_window_and_corrections():
    trial = position_trial(**ANKLE, seed=4)
    unit = Unit("a", [trial], "")
    low = analyse(unit, AnalysisOptions(band_hz=(0.0, 3.0)))
    assert low.band_hz == (0.0, 3.0) and low.band_source == "set by the user"
    assert any("I poorly determined" in w for w in low.warnings)  # one joint: I
    short = analyse(unit, AnalysisOptions(nperseg=4096, noverlap=2048, window="hamming",
                                          leakage_correction="off"))
    assert short.welch["nperseg"] == 4096 and short.n_segments == 23
    assert short.corrections["window_leakage"] is False
    with pytest.raises(EstimationError, match="leakage correction needs"):
        analyse(unit, AnalysisOptions(window="hamming", leakage_correction="on"))
    on = analyse(unit, AnalysisOptions(sampling_correction="on"))
    assert on.corrections["inertia_delay_s"] == pytest.approx(0.5e-3)
    trial.meta["sensors"]["torque_sampling"] = "left_limit"
    assert analyse(unit).corrections["left_limit_sampling"] is True


def test_warnings_non_physical_and_low_coherence():
    neg = position_trial(K=-20.0, B=1.5, I=0.015, seed=5,  # held by the stiff servo
                         voluntary_rms_nm=0.05)
    r = analyse(Unit("neg", [neg], ""))
    assert r.fit.K[0, 0] == pytest.approx(-20.0, rel=0.1)
    assert any("non-physical fit: K = " in w and "negative" in w for w in r.warnings)
    weak = position_trial(**ANKLE, seed=6, ref_rms_rad=2e-4, voluntary_rms_nm=2.0,
                          voluntary_hz=20.0, tau_noise_std_nm=1.0)
    r = analyse(Unit("weak", [weak], ""))
    assert any(w.startswith("low coherence") for w in r.warnings)


def test_failed_figures_leave_no_partial_report(ankle_folder, tmp_path, monkeypatch):
    import estimation.labreport as lr
    out = tmp_path / "rep"
    calls = []

    def boom(result):
        calls.append(result.label)
        if len(calls) == 2:
            raise RuntimeError("disk full")
        return orig(result)
    orig = lr.bode
    monkeypatch.setattr(lr, "bode", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        main(["figures", str(ankle_folder), "--out", str(out)])
    assert not out.exists() and list(tmp_path.iterdir()) == []
    out.mkdir()  # an earlier report of ours (marked), kept whole by a failed one
    (out / "old.txt").write_text("previous report")
    (out / tf.logs.REPORT_MARK).write_text("{}")
    calls.clear()
    with pytest.raises(RuntimeError):
        main(["figures", str(ankle_folder), "--out", str(out)])
    assert sorted(p.name for p in out.iterdir()) == [tf.logs.REPORT_MARK, "old.txt"]


def test_worked_example_ankle(tmp_path, capsys):
    """docs/estimation.md's example: lab-style files (7 digits, t with 6 decimals, torque
    sign -1), two labelled conditions and an unlabelled recording without reference."""
    from estimation.examples import ANKLE_CONDITIONS, main as examples_main
    assert examples_main(["ankle", str(tmp_path / "ankle")]) == 0
    out = tmp_path / "est.json"
    assert main(["estimate", str(tmp_path / "ankle"), "--json", str(out)]) == 0
    results = {r["label"]: r for r in json.loads(out.read_text())}
    assert set(results) == {"relaxed", "co-contracted", "relaxed_noref"}
    assert len(results["relaxed"]["trials"]) == 2
    for label, r in results.items():
        limb = ANKLE_CONDITIONS[label.replace("_noref", "")]
        _check_1dof(r, **limb)


def test_reports_get_the_umask(ankle_folder, tmp_path):
    import os
    old = os.umask(0o022)
    try:
        assert main(["figures", str(ankle_folder), "--out", str(tmp_path / "rep")]) == 0
        assert (tmp_path / "rep").stat().st_mode & 0o777 == 0o755
        assert all(p.stat().st_mode & 0o777 == 0o644 for p in (tmp_path / "rep").iterdir())
    finally:
        os.umask(old)
