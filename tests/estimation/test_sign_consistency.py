"""Every K one ``estimate`` prints uses one torque sign (the declared one, or the
default +1): the time-variation blocks ("time-varying: K a -> b") and the time-segment
track ("K per segment") follow the main estimate's sign (``Z: K=...``), with and without
``--torque-sign``. Before, both picked the sign that made their own K positive, so a
recording stored with the opposite sign printed ``Z: K=-79.98`` beside ``K per segment
79.99``."""

import re
from pathlib import Path

import numpy as np
import pytest

import trialformat as tf
from labsim_switching import switching_trial
from estimation.cli import main
from estimation.segmentfit import segment_track
from estimation.timevarying import time_variation

PILOT = next((p for p in (Path(__file__).resolve().parents[k] / "shared" / "data" /
                          "reklab-pilot" / "IEEETBME2022_PilotData_AV_PT1_UT2.mat"
                          for k in (2, 3)) if p.exists()), None)
NUM = r"(-?\d+(?:\.\d+)?(?:e[-+]?\d+)?)"


def _ks(text):
    """The signs of every K printed: the estimate's, the blocks', the segments'."""
    main_k = [float(x) for x in re.findall(r"Z: K=" + NUM, text)]
    blocks = [float(x) for line in re.findall(r"time-varying: K [^\n]*", text)
              for x in re.findall(r"s: " + NUM + r"\+-", line)]
    segs = [float(x) for line in re.findall(r"K per segment ([^\n]*) N m/rad", text)
            for x in re.findall(NUM + "±", line)]
    return main_k, blocks, segs


def _one_sign(text):
    main_k, blocks, segs = _ks(text)
    assert main_k and segs, text
    sign = np.sign(main_k[0])
    assert all(np.sign(v) == sign for v in blocks + segs), (main_k, blocks, segs)
    return sign, blocks, segs


@pytest.fixture(scope="module")
def reversed_trial(tmp_path_factory):
    """14 s labsim recording, K 40 <-> 160 N m/rad switching every 2 s, its torque
    stored with the opposite sign and the metadata not saying so (sign lost)."""
    trial = switching_trial()
    trial.tau_h = -trial.tau_h
    out = tmp_path_factory.mktemp("reversed")
    tf.write_trial(out / "rec", trial)
    return out


def test_the_library_defaults_keep_the_torque_as_given():
    """time_variation and segment_track no longer flip a negative-K record's torque."""
    rng = np.random.default_rng(3)
    fs, n = 1000.0, 20000
    x = np.convolve(rng.standard_normal(n), np.ones(20) / 20, "same")
    t = np.arange(n) / fs
    K = np.where(t < 10.0, 80.0, 160.0)
    tau = -(K * x) + 0.01 * rng.standard_normal(n)
    tv = time_variation(x, tau, fs)
    assert all(b.values["K"] < 0 for b in tv.blocks), [b.values["K"] for b in tv.blocks]
    s = segment_track(x, tau, fs)
    assert s.sign == 1.0 and np.all(s.values["K"] < 0), s.values["K"]
    assert np.all(segment_track(x, tau, fs, sign=-1).values["K"] > 0)


@pytest.mark.parametrize("given", [None, -1])
def test_a_recording_with_a_lost_sign_prints_one_sign(reversed_trial, capsys, given):
    argv = ["estimate", str(reversed_trial), "--track", "segments", "--nperseg", "4096"]
    if given is not None:
        argv += ["--torque-sign", str(given)]
    assert main(argv) == 0
    sign, _, _ = _one_sign(capsys.readouterr().out)
    assert sign == (-1 if given is None else 1)


@pytest.mark.skipif(PILOT is None, reason="the moving-ankle recording is not at "
                    "../shared/data/reklab-pilot (GPL data, not in the repository)")
def test_the_pilot_recording_prints_one_sign_with_and_without_the_option(capsys):
    found = {}
    for given in (None, -1):
        argv = ["estimate", str(PILOT), "--track", "segments"]
        if given is not None:
            argv += ["--torque-sign", str(given)]
        assert main(argv) == 0
        found[given] = _one_sign(capsys.readouterr().out)
    assert found[None][0] == -1 and found[-1][0] == 1
    # the same magnitudes, opposite signs
    assert found[None][1] and np.allclose(found[None][1], [-v for v in found[-1][1]])
    assert np.allclose(found[None][2], [-v for v in found[-1][2]])
