"""K(rho)'s band in the diagnosis takes the widening K0's interval has (issue 20/21)."""

import numpy as np

from diagnosis.limbfit import jackknife_se
from diagnosis.pipeline.state_profile import _form_widening, _interval, _named_k


def _replicates(k0s, slope=0.5):
    p = {"rho_mid": 0.0, "slope_rel": slope, "curvature_rel": 0.0}
    return [{"K": k, "stiffness_angle": p} for k in k0s]


def test_without_a_form_widening_the_band_is_the_jackknife():
    reps = _replicates([10.0, 10.2, 9.8, 10.1])
    own = 1.96 * float(jackknife_se([r["K"] for r in reps]))
    # K0's interval is exactly its jackknife: nothing to add
    assert _form_widening(reps, [10.0, 10.0 - own, 10.0 + own]) == (0.0, 0.0)
    assert _interval(12.0, 0.5, (0.0, 0.0)) == [12.0, 12.0 - 0.98, 12.0 + 0.98]


def test_the_form_widening_is_the_part_of_k0s_interval_the_jackknife_lacks():
    reps = _replicates([10.0, 10.2, 9.8, 10.1])
    own = 1.96 * float(jackknife_se([r["K"] for r in reps]))
    lo_w, hi_w = 3.0, 5.0  # the form envelope made K0's interval wider and skewed
    below, above = _form_widening(reps, [10.0, 10.0 - lo_w, 10.0 + hi_w])
    assert np.isclose(below, np.sqrt(lo_w ** 2 - own ** 2) / 10.0)
    assert np.isclose(above, np.sqrt(hi_w ** 2 - own ** 2) / 10.0)
    # at rho_mid the band is K0's own interval again (same value, same replicates)
    p = reps[0]["stiffness_angle"]
    k = float(_named_k(10.0, p, 0.0))
    se = float(jackknife_se([_named_k(r["K"], p, 0.0) for r in reps]))
    v, lo, hi = _interval(k, se, (below, above))
    assert np.isclose(lo, 10.0 - lo_w) and np.isclose(hi, 10.0 + hi_w)
    # elsewhere it scales with K: twice the stiffness, about twice the form's share
    v2, lo2, hi2 = _interval(2 * k, se, (below, above))
    assert hi2 - v2 > 1.8 * (hi - v)


def test_no_replicates_or_no_interval_gives_no_widening():
    assert _form_widening(None, [10.0, 8.0, 12.0]) == (0.0, 0.0)
    assert _form_widening(_replicates([1.0, 1.1]), None) == (0.0, 0.0)
    assert _form_widening(_replicates([1.0, 1.1]), [10.0, None, None]) == (0.0, 0.0)
    assert _interval(3.0, None, (0.1, 0.1)) == [3.0, None, None]
