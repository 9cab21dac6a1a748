"""A named pair's intervals include the form (limbpairs.profile_pair; issue 21, item 2):
labsim's reflex of activation damping 1.0 (the fit ties 0.7) under its PD servo with the
reference recorded, named stretch_reflex + servo_bandwidth. At the tied form the reflex's
delay moves ~8 ms short of the truth and the pair's one-step jackknife is ~1 ms wide; the
envelope over the members' form alternatives (the reflex's damping, threshold and
rectification, the servo's damping) the data do not reject covers the truth."""

import numpy as np

import labsim
from diagnosis import limbfit as lf


def test_the_named_pairs_intervals_cover_a_reflex_of_another_damping():
    spec = labsim.draw("nominal+reflex", np.random.default_rng(3), duration_s=20.0)
    spec.reflex.form = "second_order"
    spec.reflex.damping = 1.0
    rec = labsim.simulate(spec)
    d = lf.diagnose_position([rec.trial], lf.FitConfig(
        effects=("stretch_reflex", "servo_bandwidth")))
    assert d.named == ["stretch_reflex", "servo_bandwidth"], d.pairs[:1]
    pair = d.pairs[0]
    fp = pair["form_profile"]
    assert set(fp) == {"stretch_reflex", "servo_bandwidth"}
    rows = fp["stretch_reflex"]["alternatives"]
    assert any(r["choice"].startswith("servo_bandwidth: damping") for r in rows)
    assert any(r["kept"] and r["choice"] != "the fit's" for r in rows)
    truth = spec.reflex.delay_s
    before = fp["stretch_reflex"]["jackknife_intervals"]["delay_s"]
    after = pair["intervals"]["stretch_reflex"]["delay_s"]
    assert not before[0] <= truth <= before[1]  # the tied form's jackknife misses it
    assert after[0] <= truth <= after[1], (truth, after)
    assert after[0] <= before[0] and before[1] <= after[1]  # an envelope of the fit's own
    assert (after[1] - after[0]) / pair["params"]["stretch_reflex"]["delay_s"] < 1 / 3
    # the limb's intervals are widened the same way (the viscosity's covers the truth)
    b, hb = np.atleast_2d(pair["B"])[0, 0], np.atleast_2d(pair["limb_ci"]["B_h"])[0, 0]
    hb0 = np.atleast_2d(fp["stretch_reflex"]["jackknife_limb_ci"]["B_h"])[0, 0]
    assert hb >= hb0
    # plus what the pipeline's central differences move the limb by (the inertia's most)
    allow = fp["stretch_reflex"]["derivative_allowance"]
    assert np.atleast_2d(allow["M_h"])[0, 0] > 0
    i, hi = np.atleast_2d(pair["I"])[0, 0], np.atleast_2d(pair["limb_ci"]["M_h"])[0, 0]
    assert abs(i - spec.limb.I) <= hi
    assert abs(b - spec.limb.B) <= hb
