"""The diagnosis's "when" stage (diagnosis.pipeline.when, issue 20 item 1): on a labsim
recording whose stiffness drifts, `estimate` and `diagnose` agree (one shared test); the
report says when the gap lies (report.json gap_in_time, report.md, gap_time.png)."""

import json

import numpy as np

import labsim
import trialformat as tf
from diagnosis.core import diagnose
from estimation.lab import analyse, estimation_units


def test_estimate_and_diagnose_agree_on_a_linear_drift(tmp_path):
    spec = labsim.draw("linear_drift", np.random.default_rng([0, 7]), duration_s=30.0)
    rec = labsim.simulate(spec)
    labsim.write(rec, tmp_path / "data", "drift")
    K0, ratio = spec.limb.K, spec.limb.K_var.ratio
    assert abs(ratio - 1) > 0.2          # a drift a lab would act on (the draw's truth)

    trials = tf.read_trials(tmp_path / "data")
    est = analyse(estimation_units(trials)[0])
    tv_est = [w for w in est.warnings if w.startswith("time-varying: ")]
    assert tv_est and "linear drift" in tv_est[0], est.warnings

    rep = diagnose(tmp_path / "data", out_dir=tmp_path / "rep", workers=1, progress=False)
    when = rep.gap_in_time
    assert when["time_varying"] and rep.gap["significant"]
    assert rep.verdict != "no significant gap"
    tv = when["trials"][0]
    assert tv["shape"] == "linear drift" and tv["message"] in tv_est[0]
    # the blocks follow the truth's direction and end near its end levels
    ks = [b["K"][0] for b in tv["blocks"]]
    assert np.sign(ks[-1] - ks[0]) == np.sign(ratio - 1)
    assert min(ks) > 0.9 * min(K0, K0 * ratio) and max(ks) < 1.1 * max(K0, K0 * ratio)
    assert "In time:" in rep.summary
    js = json.loads((tmp_path / "rep" / "report.json").read_text())
    assert js["gap_in_time"]["blocks"] and all("gap" in b for b in js["gap_in_time"]["blocks"])
    assert "## When: the gap in time" in (tmp_path / "rep" / "report.md").read_text()
    assert (tmp_path / "rep" / "gap_time.png").stat().st_size > 1000


def test_a_stationary_recording_has_no_time_finding(tmp_path):
    spec = labsim.draw("nominal_coloured_noise", np.random.default_rng([1, 7]),
                       duration_s=30.0)
    labsim.write(labsim.simulate(spec), tmp_path / "data", "still")
    trials = tf.read_trials(tmp_path / "data")
    est = analyse(estimation_units(trials)[0])
    assert not any(w.startswith("time-varying") for w in est.warnings), est.warnings
    from diagnosis.pipeline.when import markdown
    from estimation.timevarying import of_trials
    found, lines = of_trials(trials)
    assert not found[0]["time_varying"] and lines == []
    text = "\n".join(markdown({"time_varying": False, "alpha": 1e-3, "trials": found,
                               "blocks": [], "notes": []}))
    assert "finds no change" in text
