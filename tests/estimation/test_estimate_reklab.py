"""The five measured ankle recordings (GPL data, read in place from ../shared/data; skipped
when absent, or set REKLAB_MAT to the file): one answer, found conventions, and agreement
with an independent scipy/numpy estimate (bench/bench_reklab.py, which also prints the
table of docs/results.md)."""

import importlib.util
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from estimation.lab import AnalysisOptions, Unit, analyse

ROOT = Path(__file__).resolve().parents[2]
MAT = Path(os.environ.get("REKLAB_MAT", ROOT.parent / "shared" / "data" / "reklab-ankle"
                          / "experimental_data.mat"))
pytestmark = pytest.mark.skipif(not MAT.is_file(), reason=f"{MAT.name} not at ../shared/data/"
                                "reklab-ankle (GPL data, not in the repository)")


@pytest.fixture(scope="module")
def bench():
    # as when run as a script: its own folder (bench/benchio.py) on the import path
    if str(ROOT / "bench") not in sys.path:
        sys.path.insert(0, str(ROOT / "bench"))
    spec = importlib.util.spec_from_file_location("bench_reklab",
                                                  ROOT / "bench" / "bench_reklab.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def recordings(bench):
    pytest.importorskip("matio")
    return bench.recordings(MAT)


@pytest.mark.parametrize("name", ["z_df", "z_df2", "z_df3", "z_pf", "z_pf2"])
def test_one_answer_next_to_an_independent_estimate(bench, recordings, name):
    angle, torque, dt = recordings[name]
    trial = bench.trial(name, angle, torque, dt)
    r1, r2 = (analyse(Unit(name, [trial], ""), AnalysisOptions()) for _ in range(2))
    for p in ("M", "B", "K", "M_ci", "B_ci", "K_ci"):
        assert np.array_equal(getattr(r1.fit, p), getattr(r2.fit, p))
    assert r1.band_source.startswith("from the data") and r1.band_hz[1] > 25.0
    ind = bench.independent(angle, -torque, 1 / dt, r1.band_hz, r1.welch)
    got = {"K": r1.fit.K[0, 0], "B": r1.fit.B[0, 0], "I": r1.fit.M[0, 0]}
    assert [ind["same"][q] for q in "KBI"] == pytest.approx([got[q] for q in "KBI"],
                                                            rel=1e-6)
    # the textbook 1/|H| fit lies within the tool's sensitivity range (plus its interval)
    for q, p in (("K", "K"), ("B", "B"), ("I", "M")):
        lo, hi = (v[0][0] for v in r1.sensitivity["range"][p])
        ci = getattr(r1.fit, f"{p}_ci")[0, 0]
        assert lo - ci <= ind["textbook"][q] <= hi + ci, (name, q)


def test_undeclared_sign_is_found(bench, recordings):
    angle, torque, dt = recordings["z_df2"]
    r = analyse(Unit("raw", [bench.trial("raw", angle, torque, dt, declare_sign=False)], ""),
                AnalysisOptions(sensitivity=False, segments=0))
    assert any(w.startswith("torque sign reversed?") and "torque_sign" in w
               for w in r.warnings), r.warnings


def test_the_clean_recording_fits_and_the_reflex_ones_are_flagged(bench, recordings):
    angle, torque, dt = recordings["z_df2"]
    clean = analyse(Unit("z_df2", [bench.trial("z_df2", angle, torque, dt)], ""))
    assert clean.fit.r2[0, 0] > 0.95 and "poor fit" not in clean.flags
    angle, torque, dt = recordings["z_pf"]
    reflex = analyse(Unit("z_pf", [bench.trial("z_pf", angle, torque, dt)], ""))
    assert "poor fit" in reflex.flags or "band-sensitive" in reflex.flags
