"""A recording shorter than the smallest Welch segment is told to record longer, not sent
round a loop ("use --nperseg 16", then with --nperseg 16 the same again; issue 22)."""

import json

import pandas as pd

from estimation.cli import main


def _three_samples(folder):
    pd.DataFrame({"t": [0.0, 0.001, 0.002], "theta_ref[1]": [0.0, 0.01, 0.0],
                  "theta[1]": [0.0, 0.01, 0.02], "tau_h[1]": [0.0, 1.0, 0.5]}).to_csv(
        folder / "s3.csv", index=False)
    (folder / "s3.json").write_text(json.dumps({
        "format": "armimp-trial/1", "fs": 1000.0, "n_dof": 1, "perturbed_dof": 1,
        "perturbation": {"kind": "position"}, "posture_deg": [0.0]}))
    return folder / "s3.csv"


def test_three_samples_no_nperseg_loop(tmp_path, capsys):
    path = _three_samples(tmp_path)
    for extra in ([], ["--nperseg", "16"]):
        assert main(["estimate", str(path), *extra]) == 1
        err = capsys.readouterr().err
        assert "s3" in err and "3 samples" in err and "record longer" in err, err
        assert "use --nperseg" not in err, err
