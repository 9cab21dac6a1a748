"""The Welch helpers against scipy.signal and against known FIR systems."""

import numpy as np
import pytest
from scipy import signal

from estimation import EstimationError
from estimation import spectral as sp

FS = 1000.0


@pytest.fixture(scope="module")
def noise():
    rng = np.random.default_rng(1)
    return rng.standard_normal((30000, 2))


def test_cross_spectrum_matches_scipy_csd(noise):
    x, y = noise[:, 0], noise[:, 1] + 0.5 * noise[:, 0]
    f, g = sp.cross_spectrum(x, y, fs=FS)
    f_ref, g_ref = signal.csd(x, y, fs=FS, window="hann", nperseg=8192, noverlap=6144,
                              nfft=8192, detrend="constant")
    np.testing.assert_array_equal(f, f_ref)
    np.testing.assert_allclose(g, g_ref, rtol=1e-12, atol=0)
    f, G = sp.cross_spectrum(noise[:, :1], np.column_stack([x, y]), fs=FS)
    assert G.shape == (f.size, 1, 2)
    np.testing.assert_allclose(G[:, 0, 1], g_ref, rtol=1e-12)


def test_coherence_matches_scipy(noise):
    x, y = noise[:, 0], noise[:, 1] + noise[:, 0]
    _, c = sp.coherence(x, y, fs=FS)
    _, c_ref = signal.coherence(x, y, fs=FS, nperseg=8192, noverlap=6144, nfft=8192)
    np.testing.assert_allclose(c, c_ref, rtol=1e-10, atol=1e-14)


def test_siso_response_of_known_fir(noise):
    b = [0.5, -0.3, 0.1]
    x = noise[:, 0]
    y = signal.lfilter(b, 1.0, x)
    f, H = sp.frequency_response(x, y, fs=FS)
    _, H_true = signal.freqz(b, 1.0, worN=f, fs=FS)
    # A 3-tap FIR leaks only its 2-sample edge per 8192-sample segment.
    np.testing.assert_allclose(H, H_true, rtol=0, atol=2e-3)


def test_mimo_response_of_two_known_firs(noise):
    b1, b2 = [1.0, 0.5], [0.2, -0.7, 0.1]
    y = signal.lfilter(b1, 1, noise[:, 0]) + signal.lfilter(b2, 1, noise[:, 1])
    f, H = sp.frequency_response(noise, y[:, None], fs=FS)
    assert H.shape == (f.size, 1, 2)
    for j, b in enumerate((b1, b2)):
        _, h = signal.freqz(b, 1, worN=f, fs=FS)
        # DC is removed by the per-segment detrend: compare from the first bin on.
        np.testing.assert_allclose(H[1:, 0, j], h[1:], atol=5e-3)


def test_window_derivative_spectra_plain_part_is_csd(noise):
    f, g0, g1, g2 = sp.window_derivative_spectra(noise[:, :1], noise, fs=FS)
    _, g = sp.cross_spectrum(noise[:, :1], noise, fs=FS)
    np.testing.assert_allclose(g0, g, rtol=1e-10, atol=1e-16)
    assert g1.shape == g2.shape == g.shape


def test_window_derivative_identity_on_a_sinusoid():
    """FFT(w y') = jw FFT(w y) - FFT(w' y), exactly, for y = sin(2 pi f0 t)."""
    t = np.arange(8192) / FS
    f0 = 5.3
    y = np.sin(2 * np.pi * f0 * t)
    dy = 2 * np.pi * f0 * np.cos(2 * np.pi * f0 * t)
    w = signal.get_window("hann", 8192)
    L = 8192 / FS
    w1 = (np.pi / L) * np.sin(2 * np.pi * np.arange(8192) / 8192)
    f = np.fft.rfftfreq(8192, 1 / FS)
    lhs = np.fft.rfft(w * (dy - dy.mean()))
    rhs = 1j * 2 * np.pi * f * np.fft.rfft(w * (y - y.mean())) - np.fft.rfft(w1 * (y - y.mean()))
    band = (f > 0) & (f < 20)
    # The per-segment mean of dy is not the derivative of the mean of y: one bin at f = 0.
    np.testing.assert_allclose(lhs[band][2:], rhs[band][2:], atol=1e-6 * np.abs(lhs).max())


@pytest.mark.parametrize("n_x, n_y", [(9000, 8000), (5000, 5000)])
def test_refuses_bad_lengths(n_x, n_y):
    with pytest.raises(EstimationError, match="samples"):
        sp.cross_spectrum(np.zeros(n_x), np.zeros(n_y), fs=FS)


def test_spectral_matrix_equals_scipy_csd(noise):
    from scipy import signal
    from estimation.spectral import spectral_matrix
    z = np.column_stack([noise[:, 0], noise[:, 1], noise[:, 0] + 0.5 * noise[:, 1]])
    for kw in ({}, {"window": "hamming", "nperseg": 4096, "noverlap": 1024, "nfft": 8192},
               {"detrend": False}):
        f, G = spectral_matrix(z, fs=1000.0, **kw)
        opts = {"nperseg": 8192, "noverlap": 6144, "nfft": 8192, "window": "hann",
                "detrend": "constant", **kw}
        for a in range(3):
            for b in range(3):
                f2, g = signal.csd(z[:, a], z[:, b], fs=1000.0, **opts)
                np.testing.assert_allclose(G[:, a, b], g, rtol=1e-9, atol=1e-12 * abs(g).max())
        np.testing.assert_array_equal(f, f2)
