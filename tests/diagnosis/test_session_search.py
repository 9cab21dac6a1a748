"""Many records (issue 22 item 3): a candidate's search on a subset of the records,
finished by Newton steps on all, and the one-step jackknife, against the search and the
jackknife on all records (FitConfig.search_trials = 0) on the same data, and Newton's
step against a known quadratic."""

import dataclasses

import numpy as np
import pytest

from diagnosis import limb as lm
from diagnosis import limbfit as lf
from diagnosis import position_validation as pv

FS = 1000.0
TRUTH = {"gain": 2.0, "delay_s": 0.045, "frequency_hz": 4.0, "rectified": True}


def test_newton_step_lands_on_a_quadratics_minimum():
    A = np.array([[3.0, 0.8], [0.8, 1.5]])
    x_min = np.array([0.42, 0.57])
    fn = lambda x: float((x - x_min) @ A @ (x - x_min)) + 1.0  # noqa: E731
    got = lf.newton_step(fn, np.array([0.40, 0.60]))
    np.testing.assert_allclose(got, x_min, atol=1e-9)
    assert lf.newton_step(lambda x: -fn(x), np.array([0.40, 0.60])) is None  # a maximum
    assert lf.newton_step(fn, np.array([0.005, 0.5])) is None                 # at a bound
    assert lf.newton_step(fn, np.array([0.2, 0.3])) is None                   # too far


def _records(n, seconds=6.0):
    rng = np.random.default_rng(8)
    limb = pv.draw_limb(rng, 1)
    recs = []
    for i in range(n):
        theta = pv.perturbation(rng, int(seconds * FS), 1)
        tau = lm.limb_torque(theta, FS, limb, {"stretch_reflex": TRUTH})
        tau = tau + 0.02 * rng.standard_normal(tau.shape)
        recs.append(lf.PositionRecord(theta + 5e-6 * rng.standard_normal(theta.shape), tau,
                                      FS, None, f"r{i}"))
    return recs


@pytest.fixture(scope="module")
def fits():
    preps = None
    out = {}
    for k in (0, 4):
        cfg = lf.FitConfig(effects=("stretch_reflex",), n_jackknife=4, search_trials=k,
                           form_profile=False)
        preps = lf.prepare(_records(10), cfg)
        nominal = lf.fit_nominal(preps, cfg)
        fit = lf.fit_effect(preps, "stretch_reflex", nominal, cfg)
        out[k] = (fit, fit._problem[0])
    return out


def test_the_subset_search_finds_the_all_records_optimum(fits):
    full, sub = fits[0][0], fits[4][0]
    assert fits[4][1].many and not fits[0][1].many
    for key in ("gain", "delay_s", "frequency_hz"):
        assert sub.params[key] == pytest.approx(full.params[key], rel=2e-3), key
    assert sub.params["delay_s"] == pytest.approx(TRUTH["delay_s"], abs=0.002)
    assert sub.calibration_objective == pytest.approx(full.calibration_objective, rel=1e-5)
    assert sub.held_out_reduction == pytest.approx(full.held_out_reduction, abs=1e-4)
    assert sub.n_evaluations < full.n_evaluations


def test_the_one_step_jackknife_gives_the_refitted_jackknifes_intervals(fits):
    full, sub = fits[0][0], fits[4][0]
    for key, (lo, hi) in full.intervals.items():
        slo, shi = sub.intervals[key]
        w, sw = hi - lo, shi - slo
        assert 0.6 < sw / w < 1.6, (key, full.intervals[key], sub.intervals[key])
        assert slo < sub.params[key] < shi
