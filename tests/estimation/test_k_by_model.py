"""``estimate`` names every stiffness it prints by the model that gave it, in one line,
when more than one model gave one (issue 21: on the measured moving ankle five K values
from 11 to 41 N m/rad were printed, none said which question it answers)."""

import re
from pathlib import Path

import pytest

from estimation.cli import main
from estimation.synthetic import position_trial
import trialformat as tf

PILOT = next((p for p in (Path(__file__).resolve().parents[k] / "shared" / "data" /
                          "reklab-pilot" / "IEEETBME2022_PilotData_AV_PT1_UT2.mat"
                          for k in (2, 3)) if p.exists()), None)
NUM = r"(-?\d+(?:\.\d+)?)"


@pytest.mark.skipif(PILOT is None, reason="no ../shared/data/reklab-pilot/")
def test_the_moving_ankle_names_each_k_by_its_model(capsys):
    assert main(["estimate", str(PILOT), "--torque-sign", "-1", "--reflex"]) == 0
    out = capsys.readouterr().out
    (line,) = [x for x in out.splitlines() if x.strip().startswith("K by model")]
    z = float(re.search(r"Z: K=" + NUM, out).group(1))
    intrinsic = float(re.search(r"intrinsic: K=" + NUM, out).group(1))
    inv = float(re.search(r"time-invariant: K=" + NUM, out).group(1))
    # the values printed elsewhere, each beside the name of its model
    assert f"FRF fit 13.5-46.9 Hz {z:.4g}" in line
    assert f"parallel cascade's intrinsic pathway {intrinsic:.4g}" in line
    assert f"time-invariant order 0 {inv:.4g}" in line
    assert "over sv" in line and "time segments" in line and "time-domain K-B-I" in line


def test_one_model_one_k_no_line(tmp_path, capsys):
    trial = position_trial(K=50.0, B=1.0, I=0.01, duration_s=20.0, name="rec")
    tf.write_trial(tmp_path / "rec", trial)
    assert main(["estimate", str(tmp_path)]) == 0
    assert "K by model" not in capsys.readouterr().out
