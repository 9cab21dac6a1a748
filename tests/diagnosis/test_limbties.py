"""Ties and alternatives on position-servo trials (issue 21, item 3; diagnosis.limbties,
diagnosis.ties): an alternative that explains the held-out gap within 5 points of the
named effect, on the named fit's own split, is reported as indistinguishable, with what
would separate the two; a clear single effect has none; an alternative of another
split is solved again on the named fit's split before it is compared.

labsim recordings (the independent simulator, its own filter and channel forms), 15 s at
1 kHz, a few effects tried: each test takes seconds."""

import json

import numpy as np
import pytest

from diagnosis import limbfit as lf
from diagnosis import limbties as lt
from diagnosis import ties as tr
from labsim_trials import labsim_trial

CHANNEL = ("channel_delay", "torque_sensor_lag", "stretch_reflex", "wobbling_mass")


def _diagnose(trial, effects=CHANNEL, **kw):
    cfg = lf.FitConfig(n_jackknife=0, held_out_fraction=0.4, effects=effects, **kw)
    return lf.diagnose_position([trial], cfg)


@pytest.fixture(scope="module")
def antialias():
    """The issue's case: the torque channel through a second-order anti-alias filter
    (labsim draws 50-200 Hz, damping 0.5-0.9; this one 150 Hz, 0.67)."""
    trial, spec = labsim_trial("antialias_filter", seed=2)
    assert spec.sensors.tau.filter.kind == "second_order"
    return trial, spec


def test_an_antialias_filter_is_a_tie_of_channel_delay_and_sensor_lag(antialias):
    """A 150 Hz second-order filter is, in a 30 Hz band, a phase lag a delay and a
    first-order lag both give: channel_delay is named (99.9 %), torque_sensor_lag closes
    99 %: both are in ``indistinguishable``, with a band above the lag's corner as what
    would separate them."""
    trial, _ = antialias
    d = _diagnose(trial)
    assert d.named == ["channel_delay"], d.ranking[:2]
    assert d.indistinguishable == ["channel_delay", "torque_sensor_lag"], d.alternatives
    row = next(r for r in d.alternatives if r["name"] == "torque_sensor_lag")
    assert row["indistinguishable"] and not row["rescored"]  # the same (default) split
    assert row["held_out_reduction"] > 0.9
    assert "above the sensor's corner" in row["separate"]
    tc = d.ranking[1]["params"]["time_constant_s"]
    assert f"{1 / (2 * np.pi * tc):.0f} Hz" in row["separate"]
    # the others are far behind, or flagged (a negative reflex gain is no alternative)
    for r in d.alternatives:
        if r["name"] != "torque_sensor_lag":
            assert not r["indistinguishable"], r
    json.dumps(d.alternatives)  # the rows go to report.json


@pytest.mark.parametrize("kind,delay,named", [("nominal+reflex", None, "stretch_reflex"),
                                              ("channel_delay", 0.010, "channel_delay")])
def test_a_clear_single_effect_has_no_tie(kind, delay, named):
    """A stretch reflex alone, a 10 ms channel delay alone: named, nothing tied (the
    runner-up a wobbling mass at about 90 % behind a delay's 99.99 %, the reflex's
    runners-up near 0 %)."""
    trial, spec = labsim_trial(kind, seed=2, channel_delay_s=delay)
    d = _diagnose(trial)
    assert d.named == [named], d.ranking[:2]
    assert d.indistinguishable == []
    assert d.alternatives and not any(r["indistinguishable"] for r in d.alternatives)
    best = max(r["held_out_reduction"] for r in d.alternatives if r["nameable"])
    assert best < d.gap["named_held_out_reduction"] - tr.TIE_SHARE


def test_the_rescoring_reproduces_a_fit_on_its_own_split():
    """limbties.score (the alternatives' evaluator, limbpairs.PairProblem with one
    effect) gives, without refinement, a fit's own held-out reduction on its own split:
    a default-split fit's and a time-varying fit's (interleaved blocks)."""
    trial, _ = labsim_trial("saturating_drift", seed=2, seconds=20.0)
    cfg = lf.FitConfig(n_jackknife=0, held_out_fraction=0.4)
    preps = lf.prepare([lf.PositionRecord.from_trial(trial)], cfg)
    nominal = lf.fit_nominal(preps, cfg)
    for name in ("stiffness_saturating", "stiffness_drift", "wobbling_mass"):
        fit = lf.fit_effect(preps, name, nominal, cfg, intervals=False)
        split, text = lt.split_of(preps, (name,), cfg)
        assert (split is None) == (name != "stiffness_saturating"), text
        share, _, _, _ = lt.score(lf, preps, {name: fit.params}, nominal, cfg, split,
                                  refine=False)
        assert share == pytest.approx(fit.held_out_reduction, abs=1e-9), name


