"""Fixtures of the diagnosis tests: synthetic trials with known answers (no simulator)."""

import numpy as np
import pytest
from scipy import signal as sps

import trialformat as tf


def linear_trial(*, n_samples=12000, seed=0, gain=1.0, noise_std=0.0, noise_seed=1,
                 tau_m_offset=0.0, perturbed_dof=1, name="t"):
    """A trial whose signals are known linear filters of a band-limited perturbation.

    theta = gain * H1(z) d, tau_h = H2(z) d, tau_m = H3(z) d (+ offset), plus white noise
    of ``noise_std`` on every signal (an independent realisation per ``noise_seed``).
    """
    rng = np.random.default_rng(seed)
    fs = 1000.0
    sos = sps.butter(8, 15.0, fs=fs, output="sos")
    d = sps.sosfilt(sos, rng.uniform(-1, 1, n_samples + 2000))[2000:]
    d = 9.0 * d / np.abs(d).max()
    filters = {"theta": sps.butter(2, 5.0, fs=fs, output="sos"),
               "tau_h": sps.butter(2, 30.0, fs=fs, output="sos"),
               "tau_m": sps.butter(1, 50.0, fs=fs, output="sos")}
    scale = {"theta": 0.05 * gain, "tau_h": 1.0, "tau_m": 2.0}
    noise = np.random.default_rng(noise_seed)
    sig = {}
    for s, f in filters.items():
        y = scale[s] * sps.sosfilt(f, d)
        y = np.column_stack([y, 0.01 * y])
        sig[s] = y + noise_std * noise.standard_normal(y.shape) * (1e-3 if s == "theta" else 1)
    sig["tau_m"] = sig["tau_m"] + tau_m_offset
    tau_delta = np.zeros((n_samples, 2))
    tau_delta[:, perturbed_dof - 1] = d
    meta = tf.default_metadata(2)
    meta["perturbed_dof"] = perturbed_dof
    meta["perturbation"]["seed"] = seed
    return tf.Trial(meta=meta, t=np.arange(n_samples) / fs, tau_delta=tau_delta, name=name,
                    **sig)


@pytest.fixture
def make_linear_trial():
    return linear_trial
