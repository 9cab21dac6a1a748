"""The reference configuration of the simulation study (docs/spec/reference.md).

The project keeps its own copy (``reference.json`` beside this file) so that it runs
without the shared spec folder; ``tests/trialformat`` compares it with the shared copy
when that folder is present.
"""

from __future__ import annotations

import copy
import json
from functools import lru_cache
from pathlib import Path

import numpy as np

REFERENCE_PATH = Path(__file__).with_name("reference.json")


@lru_cache(maxsize=1)
def _load() -> dict:
    with open(REFERENCE_PATH, encoding="utf-8") as fh:
        return json.load(fh)


def reference() -> dict:
    """Return a fresh deep copy of the reference configuration (safe to modify)."""
    return copy.deepcopy(_load())


def arm_matrices() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Table I arm matrices ``(M_h, B_h, K_h)`` as 2x2 arrays, used as printed."""
    arm = _load()["human_arm"]
    return tuple(np.array(arm[key], dtype=float) for key in ("M_h", "B_h", "K_h"))


def friction_level(level: int, n_dof: int = 2) -> dict:
    """Friction metadata block (log-format.md keys) for a reference friction level 0-3."""
    ref = _load()["friction"]
    row = _level_row(ref["levels"], level, "friction")
    return {
        "Fc": [row["Fc"]] * n_dof,
        "Fs": [row["Fs"]] * n_dof,
        "sigma2": [row["sigma2"]] * n_dof,
        "sigma0": ref["sigma0"],
        "sigma1": ref["sigma1"],
        "ws": ref["ws"],
    }


def sensor_level(level: int) -> dict:
    """Sensor metadata block for a reference resolution level 0-3."""
    row = _level_row(_load()["sensor_resolution"]["levels"], level, "sensor resolution")
    return {"encoder_resolution_deg": row["encoder_deg"], "torque_resolution_nm": row["torque_nm"]}


def perturbation_peak(level: int) -> list[float]:
    """Peak |tau_delta| per joint [N m] for perturbation level 1-3."""
    levels = _load()["perturbation"]["levels"]
    if level not in (1, 2, 3):
        raise ValueError(f"perturbation level must be 1, 2 or 3, got {level!r}")
    return list(levels[level - 1])


def controller(tuning: str = "reference") -> dict:
    """Controller metadata block for the 'reference' or 'robust' tuning (reference.md s. 7)."""
    ref = _load()
    block = copy.deepcopy(ref["controller"])
    if tuning == "robust":
        block.update(copy.deepcopy(ref["controller_robust"]))
    elif tuning != "reference":
        raise ValueError(f"controller tuning must be 'reference' or 'robust', got {tuning!r}")
    block["tuning"] = tuning
    return block


def robot() -> dict:
    """Robot metadata block (reference.md section 3)."""
    block = copy.deepcopy(_load()["robot"])
    return block


def spectral() -> dict:
    """Welch parameters of Table IV plus the evaluation band."""
    return copy.deepcopy(_load()["spectral"])


def _level_row(levels: list, level: int, what: str) -> dict:
    if not isinstance(level, (int, np.integer)) or not 0 <= level < len(levels):
        raise ValueError(f"{what} level must be an integer 0..{len(levels) - 1}, got {level!r}")
    return levels[level]
