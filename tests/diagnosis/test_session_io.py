"""Issue 22 (a lab's whole session): units of theta_ref, one grouping rule, one name per
output, in the diagnosis."""

import dataclasses

import numpy as np

from diagnosis.conventions import check_angles
from estimation.synthetic import position_trial


def _ref_trial(**kw):
    return position_trial(K=80.0, B=1.2, I=0.012, duration_s=10, seed=3, **kw)


def test_theta_ref_in_degrees_is_converted_with_theta():
    t = _ref_trial()
    deg = dataclasses.replace(t, theta=np.degrees(t.theta), theta_ref=np.degrees(t.theta_ref))
    out, found = check_angles([deg])
    assert "angles in degrees" in [f.name for f in found]
    np.testing.assert_allclose(out[0].theta_ref, t.theta_ref, atol=1e-12)
    np.testing.assert_allclose(out[0].theta, t.theta, atol=1e-12)


def test_theta_ref_in_degrees_beside_theta_in_radians_is_noticed():
    t = _ref_trial()
    deg = dataclasses.replace(t, theta_ref=np.degrees(t.theta_ref))
    out, found = check_angles([deg])
    names = [f.name for f in found]
    assert "theta_ref in degrees" in names, names
    np.testing.assert_allclose(out[0].theta_ref, t.theta_ref, atol=1e-12)
    np.testing.assert_allclose(out[0].theta, t.theta, atol=1e-12)
