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
