"""Options that do not apply to an input never cost the user the K-B-I result.

- ``--reflex`` on a recording shorter than the reflex fit needs: the K-B-I result is
  printed and written, the reflex part says why (the minimum length named), exit 0;
- ``--reflex`` on a folder with a two-joint condition: the reflex fit where it is defined,
  the usual result elsewhere, one note naming the condition, exit 0;
- ``--segments`` larger than a recording allows: refused naming the option, the value and
  the largest that works; the largest itself works; the default says when it does less.
"""

import json

import numpy as np
import pytest

import trialformat as tf
from estimation import lab
from estimation.errors import EstimationError
from estimation.reflex import (ReflexNotApplicable, ReflexOptions, fit_reflex,
                               minimum_samples)
from estimation.synthetic import synthetic_trial
from estimation.synthetic_reflex import parallel_cascade, parallel_cascade_trial


def test_minimum_samples_is_the_boundary():
    opts = ReflexOptions(segments=3, delay_ms=(20.0, 80.0))
    need = minimum_samples(opts, 1000.0)
    # 1 s + 80 ms + 2 working samples skipped, then 3 blocks of 1 s at 500 Hz
    assert need == (int(np.ceil(500.0)) + 40 + 2 + 1500 - 1) * 2 + 1
    sim = parallel_cascade(duration_s=need / 1000.0 + 0.5, seed=3)
    th, tq = sim["theta"], sim["tau"]
    fit_reflex(th[:need], tq[:need], 1000.0, opts)  # the minimum itself fits
    with pytest.raises(ReflexNotApplicable, match=f"minimum of {need / 1000:.4g} s"):
        fit_reflex(th[:need - 1], tq[:need - 1], 1000.0, opts)


def test_short_recording_keeps_kbi(tmp_path, capsys):
    from orchestrator.cli import main
    tf.write_trial(tmp_path / "data" / "short9", parallel_cascade_trial("short9",
                                                                        duration_s=9.0))
    out_json = tmp_path / "r.json"
    assert main(["estimate", str(tmp_path / "data"), "--reflex", "--json",
                 str(out_json)]) == 0
    out = capsys.readouterr().out
    assert "Z: K=" in out  # the K-B-I result is printed
    need = minimum_samples(None, 1000.0) / 1000.0
    assert (f"warning: reflex fit not done for short9: the recording has 9 s (9000 "
            f"samples), fewer than the minimum of {need:.4g} s") in out
    doc = json.loads(out_json.read_text())[0]
    assert doc["parameters"]["K"]["value"][0][0] > 0
    assert doc["reflex"] == [] and doc["reflex_not_fitted"][0]["kind"] == "short"
    assert any("reflex fit not done" in w for w in doc["warnings"])


@pytest.fixture(scope="module")
def mixed_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mixed")
    tf.write_trial(folder / "pc", parallel_cascade_trial("pc", duration_s=20.0, seed=6))
    for k in (1, 2):
        t = synthetic_trial(perturbed_dof=k, duration_s=20.0, name=f"arm2_dof{k}")
        t.meta["condition"] = "arm2"
        tf.write_trial(folder / f"arm2_dof{k}", t)
    return folder


def test_two_joint_condition_in_a_folder(mixed_folder, tmp_path, capsys):
    from orchestrator.cli import main
    assert main(["estimate", str(mixed_folder), "--reflex", "--segments", "0", "--json",
                 str(tmp_path / "r.json")]) == 0
    cap = capsys.readouterr()
    assert "arm2: method=full" in cap.out and "Z22: K=" in cap.out
    assert "reflex (parallel cascade, pc, joint 1" in cap.out
    notes = [line for line in cap.err.splitlines() if "--reflex" in line]
    assert len(notes) == 1 and "arm2 (2 joints)" in notes[0], cap.err
    assert "error" not in cap.err
    doc = {d["condition"]: d for d in json.loads((tmp_path / "r.json").read_text())}
    assert doc["arm2"]["reflex"] == []
    assert {s["kind"] for s in doc["arm2"]["reflex_not_fitted"]} == {"joints"}
    assert len(doc["pc"]["reflex"]) == 1


