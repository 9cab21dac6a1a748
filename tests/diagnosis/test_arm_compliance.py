"""Removing a candidate compliance from the impedance estimate (known-answer, analytic)."""

import numpy as np
import pytest

from diagnosis.arm import ArmModel, arm_behind_cuff, arm_behind_transmission, link_inertia

M = np.array([[0.187, 0.084], [0.079, 0.06]])
B = np.array([[0.651, 0.239], [0.236, 0.407]])
K = np.array([[7.967, 3.187], [1.663, 6.901]])
F = np.linspace(0.5, 40.0, 200)
W = 2 * np.pi * F


def _arm_z():
    """The arm as the estimator sees it: inertia term with the left-limit sampling delay
    that fit_second_order compensates."""
    from estimation.accuracy import left_limit_delay
    lag = np.exp(-1j * W * left_limit_delay(1000.0))[:, None, None]
    return K[None] + 1j * W[:, None, None] * B[None] - (W ** 2)[:, None, None] * lag * M[None]


def _measured(z):
    return ArmModel(M=np.zeros((2, 2)), B=np.zeros((2, 2)), K=np.zeros((2, 2)),
                    r2=np.zeros((2, 2)), method="full", f=F, Z=z, fs=1000.0)


def _diag(k, c):
    return (k + 1j * W * c)[:, None, None] * np.eye(2)[None]


def test_cuff_is_removed_exactly():
    k, c = 220.0, 1.1
    z_meas = np.linalg.inv(np.linalg.inv(_arm_z()) + np.linalg.inv(_diag(k, c)))
    out = arm_behind_cuff(_measured(z_meas), [k, k], [c, c])
    np.testing.assert_allclose(out.M, M, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(out.K, K, rtol=1e-6, atol=1e-9)
    # the wrong cuff does not give the arm back
    wrong = arm_behind_cuff(_measured(z_meas), [2 * k, 2 * k], [2 * c, 2 * c])
    assert not np.allclose(wrong.M, M, rtol=0.05)


def test_transmission_is_removed_exactly():
    meta = {"robot": {"m1": 1.5, "L1": 0.3, "lc1": 0.15, "I1": 0.0113, "m2": 1.0,
                      "L2": 0.35, "lc2": 0.175, "I2": 0.0102}, "posture_deg": [62.7, 77.3]}
    m_link = link_inertia(meta)
    assert m_link[0, 1] == pytest.approx(m_link[1, 0])
    k, c = 465.0, 0.465
    kc, zl = _diag(k, c), (-W ** 2)[:, None, None] * m_link[None]
    # theta_mot = [(I + Kc^-1 Z_link) Z_arm^-1 + Kc^-1] tau_h, built forward
    kci = np.linalg.inv(kc)
    z_meas = np.linalg.inv((np.eye(2) + kci @ zl) @ np.linalg.inv(_arm_z()) + kci)
    out = arm_behind_transmission(_measured(z_meas), [k, k], [c, c], m_link)
    np.testing.assert_allclose(out.M, M, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(out.B, B, rtol=1e-6, atol=1e-9)


def test_no_stored_estimate_gives_none():
    arm = ArmModel(M=M, B=B, K=K, r2=np.ones((2, 2)), method="full")
    assert arm_behind_cuff(arm, [200, 200], [1, 1]) is None
