"""Options and metadata that leave no fit band, and the CLI's plain messages (issue 11
follow-up). Trials from the independent scipy simulation (estimation.synthetic)."""

import json
import re

import pytest

import trialformat as tf
from estimation import EstimationError
from estimation.cli import main
from estimation.lab import AnalysisOptions
from estimation.synthetic import position_trial

ANKLE = {"K": 150.0, "B": 1.5, "I": 0.015}


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("one")
    tf.write_trial(out / "pos", position_trial(**ANKLE, seed=1, duration_s=20.0))
    return out


@pytest.mark.parametrize("argv, match", [
    (["--band", "0", "0.01"], r"--band 0 0.01 holds 0 frequencies .*--nperseg 8192 .*"
                              r"at least 3: widen the band to --band 0 0.3\d* or more"),
    (["--nperseg", "16"], r"holds 0 frequencies .*--nperseg 16 at fs=1000 Hz: one every "
                          r"62.5 Hz.*--nperseg \(and --nfft\) >= \d+"),
    (["--nperseg", "16", "--nfft", "8"], r"--nfft 8 is shorter than the Welch segment "
                                         r"\(--nperseg 16\)"),
])
def test_options_leaving_no_fit_band_are_refused_by_name(folder, capsys, argv, match):
    assert main(["estimate", str(folder), *argv]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "reshape" not in err
    assert re.search(match, err), err


def test_nfft_below_nperseg_refused_in_the_library():
    with pytest.raises(EstimationError, match="--nfft 1024 is shorter"):
        AnalysisOptions(nperseg=2048, nfft=1024).check()
    AnalysisOptions(nperseg=2048, nfft=4096).check()


def test_the_suggested_segment_works(folder, capsys):
    assert main(["estimate", str(folder), "--nperseg", "16"]) == 1
    need = int(capsys.readouterr().err.split(">= ")[1].split()[0])
    assert main(["estimate", str(folder), "--nperseg", str(need)]) == 0


def test_filled_keys_are_one_plain_line(tmp_path, capsys):
    tf.write_trial(tmp_path / "pos", position_trial(**ANKLE, seed=1, duration_s=20.0))
    meta = json.loads((tmp_path / "pos.json").read_text())
    del meta["fs"]
    (tmp_path / "pos.json").write_text(json.dumps(meta))
    assert main(["estimate", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert err == ("note: pos.csv: metadata keys absent, filled from the documented "
                   "1-joint defaults (log-format.md): fs\n")


def test_missing_folder_says_so(tmp_path, capsys):
    assert main(["estimate", str(tmp_path / "nonexistent")]) == 1
    assert "nonexistent: no such file or folder" in capsys.readouterr().err


def _slowly_moving_trial(folder):
    """60 s at 1 kHz: the joint moves +-0.3 rad at 0.05 Hz, a 3 mrad 1-40 Hz position
    perturbation on top, tau_h = K theta + B theta' + I theta'' (+ a little noise), no
    declared cutoff: the angle's spectrum is the movement's, so no coherent stretch of the
    perturbation is found and the band falls back to the 20 dB top of the movement."""
    import numpy as np
    from scipy import signal as sps
    fs, n = 1000.0, 60_000
    t = np.arange(n) / fs
    rng = np.random.default_rng(0)
    d = sps.sosfilt(sps.butter(4, [1.0, 40.0], btype="bandpass", fs=fs, output="sos"),
                    rng.standard_normal(n))
    th = 0.3 * np.sin(2 * np.pi * 0.05 * t) + 0.003 * d / d.std()
    w = np.gradient(th, 1 / fs)
    tau = 80.0 * th + 1.2 * w + 0.011 * np.gradient(w, 1 / fs) + 0.05 * rng.standard_normal(n)
    meta = tf.default_metadata(1)
    meta["perturbation"] = {"kind": "position", "seed": 0}
    tf.write_trial(folder / "slow", tf.Trial(meta=meta, t=t, theta=th[:, None],
                                             tau_h=tau[:, None], name="slow"))


def test_moving_joint_band_advice_works_when_followed(tmp_path, capsys):
    """The refusal of a slowly moving joint's too-narrow band used to advise
    '--band 0 0.3662', which (rounded down below the third bin, 0.36621 Hz) was refused
    again with the same advice; now it names the perturbation's band above the movement,
    and both that band and the widened one are accepted when given back."""
    _slowly_moving_trial(tmp_path)
    assert main(["estimate", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "holds 2 frequencies" in err and "moves slowly beyond its perturbation" in err
    own = re.search(r"own band above it is --band (\S+) (\S+) ", err)
    widened = re.search(r"widen the band to --band (\S+) (\S+) or more", err)
    assert own and widened, err
    lo, hi = float(own[1]), float(own[2])
    assert 0.4 < lo < 1.0 and 30.0 < hi < 100.0, err
    out = tmp_path / "res.json"
    assert main(["estimate", str(tmp_path), "--band", own[1], own[2],
                 "--json", str(out)]) == 0, capsys.readouterr().err
    p = json.loads(out.read_text())[0]["parameters"]
    assert p["K"]["value"][0][0] == pytest.approx(80.0, rel=0.05)
    assert p["B"]["value"][0][0] == pytest.approx(1.2, rel=0.05)
    assert p["M"]["value"][0][0] == pytest.approx(0.011, rel=0.05)
    capsys.readouterr()
    # the fallback, too, is accepted (not refused with the same advice again)
    assert main(["estimate", str(tmp_path), "--band", widened[1], widened[2]]) == 0, \
        capsys.readouterr().err
