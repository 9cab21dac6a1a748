"""FRF helpers of the orchestrator tests (a module name no other test folder uses)."""

import numpy as np
from scipy.signal import csd, welch


def frf(x, y, nperseg=4096, fs=1000.0):
    """H1 estimate G_xy / G_xx (Welch, Hann, 75 % overlap) and its frequencies [Hz]."""
    f, gxy = csd(x, y, fs=fs, nperseg=nperseg, noverlap=3 * nperseg // 4)
    _, gxx = welch(x, fs=fs, nperseg=nperseg, noverlap=3 * nperseg // 4)
    return f, gxy / gxx


def band(f, hi=15.0):
    return (f > 0) & (f <= hi)


def rel_error(est, true):
    return np.abs(est - true) / np.abs(true)
