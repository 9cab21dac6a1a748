"""The CLI loads heavy modules only where used (issue 17; timings: bench/bench_startup.py).

Each case runs in a fresh interpreter and lists the heavy top-level modules it loaded.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import trialformat as tf

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("numpy", "scipy", "matplotlib", "fmpy", "pandas")
SNIPPET = """
import json, sys
from orchestrator.cli import main
try:
    code = main(json.loads(sys.argv[1]))
except SystemExit as exc:
    code = exc.code
print(json.dumps({"code": code, "heavy": sorted({m.split('.')[0] for m in sys.modules
                  if m.split('.')[0] in %r})}))
""" % (HEAVY,)


def _loaded(args):
    out = subprocess.run([sys.executable, "-c", SNIPPET, json.dumps(args)], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    return json.loads(out.stdout.strip().splitlines()[-1]), out.stderr


@pytest.mark.parametrize("args", [["--help"], ["--bogus"], ["estimate", "--help"],
                                  ["figures", "--help"], ["diagnose", "--help"],
                                  ["estimate", "x", "--nperseg", "many"]])
def test_help_and_bad_options_load_no_heavy_module(args):
    got, err = _loaded(args)
    assert got["code"] in (0, 2)
    assert got["heavy"] == [], (args, got, err)


def test_estimate_loads_numpy_and_scipy_but_not_matplotlib(tmp_path):
    n = 20_000
    rng = np.random.default_rng(0)
    theta = np.convolve(rng.standard_normal(n), np.ones(20) / 20, mode="same") * 0.01
    meta = tf.default_metadata(1)
    meta.update(fs=1000.0, n_dof=1, perturbed_dof=1, posture_deg=[0.0])
    meta["perturbation"] = {"kind": "position"}
    tau = 100 * theta + 0.001 * rng.standard_normal(n)
    tf.write_trial(tmp_path / "a", tf.Trial(meta=meta, t=np.arange(n) / 1000.0,
                                           theta=theta[:, None], tau_h=tau[:, None],
                                           name="a"))
    got, err = _loaded(["estimate", str(tmp_path), "--nperseg", "2048"])
    assert got["code"] == 0, err
    assert "numpy" in got["heavy"] and "matplotlib" not in got["heavy"], got
    assert "fmpy" not in got["heavy"], got
