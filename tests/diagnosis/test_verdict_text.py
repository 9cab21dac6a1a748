"""The "unexplained" sentence says why the best-ranked fit was not named (a new user read
"no catalogue effect closes half of the gap" beside a ranking whose first row closed 59 %)."""

from diagnosis import catalogue as cat
from diagnosis.fitting import EffectFit
from diagnosis.pipeline.verdict import verdict_text

RESIDUAL = None
AMPLITUDE = {"amplitude_dependent": False}


def _fit(delay_s, held_out_gap):
    spec = {p.name: p for p in cat.get_effect("stretch_reflex").parameters}
    params = {name: (delay_s if name == "delay_s" else p.realistic[0] * 0.5
                     + p.realistic[1] * 0.5) for name, p in spec.items()}
    return EffectFit(effects=("stretch_reflex",), params={"stretch_reflex": params},
                     calibration_gap=0.05, n_evaluations=1, held_out_gap=held_out_gap)


def _text(best, monkeypatch):
    monkeypatch.setattr("diagnosis.pipeline.verdict.rest_where", lambda residual: ["x"])
    return verdict_text("unexplained", [], None, 0.1, RESIDUAL, AMPLITUDE, best=best)


def test_a_best_fit_on_a_search_bound_is_named_with_its_share_and_the_reason(monkeypatch):
    low = cat.get_effect("stretch_reflex")
    delay = next(p for p in low.parameters if p.name == "delay_s").bounds[0]
    text = _text(_fit(delay, 0.041), monkeypatch)
    assert "stretch_reflex (59 % of the held-out gap)" in text, text
    assert "delay_s" in text and "search bound" in text and "not named" in text


def test_a_best_fit_that_closes_too_little_is_named_as_the_best(monkeypatch):
    text = _text(_fit(0.045, 0.08), monkeypatch)
    assert "no catalogue effect closes half" in text and "the best: stretch_reflex (20 %" in text
