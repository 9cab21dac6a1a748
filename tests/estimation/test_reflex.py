"""Intrinsic + reflex (parallel-cascade) identification against known answers.

The recordings come from estimation.synthetic_reflex (analytic multisine angle, reflex
activation simulated in continuous time by scipy.signal.lsim), independent of the fit's
discrete filters, differences and grid.
"""

import json

import numpy as np
import pytest

import trialformat as tf
from estimation import lab
from estimation.errors import EstimationError
from estimation.reflex import ReflexOptions, fit_reflex, fit_reflex_trial
from estimation.synthetic_reflex import parallel_cascade, parallel_cascade_trial

# Stated tolerances of the known-answer test (30 s at 1 kHz, torque noise 5 % of its std)
TOL_REL = {"K": 0.02, "B": 0.03, "I": 0.03, "G": 0.03, "cutoff_hz": 0.10, "damping": 0.10}
TOL_DELAY_MS = 2.0


def _check(result, truth):
    v = result.values
    for p, tol in TOL_REL.items():
        assert abs(v[p] - truth[p]) <= tol * abs(truth[p]), (p, v[p], truth[p])
    assert abs(v["delay_ms"] - truth["delay_ms"]) <= TOL_DELAY_MS, (v["delay_ms"], truth)


@pytest.mark.parametrize("delay_s", [0.030, 0.045, 0.060])
def test_known_reflex_delays(delay_s):
    sim = parallel_cascade(delay_s=delay_s, duration_s=30.0, seed=int(delay_s * 1000))
    r = fit_reflex(sim["theta"], sim["tau"], 1000.0)
    _check(r, sim["truth"])
    assert r.rectify == "positive" and r.resists_stretch
    assert r.vaf_pct["total"] > 99.0
    assert r.vaf_pct["total"] - r.vaf_pct["intrinsic_only"] > 3.0
    assert not r.warnings
    assert all(r.ci[p] > 0 for p in r.ci)


def test_other_pathway_shapes_and_intervals_cover():
    """Negative rectification with another intrinsic set, found by rectify='auto'; a noisy
    recording whose jackknife intervals cover the truth."""
    sim = parallel_cascade(K=150.0, B=2.0, I=0.02, G=-6.0, delay_s=0.040, cutoff_hz=2.0,
                           damping=0.9, rectify="negative", duration_s=30.0, seed=3)
    r = fit_reflex(sim["theta"], sim["tau"], 1000.0)
    _check(r, sim["truth"])
    assert r.rectify == "negative" and r.resists_stretch
    noisy = parallel_cascade(noise=1.0, duration_s=30.0, seed=11)
    r = fit_reflex(noisy["theta"], noisy["tau"], 1000.0, ReflexOptions(segments=6))
    for p in ("K", "B", "I", "G", "delay_ms"):
        err = abs(r.values[p] - noisy["truth"][p])
        assert err <= 2 * r.ci[p], (p, r.values[p], r.ci[p], noisy["truth"][p])
    assert r.ci["K"] > 1.0  # the noise shows in the interval (about 0.05 at 5 % noise)


def test_no_reflex_is_said_and_intrinsic_kept():
    sim = parallel_cascade(G=0.0, duration_s=30.0, seed=5)
    r = fit_reflex(sim["theta"], sim["tau"], 1000.0, ReflexOptions(segments=4))
    for p, tol in (("K", 0.01), ("B", 0.02), ("I", 0.02)):
        assert abs(r.values[p] - sim["truth"][p]) <= tol * sim["truth"][p]
    assert any("no reflex detected" in w for w in r.warnings)


def test_linear_pathway_option():
    sim = parallel_cascade(rectify="none", G=3.0, delay_s=0.050, duration_s=30.0, seed=2)
    r = fit_reflex(sim["theta"], sim["tau"], 1000.0, ReflexOptions(rectify="none", segments=4))
    _check(r, sim["truth"])


def test_same_numbers_every_run_and_from_csv(tmp_path):
    trial = parallel_cascade_trial("pc", duration_s=20.0, seed=9, delay_s=0.035)
    opts = ReflexOptions(segments=4)
    a, b = fit_reflex_trial(trial, opts), fit_reflex_trial(trial, opts)
    tf.write_trial(tmp_path / "pc", trial)
    c = fit_reflex_trial(tf.read_trial(tmp_path / "pc.csv", min_samples=1000), opts)
    assert a.values == b.values == c.values and a.ci == b.ci == c.ci


def test_lab_option_json_and_report(tmp_path):
    trial = parallel_cascade_trial("pc", duration_s=20.0, seed=4)
    opts = lab.AnalysisOptions(reflex=ReflexOptions(segments=4))
    res = lab.analyse(lab.Unit("pc", [trial], "single recording"), opts)
    assert len(res.reflex) == 1 and abs(res.reflex[0].values["delay_ms"] - 45) < 2
    doc = res.to_json()["reflex"][0]
    assert doc["parameters"]["delay_ms"]["unit"] == "ms"
    json.dumps(doc)
    from estimation.labreport import write_lab_report
    files = write_lab_report([res], tmp_path / "rep")
    md = (tmp_path / "rep" / "reflex.md").read_text()
    assert "Intrinsic and reflex pathways" in md and "pc (positive)" in md
    assert str(tmp_path / "rep" / "reflex.csv") in files


def test_cli_reflex(tmp_path, capsys):
    from orchestrator.cli import main
    tf.write_trial(tmp_path / "data" / "pc", parallel_cascade_trial("pc", duration_s=20.0,
                                                                    seed=6))
    assert main(["estimate", str(tmp_path / "data"), "--reflex", "--json",
                 str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert "reflex (parallel cascade, pc" in out and "delay=" in out
    doc = json.loads((tmp_path / "r.json").read_text())
    assert abs(doc[0]["reflex"][0]["parameters"]["delay_ms"]["value"] - 45) < 2


def test_refusals():
    sim = parallel_cascade(duration_s=10.0)
    with pytest.raises(EstimationError, match="rectify"):
        fit_reflex(sim["theta"], sim["tau"], 1000.0, ReflexOptions(rectify="half"))
    with pytest.raises(EstimationError, match="delay_ms"):
        fit_reflex(sim["theta"], sim["tau"], 1000.0, ReflexOptions(delay_ms=(50, 20)))
    with pytest.raises(EstimationError, match="samples"):
        fit_reflex(sim["theta"], sim["tau"][:-1], 1000.0)
    with pytest.raises(EstimationError, match="non-finite"):
        bad = sim["tau"].copy()
        bad[5] = np.nan
        fit_reflex(sim["theta"], bad, 1000.0)
    with pytest.raises(EstimationError, match="fewer than the minimum of 9.123 s"):
        fit_reflex(sim["theta"][:2000], sim["tau"][:2000], 1000.0)
    trial = parallel_cascade_trial(duration_s=10.0)
    trial.meta["n_dof"] = 2
    with pytest.raises(EstimationError, match="one joint"):
        fit_reflex_trial(trial)
