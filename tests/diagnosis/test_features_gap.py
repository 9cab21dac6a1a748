"""Features and the gap measure on known-answer signals (no simulator needed)."""

import numpy as np
import pytest
from scipy import signal as sps

from diagnosis.features import FeatureConfig, grid_step, trial_features
from diagnosis.gap import make_normaliser, set_gap

CFG = FeatureConfig()


def _gap(meas, sim, nominal=None):
    fm, fsim = trial_features(meas, CFG), trial_features(sim, CFG)
    norm = make_normaliser(fm, trial_features(nominal or sim, CFG), CFG)
    return set_gap([(meas.name, 3, fm, fsim, norm)])


def _value(fv, kind, signal, joint, band, part):
    return fv.values[fv.labels.index((kind, signal, joint, band, part))]


def test_gap_of_a_trial_against_itself_is_exactly_zero(make_linear_trial):
    t = make_linear_trial(noise_std=0.01)
    result = _gap(t, t)
    assert result.value == 0.0
    assert np.all(result.z == 0.0)


def test_frf_feature_matches_the_analytic_response(make_linear_trial):
    t = make_linear_trial()
    fv = trial_features(t, CFG)
    sos = sps.butter(2, 30.0, fs=1000.0, output="sos")
    f = np.arange(3, 7, 1000.0 / CFG.nperseg)
    f = f[(f >= 3.0) & (f <= 6.0)]
    _, h = sps.sosfreqz(sos, worN=f, fs=1000.0)
    expected = np.mean(np.log(np.abs(h)))
    got = _value(fv, "frf", "tau_h", 1, "3-6 Hz", "logmag")
    assert got == pytest.approx(expected, abs=0.01)
    phase = _value(fv, "frf", "tau_h", 1, "3-6 Hz", "phase")
    assert phase == pytest.approx(np.angle(np.mean(h / np.abs(h))), abs=0.02)


def test_noise_feature_reads_white_noise_level(make_linear_trial):
    std = 0.05
    fv = trial_features(make_linear_trial(noise_std=std), CFG)
    got = _value(fv, "noise", "tau_m", 1, "200-500 Hz", "lnpsd")
    assert got == pytest.approx(np.log(2 * std ** 2 / 1000.0 + CFG.noise_psd_floor["tau_m"]),
                                abs=0.1)


def test_static_feature_reads_a_torque_offset(make_linear_trial):
    a = trial_features(make_linear_trial(), CFG)
    b = trial_features(make_linear_trial(tau_m_offset=0.05), CFG)
    i = a.labels.index(("static", "tau_m", 2, "0 Hz", "a0"))
    assert b.values[i] - a.values[i] == pytest.approx(0.05, abs=1e-9)


@pytest.mark.parametrize("step", [1.758e-3 * np.pi / 180, 0.005, 0.02])
def test_grid_step_is_exact_on_quantised_samples(step):
    x = np.random.default_rng(0).normal(scale=50 * step, size=5000)
    assert grid_step(step * np.round(x / step)) == pytest.approx(step, rel=1e-9)


def test_grid_step_is_zero_off_grid():
    assert grid_step(np.random.default_rng(0).normal(size=5000)) == 0.0


def test_noise_alone_gives_no_significant_gap(make_linear_trial):
    """Two realisations of the same noisy system: the gap stays near 0, far below
    the gap of a 10 % systematic gain change."""
    meas = make_linear_trial(noise_std=0.02, noise_seed=1)
    same = make_linear_trial(noise_std=0.02, noise_seed=2)
    changed = make_linear_trial(noise_std=0.02, noise_seed=2, gain=1.1)
    g_noise = _gap(meas, same).value
    g_change = _gap(meas, changed, nominal=same).value
    assert g_noise < 1.0
    assert g_change > 10 * max(g_noise, 0.1)


def test_adding_noise_to_the_model_is_not_rewarded(make_linear_trial):
    """A noise-free measurement against a model with extra noise: the gap rises."""
    meas = make_linear_trial()
    clean = _gap(meas, make_linear_trial(), nominal=meas).value
    noisy = _gap(meas, make_linear_trial(noise_std=0.02), nominal=meas).value
    assert noisy > clean


def test_breakdown_locates_a_gain_change_in_theta(make_linear_trial):
    meas = make_linear_trial(gain=1.2)
    nominal = make_linear_trial()
    result = _gap(meas, nominal)
    by_signal = result.breakdown("signal")
    assert max(by_signal, key=by_signal.get) == ("theta",)
    assert result.coherent_share() > 0.9
