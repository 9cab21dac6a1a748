"""Accuracy measures on analytic answers."""

import numpy as np
import pytest

from estimation import EstimationError, fit_second_order, true_impedance, vaf

F = np.arange(1, 124) * 1000.0 / 8192  # the bins of the 0-15 Hz band


def test_true_impedance_elements(arm):
    Z = true_impedance(F, *arm)
    w = 2 * np.pi * F[5]
    assert Z.shape == (F.size, 2, 2)
    assert Z[5, 0, 1] == pytest.approx(arm[2][0, 1] - arm[0][0, 1] * w ** 2
                                       + 1j * arm[1][0, 1] * w)


def test_vaf_known_answer(arm):
    Z = true_impedance(F, *arm)
    assert np.all(vaf(Z, Z) == 100.0)
    # A uniform 3 % relative error leaves 100 (1 - 0.03^2) %.
    np.testing.assert_allclose(vaf(Z * (1 + 0.03j), Z), 100 * (1 - 0.03 ** 2))
    with pytest.raises(EstimationError, match="shape"):
        vaf(Z[:10], Z)


@pytest.mark.parametrize("delay", [0.0, 5e-4])
def test_fit_is_exact_on_the_model(arm, delay):
    w = 2 * np.pi * F[:, None, None]
    Z = arm[2] + 1j * arm[1] * w - arm[0] * w ** 2 * np.exp(-1j * w * delay)
    fit = fit_second_order(F, Z, inertia_delay_s=delay)
    for got, true in zip((fit.M, fit.B, fit.K), arm):
        np.testing.assert_allclose(got, true, rtol=1e-9)
    np.testing.assert_allclose(fit.r2, 1.0, atol=1e-12)
    np.testing.assert_allclose(fit.model(F), Z, rtol=1e-9)


def test_fit_band_excludes_outside_bins(arm):
    f = np.linspace(0, 40, 400)
    Z = true_impedance(f, *arm)
    Z[f > 15] = 0.0  # garbage outside the band must not matter
    Z[f == 0] = 1e9
    fit = fit_second_order(f, Z)
    np.testing.assert_allclose(fit.K, arm[2], rtol=1e-9)


def test_confidence_intervals_cover_under_their_assumption(arm):
    """Relative iid noise (the stated assumption): 95 % intervals cover about 95 %."""
    rng = np.random.default_rng(0)
    Zt = true_impedance(F, arm[0][0, 0], arm[1][0, 0], arm[2][0, 0])
    hits = []
    for _ in range(600):  # coverage 0.96/0.93/0.94 over 2000 draws; MC s.e. 0.9 % here
        noise = 0.02 * (rng.standard_normal(F.size) + 1j * rng.standard_normal(F.size))
        fit = fit_second_order(F, Zt * (1 + noise), hac_bins=0)  # iid: no bin correlation
        hits.append([abs(p - t) <= ci for p, t, ci in
                     ((fit.M, arm[0][0, 0], fit.M_ci), (fit.B, arm[1][0, 0], fit.B_ci),
                      (fit.K, arm[2][0, 0], fit.K_ci))])
    coverage = np.mean(hits, axis=0)
    assert np.all((coverage > 0.90) & (coverage < 0.99)), coverage


def test_fit_refuses_bad_input(arm):
    Z = true_impedance(F, *arm)
    with pytest.raises(EstimationError, match="frequencies"):
        fit_second_order(F[:-1], Z)
    with pytest.raises(EstimationError, match="fewer than 3"):
        fit_second_order(F, Z, band_hz=(0.0, 0.2))
    with pytest.raises(EstimationError, match="weighting"):
        fit_second_order(F, Z, weighting="absolute")