def _noref():
    from estimation.synthetic import position_trial
    return position_trial(K=80.0, B=1.2, I=0.012, duration_s=30.0, seed=2,
                          name="rec30", record_reference=False)


def test_segments_beyond_the_data_refused_naming_the_largest(tmp_path):
    trial = _noref()
    unit = lab.Unit("rec30", [trial], "single recording")
    base = dict(sensitivity=False, band_hz=(0.0, 30.0))
    band = (0.0, 30.0)
    top = lab.max_time_segments(trial.n_samples, band, lab.AnalysisOptions(**base), trial.fs)
    # by hand: a Welch segment of >= 256 samples with >= 12 bins in 0-30 Hz at 1 kHz
    # (256: one bin every 3.9 Hz, 8 bins; 512: 16 bins) -> time segments of >= 2048 samples
    assert top == trial.n_samples // 2048
    with pytest.raises(EstimationError, match=rf"--segments 100000: .*rec30 .*largest that "
                                              rf"works for it is --segments {top}\b"):
        lab.analyse(unit, lab.AnalysisOptions(segments=100000, **base))
    with pytest.raises(EstimationError, match=f"--segments {top + 1}:"):
        lab.analyse(unit, lab.AnalysisOptions(segments=top + 1, **base))
    r = lab.analyse(unit, lab.AnalysisOptions(segments=top, **base))
    assert len(r.segments) == top
    assert not any("time-variation" in w for w in r.warnings)


def test_segments_cli_refusal_same_for_estimate_and_figures(tmp_path, capsys):
    from orchestrator.cli import main
    tf.write_trial(tmp_path / "data" / "rec30", _noref())
    for cmd in (["estimate", str(tmp_path / "data")],
                ["figures", str(tmp_path / "data"), "--out", str(tmp_path / "rep")]):
        assert main(cmd + ["--segments", "100000"]) == 1
        err = capsys.readouterr().err
        assert "--segments 100000" in err and "largest that works for it is --segments" in err
    assert not (tmp_path / "rep").exists()


def test_default_segments_on_a_short_recording_says_so():
    trial = parallel_cascade_trial("short9", duration_s=9.0)
    r = lab.analyse(lab.Unit("short9", [trial], "single recording"),
                    lab.AnalysisOptions(sensitivity=False))
    top = lab.max_time_segments(trial.n_samples, r.band_hz, lab.AnalysisOptions(), trial.fs)
    assert 2 <= top < 4 and len(r.segments) == top
    assert any(w.startswith(f"{top} fixed time segments (results.json segments), not 4")
               for w in r.warnings)
    with pytest.raises(EstimationError, match="--segments must be"):
        lab.AnalysisOptions(segments=1).check()


# ------------------------------------------------------------------ the reflex in the report


def test_reflex_frequency_response_matches_the_measured_frf():
    """The drawn total model against an independent answer: the H1 estimate (scipy's
    csd / welch) of the simulated recording. Linear pathway: the total matches where the
    multisine has power; the K-B-I part alone does not (the reflex is visible)."""
    from scipy import signal
    sim = parallel_cascade(rectify="none", duration_s=40.0, seed=5, noise=0.01)
    r = fit_reflex(sim["theta"], sim["tau"], 1000.0, ReflexOptions(rectify="none"))
    assert r.linear_gain == pytest.approx(1.0, abs=1e-9)
    f, pxy = signal.csd(sim["theta"], sim["tau"], fs=1000.0, nperseg=8192)
    _, pxx = signal.welch(sim["theta"], fs=1000.0, nperseg=8192)
    sel = (f > 0.3) & (f < 10.0)
    h1 = pxy[sel] / pxx[sel]
    resp = r.frequency_response(f[sel])
    rel_total = np.abs(resp["total"] - h1) / np.abs(h1)
    rel_intr = np.abs(resp["intrinsic"] - h1) / np.abs(h1)
    assert np.median(rel_total) < 0.02, np.median(rel_total)
    assert np.median(rel_intr) > 5 * np.median(rel_total)
    np.testing.assert_allclose(resp["total"], resp["intrinsic"] + resp["reflex"])


