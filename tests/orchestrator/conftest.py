"""Fixtures of the orchestrator tests: the reference C plant and the pythonfmu linear plant,
each built once per session into a temporary folder, and a loaded Plant of each."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import csd, welch

from orchestrator import Plant


@pytest.fixture(scope="session")
def reference_fmu(tmp_path_factory):
    """The ArmExoPlant C FMU built from source (package fmus)."""
    fmus = pytest.importorskip("fmus")
    return fmus.build_fmu(tmp_path_factory.mktemp("reference_fmu"))


@pytest.fixture(scope="session")
def reference_plant(reference_fmu):
    with Plant(reference_fmu) as plant:
        yield plant


@pytest.fixture(scope="session")
def linear_fmu(tmp_path_factory):
    """The linear arm plant exported by pythonfmu (another exporter)."""
    pytest.importorskip("pythonfmu")
    from orchestrator.plants import build_linear_arm_fmu
    return build_linear_arm_fmu(tmp_path_factory.mktemp("linear_fmu"))


@pytest.fixture(scope="session")
def linear_plant(linear_fmu):
    with pytest.warns(Warning):  # pythonfmu omits ModelStructure/InitialUnknowns
        plant = Plant(linear_fmu)
    with plant:
        yield plant


def frf(x, y, nperseg=4096, fs=1000.0):
    """H1 estimate G_xy / G_xx (Welch, Hann, 75 % overlap) and its frequencies [Hz]."""
    f, gxy = csd(x, y, fs=fs, nperseg=nperseg, noverlap=3 * nperseg // 4)
    _, gxx = welch(x, fs=fs, nperseg=nperseg, noverlap=3 * nperseg // 4)
    return f, gxy / gxx


def band(f, hi=15.0):
    return (f > 0) & (f <= hi)


def rel_error(est, true):
    return np.abs(est - true) / np.abs(true)
