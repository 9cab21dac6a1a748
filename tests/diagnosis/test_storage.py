"""Storage of the measured numbers (issue 8, item 1): representation, rounding, grid.

Known answers: numbers written by Python's own formatting (the writers a lab uses print
the same decimals), float32 casts by numpy, and quantised samples r * round(x / r).
"""

import numpy as np
import pytest
from scipy import signal as sps

from diagnosis.features import FeatureConfig, _Spectra
from diagnosis.storage import Storage, detect_storage, find_grid

RNG = np.random.default_rng(7)
WALK = np.cumsum(RNG.standard_normal(20000)) * 1e-4          # a slowly moving angle [rad]
STEP = np.radians(0.001758)                                  # encoder resolution level 3


def written(fmt, x):
    return np.array([float(fmt % v) for v in x])


WRITERS = {"sig6": ("%.5e", Storage("significant", 6)),
           "sig7": ("%.6e", Storage("significant", 7)),
           "sig8": ("%.7e", Storage("significant", 8)),
           "sig10": ("%.9e", Storage("significant", 10)),
           "dec6": ("%.6f", Storage("decimals", 6)),
           "dec5": ("%.5f", Storage("decimals", 5))}


@pytest.mark.parametrize("name", sorted(WRITERS))
def test_the_writer_is_read_from_the_numbers(name):
    fmt, expected = WRITERS[name]
    assert detect_storage(written(fmt, WALK)) == expected


def test_float32_and_float64_are_read_from_the_numbers():
    assert detect_storage(WALK.astype(np.float32).astype(float)).kind == "float32"
    assert detect_storage(written("%.9g", WALK.astype(np.float32))).kind == "float32"
    assert detect_storage(WALK).kind == "float64"


@pytest.mark.parametrize("name", sorted(WRITERS))
def test_apply_reproduces_the_writer(name):
    fmt, storage = WRITERS[name]
    np.testing.assert_allclose(storage.apply(WALK), written(fmt, WALK), rtol=0, atol=1e-15)


def test_rounding_variance_is_what_the_rounding_does():
    storage = Storage("significant", 4)
    err = storage.apply(WALK) - WALK
    assert storage.rounding_variance(WALK) == pytest.approx(np.var(err), rel=0.1)


@pytest.mark.parametrize("name", sorted(set(WRITERS) - {"dec5"}) + ["float32", "float64"])
def test_grid_is_found_through_storage_rounding_within_its_uncertainty(name):
    q = STEP * np.round(WALK / STEP)
    if name == "float32":
        x = q.astype(np.float32).astype(float)
    elif name == "float64":
        x = q
    else:
        x = written(WRITERS[name][0], q)
    grid = find_grid(x)
    assert grid.step == pytest.approx(STEP, abs=5 * grid.sigma + 1e-15), name
    assert grid.sigma < 1e-3 * STEP


@pytest.mark.parametrize("name", sorted(WRITERS))
def test_no_grid_is_made_up_by_the_storage(name):
    assert find_grid(written(WRITERS[name][0], WALK)).step == 0.0


def test_a_grid_coarser_than_the_storage_cannot_be_hidden_but_a_finer_one_is_not_claimed():
    q = STEP * np.round(WALK / STEP)
    # a grid of fewer than 10 storage steps is not claimed (3e-5 rad at 1e-5 or 1e-4)
    assert find_grid(written("%.5f", q)).step == 0.0
    assert find_grid(written("%.4f", q)).step == 0.0
    q = 0.005 * np.round(WALK * 50 / 0.005)
    assert find_grid(written("%.3f", q)).step == pytest.approx(0.005)


def test_welch_features_from_one_fft_per_column_equal_scipy():
    cfg = FeatureConfig()
    data = {"a": RNG.standard_normal((12000, 2)), "b": RNG.standard_normal((12000, 2)) + 3}
    spectra = _Spectra(data, 1000.0, cfg)
    kw = dict(fs=1000.0, window="hann", nperseg=cfg.nperseg, noverlap=cfg.noverlap)
    f, pxy = sps.csd(data["a"][:, 0], data["b"][:, 1], **kw)
    np.testing.assert_allclose(spectra.f, f)
    np.testing.assert_allclose(spectra.cross(("a", 1), ("b", 2)), pxy, rtol=1e-10, atol=1e-14)
    _, pyy = sps.welch(data["b"][:, 1], **kw)
    np.testing.assert_allclose(spectra.auto(("b", 2)), pyy, rtol=1e-10)
