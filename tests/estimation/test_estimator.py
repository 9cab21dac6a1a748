"""Known answers: the estimators on trials of the independent scipy simulation."""

import copy

import numpy as np
import pytest

from estimation import (EstimationError, coherence, estimate_impedance, fit_impedance,
                        fit_second_order, left_limit_delay, true_impedance, vaf)


def _band_truth(est, arm):
    return est.Z[est.band], true_impedance(est.f[est.band], *arm)


def _max_rel_err(fit, arm, name):
    return np.abs(fit.relative_errors(*arm)[name]).max()


def _with_noise(trials, seed, theta_std=2e-3, tau_std=0.3):
    rng = np.random.default_rng(seed)
    out = []
    for t in trials:
        t2 = copy.copy(t)
        t2.theta = t.theta + theta_std * rng.standard_normal(t.theta.shape)
        t2.tau_h = t.tau_h + tau_std * rng.standard_normal(t.tau_h.shape)
        out.append(t2)
    return out


def test_decomposition_recovers_impedance_on_the_decomposed_loop(perfect_hold_trials, arm):
    est = estimate_impedance(perfect_hold_trials)
    assert est.Z.shape == (4097, 2, 2) and est.R.shape == (4097, 2)
    Z, Zt = _band_truth(est, arm)
    assert vaf(Z, Zt).min() > 99.99
    # Plain per-element fit: M and K within 1 %; B carries Welch's window leakage.
    plain = fit_second_order(est.f, est.Z)
    assert _max_rel_err(plain, arm, "M") < 0.005 and _max_rel_err(plain, arm, "K") < 0.01
    assert 0.01 < _max_rel_err(plain, arm, "B") < 0.05
    # The leakage-aware fit removes it: every parameter within 0.5 %.
    exact = fit_impedance(est)
    for name in "MBK":
        assert _max_rel_err(exact, arm, name) < 0.005, name
    assert exact.r2.min() > 0.9999


def test_leakage_shrinks_with_longer_segments(perfect_hold_trials, arm):
    """The B error of the plain fit is Welch leakage: 16384-sample segments cut it."""
    short = fit_second_order(*_fz(estimate_impedance(perfect_hold_trials)))
    long = fit_second_order(*_fz(estimate_impedance(perfect_hold_trials, nperseg=16384,
                                                    noverlap=12288, nfft=16384)))
    assert _max_rel_err(long, arm, "B") < 0.5 * _max_rel_err(short, arm, "B")


def _fz(est):
    return est.f, est.Z


def test_noise_free_coherence_near_one(perfect_hold_trials):
    est = estimate_impedance(perfect_hold_trials)
    assert est.mean_coherence().min() > 0.99
    assert np.all(est.mean_coherence() <= 1.0)


def test_unbiased_under_uncorrelated_output_noise(perfect_hold_trials):
    """Mean over noise seeds of the noisy T, R and Z equals the noise-free estimate."""
    clean = estimate_impedance(perfect_hold_trials)
    b = clean.band
    diffs = {"T": [], "R": [], "Z": []}
    for seed in range(8):
        noisy = estimate_impedance(_with_noise(perfect_hold_trials, seed))
        for key, a, c in (("T", noisy.T, clean.T), ("R", noisy.R, clean.R),
                          ("Z", noisy.Z, clean.Z)):
            diffs[key].append(((a - c) / c)[b].mean(axis=0))  # band mean of rel. error
    for key, d in diffs.items():
        d = np.array(d)
        for part in (d.real, d.imag):
            se = part.std(axis=0, ddof=1) / np.sqrt(len(part))
            assert np.all(np.abs(part.mean(axis=0)) < 3 * se + 2e-4), key


