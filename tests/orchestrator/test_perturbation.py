"""The perturbation generator (reference.md section 6)."""

import numpy as np
import pytest
from scipy.signal import butter, sosfreqz, welch

from orchestrator import SetupError, make_perturbation


@pytest.mark.parametrize("level,peak", [(1, [3.0, 1.8]), (2, [6.0, 3.6]), (3, [9.0, 5.4])])
def test_peak_per_joint_equals_level(level, peak):
    tau = make_perturbation(level, seed=4, n_samples=5000)
    assert tau.shape == (5000, 2)
    np.testing.assert_allclose(np.max(np.abs(tau), axis=0), peak, rtol=1e-12)


def test_seeded_and_reproducible():
    a = make_perturbation(3, 7, 3000)
    np.testing.assert_array_equal(a, make_perturbation(3, 7, 3000))
    assert not np.allclose(a, make_perturbation(3, 8, 3000))


def test_single_joint_column_matches_all_joint_mode():
    both = make_perturbation(2, 5, 4000, perturbed_dof=None)
    only2 = make_perturbation(2, 5, 4000, perturbed_dof=2)
    assert not np.any(only2[:, 0])
    np.testing.assert_array_equal(only2[:, 1], both[:, 1])
    long = make_perturbation(2, 5, 50000)
    assert abs(np.corrcoef(long.T)[0, 1]) < 0.1  # independent per joint


def test_spectrum_follows_the_butterworth_response():
    """Filtered white noise has PSD proportional to |H|^2 of the 8th-order 15 Hz filter."""
    tau = make_perturbation(3, 1, 200_000)[:, 0]
    f, p = welch(tau, fs=1000.0, nperseg=2048)
    _, h = sosfreqz(butter(8, 15.0, fs=1000.0, output="sos"), worN=f, fs=1000.0)
    passband = (f > 1) & (f < 10)
    scale = np.median(p[passband] / np.abs(h[passband]) ** 2)
    check = (f > 1) & (f < 22)  # above, the PSD falls under Welch leakage
    np.testing.assert_allclose(p[check], scale * np.abs(h[check]) ** 2, rtol=0.35, atol=1e-9)
    assert p[f > 40].max() < 1e-4 * p[passband].mean()


def test_transient_discarded():
    """The first 2 s of the causal filter's output are dropped: the signal starts at full
    amplitude, not from the filter's zero state."""
    tau = make_perturbation(3, 3, 20000)[:, 0]
    assert np.std(tau[:200]) > 0.3 * np.std(tau)


@pytest.mark.parametrize("kwargs,match", [
    ({"level": 4}, "level"), ({"perturbed_dof": 3}, "perturbed_dof"),
    ({"n_dof": 4}, "peak"), ({"n_samples": 0}, "n_samples")])
def test_bad_input(kwargs, match):
    args = {"level": 1, "seed": 0, "n_samples": 100}
    args.update(kwargs)
    with pytest.raises(SetupError, match=match):
        make_perturbation(**args)
