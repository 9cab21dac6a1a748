"""Targets on the paper grid (slow; skipped unless runs/grid or runs/grid_robust exist).

    python -m pytest -q -m slow tests/estimation/test_grid_targets.py
"""

from pathlib import Path

import numpy as np
import pytest

from estimation import evaluate, group_conditions, read_trials
from trialformat import reference as ref

ROOT = Path(__file__).resolve().parents[2] / "runs"
TARGET = [("full_corrected", "full", True, True)]


@pytest.mark.slow
@pytest.mark.parametrize("folder", ["grid", "grid_robust"])
def test_bias_removing_estimator_meets_targets_in_every_condition(folder):
    if not (ROOT / folder).is_dir():
        pytest.skip(f"runs/{folder} absent (python -m orchestrator grid --out runs/{folder})")
    groups = group_conditions(read_trials(ROOT / folder))
    assert len(groups) == 48
    arm = ref.arm_matrices()
    for cond, trials in groups.items():
        row = evaluate(trials, truth=arm, variants=TARGET)[0]
        assert row["vaf_min"] >= 99.5, (cond, row["vaf_min"])
        assert row["err_M_max"] <= 2.0 and row["err_K_max"] <= 2.0, cond
        assert row["err_B_max"] <= 3.0, (cond, row["err_B_max"])
        assert np.isfinite(row["coh_min"]) and row["coh_min"] > 0.9, cond