def test_derived_coherence_falls_with_noise_and_matches_direct(perfect_hold_trials):
    clean = estimate_impedance(perfect_hold_trials)
    trials = _with_noise(perfect_hold_trials, seed=0)
    noisy = estimate_impedance(trials)
    assert np.all(noisy.mean_coherence() < clean.mean_coherence() - 0.01)
    # Derivation: with uncorrelated noise the product equals the coherence of the direct
    # estimate from theta_k to tau_h_i (here theta_1 -> tau_h_2 in the joint-1 trial).
    f, c_direct = coherence(trials[0].theta[:, 0], trials[0].tau_h[:, 1], fs=1000.0)
    assert abs(c_direct[noisy.band].mean() - noisy.coherence_Z[noisy.band, 1, 0].mean()) < 0.01


def test_plain_decomposition_biased_when_held_joints_move_full_is_not(loose_hold_trials, arm):
    plain = estimate_impedance(loose_hold_trials, method="decomposition")
    full = estimate_impedance(loose_hold_trials, method="full")
    assert vaf(*_band_truth(plain, arm)).min() < 95
    assert vaf(*_band_truth(full, arm)).min() > 99.99
    fit = fit_impedance(full)
    for name in "MBK":  # 0.51 % on K with model-based weights (0.45 % with 1/|Zhat|)
        assert _max_rel_err(fit, arm, name) < 0.006, name


def test_closed_loop_mimo_recovers_impedance(all_joints_trial, arm):
    est = estimate_impedance([all_joints_trial], method="closed_loop")
    assert vaf(*_band_truth(est, arm)).min() > 99.99
    fit = fit_impedance(est)
    for name in "MBK":
        assert _max_rel_err(fit, arm, name) < 0.01, name


def test_direct_mimo_biased_by_angle_noise_closed_loop_much_less(all_joints_trial, arm):
    noisy = _with_noise([all_joints_trial], seed=1, theta_std=5e-3, tau_std=0.0)
    direct = fit_impedance(estimate_impedance(noisy, method="direct"), leakage=False)
    closed = fit_impedance(estimate_impedance(noisy, method="closed_loop"), leakage=False)
    assert np.abs(direct.relative_errors(*arm)["K"]).min() > 0.10  # 12-33 %
    assert _max_rel_err(closed, arm, "K") < 0.07


def test_left_limit_sampling_bias_and_its_compensation(left_limit_trials, arm):
    est = estimate_impedance(left_limit_trials)
    raw = fit_impedance(est, leakage=False)
    corrected = fit_impedance(est, inertia_delay_s=left_limit_delay(est.fs))
    assert _max_rel_err(raw, arm, "B") > 0.03
    assert _max_rel_err(corrected, arm, "B") < 0.025
    assert np.all(np.abs(corrected.relative_errors(*arm)["B"]) <
                  np.abs(raw.relative_errors(*arm)["B"]))


def test_several_trials_per_joint_are_pooled(perfect_hold_trials, arm):
    est = estimate_impedance(perfect_hold_trials + perfect_hold_trials)
    one = estimate_impedance(perfect_hold_trials)
    np.testing.assert_allclose(est.Z, one.Z, rtol=1e-10)
    assert est.n_segments == 2 * one.n_segments


@pytest.mark.parametrize("method, needs", [("decomposition", "perturbed_dof=null"),
                                           ("closed_loop", "perturb one joint")])
def test_refuses_wrong_kind_of_trials(perfect_hold_trials, all_joints_trial, method, needs):
    with pytest.raises(EstimationError, match=needs):
        estimate_impedance(perfect_hold_trials + [all_joints_trial], method=method)


def test_refuses_missing_joint_unknown_method_and_mixed_rates(perfect_hold_trials):
    with pytest.raises(EstimationError, match=r"joint\(s\) \[2\]"):
        estimate_impedance(perfect_hold_trials[:1])
    with pytest.raises(EstimationError, match="method must be one of"):
        estimate_impedance(perfect_hold_trials, method="magic")
    other = copy.copy(perfect_hold_trials[1])
    other.meta = dict(other.meta, fs=500.0)
    with pytest.raises(EstimationError, match="fs=500.0"):
        estimate_impedance([perfect_hold_trials[0], other])