def test_runner_ups_of_another_split_are_scored_on_the_named_split():
    """A stiffness drifting and settling (labsim: x2.1 with tau 11 s, 20 s): the named
    stiffness_saturating is judged on interleaved blocks; every default-split runner-up
    is solved again on those blocks (``rescored``), its own figure kept apart. The linear
    drift closes 84 % of the last 40 % (its rate on the search bound there) but 97 % of
    the interleaved blocks, 1.6 points behind the saturating drift's 98.5 %: the two are
    indistinguishable over 20 s, and a longer recording would separate them."""
    trial, _ = labsim_trial("saturating_drift", seed=2, seconds=20.0)
    d = _diagnose(trial, effects=("stiffness_drift", "stiffness_saturating", "channel_delay",
                                  "wobbling_mass"))
    assert d.named == ["stiffness_saturating"], d.ranking[:2]
    for r in d.alternatives:
        assert r["rescored"] and "stiffness_saturating's own split" in r["split"], r
        assert r["own_split"].startswith("the last 40 %")
        assert r["named_held_out_reduction"] == d.gap["named_held_out_reduction"]
    drift = next(r for r in d.alternatives if r["name"] == "stiffness_drift")
    own = next(f for f in d.ranking if f["effect"] == "stiffness_drift")
    assert own["at_search_bound"] and drift["own_held_out_reduction"] < 0.9
    assert drift["held_out_reduction"] > d.gap["named_held_out_reduction"] - tr.TIE_SHARE
    assert drift["nameable"] and drift["indistinguishable"]
    assert d.indistinguishable == ["stiffness_saturating", "stiffness_drift"]
    assert "a longer recording" in drift["separate"]
    # the named model on an alternative's own split is solved for the reader only where
    # the ranking invites the comparison (its own figure within 5 points): not here
    assert all(r["named_on_own_split"] is None for r in d.alternatives)


def test_separation_advice_is_specific_to_the_pair():
    adv = tr.separation(("channel_delay",), {"channel_delay": {"delay_s": 0.002}},
                        ("torque_sensor_lag",), {"torque_sensor_lag": {"time_constant_s": 0.002}},
                        30.0)
    assert "above the sensor's corner (1 / (2 pi T) = 80 Hz for the fitted lag; these " \
           "trials are analysed to 30 Hz)" in adv
    assert "EMG" in tr.separation(("stiffness_angle",), {}, ("stretch_reflex",), {})
    assert "another perturbation amplitude" in tr.separation(
        ("stiffness_amplitude",), {}, ("wobbling_mass",), {})
    assert "resonance (fitted at 12.0 Hz" in tr.separation(
        ("channel_delay",), {}, ("wobbling_mass",), {"wobbling_mass": {"frequency_hz": 12.0}})
    # a pair against a pair: the effects they share separate nothing
    assert "above the sensor's corner" in tr.separation(
        ("stretch_reflex", "channel_delay"), {}, ("stretch_reflex", "torque_sensor_lag"), {})
    assert tr.separation(("gravity",), {}, ("friction",), {}) == tr.GENERIC


def test_the_report_gives_the_tie_in_report_md_and_report_json(antialias, tmp_path):
    """The whole diagnosis (armimp diagnose) of the anti-alias trial, written: report.json
    ``indistinguishable`` beside ``named_effects`` and the ``alternatives`` rows;
    report.md says they cannot be told apart and what would separate them."""
    import trialformat as tf
    from diagnosis.config import DiagnosisConfig
    from diagnosis.core import diagnose
    trial, _ = antialias
    trial.name = "aa"
    (tmp_path / "in").mkdir()
    tf.write_trial(tmp_path / "in" / trial.name, trial)
    diagnose(tmp_path / "in", tmp_path / "out", workers=1, progress=False,
             config=DiagnosisConfig(effects=CHANNEL))
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert rep["named_effects"] == ["channel_delay"], rep["summary"]
    assert rep["indistinguishable"] == ["channel_delay", "torque_sensor_lag"], rep["summary"]
    assert rep["alternatives"][0]["name"] == "torque_sensor_lag"
    md = (tmp_path / "out" / "report.md").read_text()
    assert "cannot tell them apart" in md and "above the sensor's corner" in md
    assert "| torque_sensor_lag |" in md and "**yes**" in md


def test_one_shape_for_the_exoskeleton_ranking_with_a_named_pair():
    """The exoskeleton's fits share one held-out split: its alternatives are read from
    the ranking (ties.rows_from_fits), in the same row shape. To a named pair A + B: the
    other pairs A + C and the singles other than A and B (A alone is the pair's own
    first step, not an alternative)."""
    from types import SimpleNamespace

    from diagnosis.pipeline.verdict import alternatives_of

    def fit(effects, share, nameable=True):
        return SimpleNamespace(effects=tuple(effects), nameable=nameable,
                               held_out_gap=1.0 - share,
                               params={e: {"time_constant_s": 0.002} for e in effects})
    singles = [fit(["gravity"], 0.60), fit(["delay"], 0.20), fit(["actuator_lag"], 0.93)]
    pairs = [fit(["gravity", "delay"], 0.95), fit(["gravity", "actuator_lag"], 0.93),
             fit(["gravity", "friction"], 0.50)]
    r = SimpleNamespace(singles=singles, pairs=pairs, g0_held=1.0, alternatives=None)
    rows = alternatives_of(r, pairs[0])
    assert [x["name"] for x in rows] == ["actuator_lag", "gravity + actuator_lag",
                                         "gravity + friction"]
    assert [x["indistinguishable"] for x in rows] == [True, True, False]
    assert rows[0]["split"] == "the held-out units every fit shares"
    # delay against actuator_lag: the actuator's corner (1 / (2 pi 2 ms) = 80 Hz)
    assert "above the actuator lag's corner (1 / (2 pi T) = 80 Hz" in rows[0]["separate"]
    assert rows[1]["separate"] == rows[0]["separate"]
    from diagnosis import ties as t
    assert t.indistinguishable(rows, pairs[0].effects) == [
        "gravity + delay", "actuator_lag", "gravity + actuator_lag"]
