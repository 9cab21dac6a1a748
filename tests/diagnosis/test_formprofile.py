"""Intervals that include the form (diagnosis.formprofile; issue 21, item 2): a truth whose
tied choice differs from the fit's (a wobbling mass of damping 0.15 against the tied 0.3)
is outside the plain jackknife interval and inside the form-profiled one; the point
estimate moves to the best-fitting damping. Seconds (diagnosis.limb simulations)."""

import numpy as np
import pytest

from diagnosis import formprofile as fp
from diagnosis import limb as lm
from diagnosis import limbfit as lf
from diagnosis import position_validation as pv
from diagnosis.pipeline.report import named_model

FS = 1000.0
TRUTH = {"mass": 0.008, "frequency_hz": 7.0, "damping": 0.15}


def _record(seed=4, seconds=15.0):
    rng = np.random.default_rng(seed)
    limb = lm.LimbModel(K=[[80.0]], B=[[1.0]], I=[[0.015]])
    theta = pv.perturbation(rng, int(seconds * FS), 1)
    tau = lm.limb_torque(theta, FS, limb, {"wobbling_mass": TRUTH})
    theta = theta + 5e-6 * rng.standard_normal(theta.shape)
    tau = tau + 0.01 * rng.standard_normal(tau.shape)
    return lf.PositionRecord(theta, tau, FS, None, "wobble")


def _fit(profile):
    cfg = lf.FitConfig(effects=("wobbling_mass",), n_jackknife=4, pairs=False,
                       form_profile=profile)
    return lf.diagnose_position([_record()], cfg)


def test_the_interval_widens_to_cover_a_truth_of_another_damping():
    plain = _fit(False)
    assert plain.named == ["wobbling_mass"]
    lo, hi = plain.intervals["wobbling_mass"]["mass"]
    # the tied damping biases the mass beyond its jackknife interval (the case)
    assert not lo <= TRUTH["mass"] <= hi, (lo, hi)
    d = _fit(True)
    assert d.named == ["wobbling_mass"]
    row = d.ranking[0]
    prof = row["form_profile"]
    assert prof["profiled"]["damping"] == list(fp.FORM_GRID["wobbling_mass"]["damping"])
    for k in ("mass", "frequency_hz"):
        lo, hi = d.intervals["wobbling_mass"][k]
        assert lo <= TRUTH[k] <= hi, (k, lo, hi)
        assert hi - lo < abs(d.fitted["wobbling_mass"][k]) / 3.0
    # the point estimate is the best-fitting damping, which is the truth's here
    assert prof["point_estimate_changed"] and d.fitted["wobbling_mass"]["damping"] == 0.15
    assert d.fitted["wobbling_mass"]["mass"] == pytest.approx(TRUTH["mass"], rel=0.05)
    assert d.gap["named_held_out_reduction"] > plain.gap["named_held_out_reduction"]
    # report.json's named model says which choices were profiled
    nm = named_model({"K_h": [[80.0]], "B_h": [[1.0]], "M_h": [[0.015]]},
                     d.fitted, d.intervals, {"wobbling_mass": prof})
    assert nm["effects"]["wobbling_mass"]["damping"] == 0.15
    assert nm["effects"]["wobbling_mass"]["mass"][1:] == d.intervals["wobbling_mass"]["mass"]
    assert nm["form_profile"]["wobbling_mass"]["profiled"]["damping"] == prof["profiled"]["damping"]


def test_alternatives_cover_the_grid_and_the_rectification():
    alts = dict(fp.alternatives("stretch_reflex", {"rectified": True, "stretch_sign": 1.0}))
    assert {a["damping"] for k, a in alts.items() if "damping" in k} == {0.5, 0.6, 0.85, 1.0, 1.2}
    assert alts["rectified = False"]["rectified"] is False
    assert not fp.profiled("channel_delay")