def test_rectified_pathway_linear_gain_is_bussgangs():
    sim = parallel_cascade(duration_s=20.0, seed=8)
    r = fit_reflex(sim["theta"], sim["tau"], 1000.0, ReflexOptions(segments=4))
    assert r.rectify == "positive" and 0.4 < r.linear_gain < 0.6  # symmetric velocity: 1/2


def test_figures_draw_and_list_the_reflex(tmp_path):
    import csv
    from estimation.labreport import bode, write_lab_report
    trial = parallel_cascade_trial("pc", duration_s=20.0, seed=4)
    res = lab.analyse(lab.Unit("pc", [trial], "single recording"),
                      lab.AnalysisOptions(reflex=ReflexOptions(segments=4), segments=0))
    fit = res.reflex[0]
    fig = bode(res)
    ax_m, ax_p = fig.axes[0], fig.axes[1]
    lines = {ln.get_label(): ln for ln in ax_m.get_lines()}
    for part in ("intrinsic", "reflex", "total"):
        ln = lines[f"{part} (parallel cascade)"]
        f = np.asarray(ln.get_xdata())
        np.testing.assert_allclose(ln.get_ydata(), np.abs(fit.frequency_response(f)[part]))
    assert len(ax_p.get_lines()) >= 5  # estimate, fitted model, and the three pathways
    text = "\n".join(t.get_text() for t in fig.texts)
    assert "intrinsic + reflex, parallel cascade (pc" in text and "VAF intrinsic" in text
    write_lab_report([res], tmp_path / "rep")
    rows = list(csv.DictReader(open(tmp_path / "rep" / "parameters.csv")))
    pc = [r for r in rows if r["model"].startswith("intrinsic + reflex")]
    assert len(pc) == 1 and float(pc[0]["delay_ms [ms]"]) == pytest.approx(
        fit.values["delay_ms"]) and float(pc[0]["VAF_total [%]"]) == pytest.approx(
        fit.vaf_pct["total"])
    assert float(pc[0]["G_ci [N m s/rad]"]) == pytest.approx(fit.ci["G"])
    md = (tmp_path / "rep" / "parameters.md").read_text()
    assert "Intrinsic and reflex pathways" in md and "VAF I / R / total" in md
    doc = json.loads((tmp_path / "rep" / "results.json").read_text())
    p = doc["results"][0]["reflex"][0]
    assert p["parameters"]["delay_ms"]["ci_half_width"] == pytest.approx(fit.ci["delay_ms"])
    assert p["vaf_pct"]["total"] == pytest.approx(fit.vaf_pct["total"])
    assert p["linear_gain"] == pytest.approx(fit.linear_gain)


def test_no_reflex_asked_report_unchanged(tmp_path):
    import csv
    from estimation.labreport import write_lab_report
    trial = parallel_cascade_trial("pc", duration_s=12.0, seed=4)
    res = lab.analyse(lab.Unit("pc", [trial], "single recording"),
                      lab.AnalysisOptions(segments=0, sensitivity=False))
    write_lab_report([res], tmp_path / "rep")
    rows = list(csv.DictReader(open(tmp_path / "rep" / "parameters.csv")))
    assert "model" not in rows[0] and len(rows) == 1
    assert not (tmp_path / "rep" / "reflex.csv").exists()


def test_slowly_sampled_recording_keeps_kbi():
    trial = parallel_cascade_trial("slow", duration_s=60.0, fs=100.0, f_max_hz=10.0)
    res = lab.analyse(lab.Unit("slow", [trial], "single recording"),
                      lab.AnalysisOptions(reflex=True, nperseg=1024, segments=0,
                                          sensitivity=False))
    assert res.fit.K[0, 0] > 0 and res.reflex == []
    assert res.reflex_not_fitted[0]["kind"] == "rate"
    assert any(w.startswith("reflex fit not done for slow: lowpass_hz 40 Hz") and
               "100 Hz" in w for w in res.warnings)
