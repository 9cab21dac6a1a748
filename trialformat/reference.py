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

#: Largest deviation of a joint angle from its posture in any trial [rad]: the master
#: stops a closed loop beyond it (diverged), and a recorded deviation beyond it reads as
#: angles stored in degrees (no joint's perturbation moves it 115 deg).
ANGLE_LIMIT_RAD = 2.0
#: A deviation read as degrees is a plausible perturbation below this [rad].
PLAUSIBLE_DEVIATION_RAD = 0.5

REFERENCE_PATH = Path(__file__).with_name("reference.json")
#: The reference configurations by name: the paper's two joints (docs/spec/reference.md)
#: and shoulder-elbow-wrist (docs/spec/reference-3dof.md), same keys.
ARMS = {"2dof": REFERENCE_PATH, "3dof": Path(__file__).with_name("reference-3dof.json")}


@lru_cache(maxsize=None)
def _load(arm: str = "2dof") -> dict:
    if arm not in ARMS:
        raise ValueError(f"reference arm must be one of {sorted(ARMS)}, got {arm!r}")
    with open(ARMS[arm], encoding="utf-8") as fh:
        return json.load(fh)


def reference(arm: str = "2dof") -> dict:
    """Return a fresh deep copy of a reference configuration (safe to modify).

    ``arm``: ``"2dof"`` (reference.md) or ``"3dof"`` (reference-3dof.md); ValueError else.
    """
    return copy.deepcopy(_load(arm))


def arm_matrices(arm: str = "2dof") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arm matrices ``(M_h, B_h, K_h)``, used as printed: Table I (2x2) or reference-3dof.md
    (3x3)."""
    block = _load(arm)["human_arm"]
    return tuple(np.array(block[key], dtype=float) for key in ("M_h", "B_h", "K_h"))


def friction_level(level: int, n_dof: int = 2, arm: str = "2dof") -> dict:
    """Friction metadata block (log-format.md keys) for a reference friction level 0-3
    (reference-3dof.md: joint 3 has 0.25 x the level's Fc, Fs and sigma2)."""
    ref = _load(arm)["friction"]
    row = _level_row(ref["levels"], level, "friction")
    scale = ref.get("joint_scale", [1.0] * n_dof)
    if len(scale) != n_dof:
        raise ValueError(f"the {arm} reference has {len(scale)} joints, not n_dof={n_dof}")
    return {
        "Fc": [row["Fc"] * s for s in scale],
        "Fs": [row["Fs"] * s for s in scale],
        "sigma2": [row["sigma2"] * s for s in scale],
        "sigma0": ref["sigma0"],
        "sigma1": ref["sigma1"],
        "ws": ref["ws"],
    }


def sensor_level(level: int) -> dict:
    """Sensor metadata block for a reference resolution level 0-3."""
    row = _level_row(_load()["sensor_resolution"]["levels"], level, "sensor resolution")
    return {"encoder_resolution_deg": row["encoder_deg"], "torque_resolution_nm": row["torque_nm"]}


def perturbation_peak(level: int, arm: str = "2dof") -> list[float]:
    """Peak |tau_delta| per joint [N m] for perturbation level 1-3."""
    levels = _load(arm)["perturbation"]["levels"]
    if level not in (1, 2, 3):
        raise ValueError(f"perturbation level must be 1, 2 or 3, got {level!r}")
    return list(levels[level - 1])


def controller(tuning: str = "reference", arm: str = "2dof") -> dict:
    """Controller metadata block for the 'reference' or 'robust' tuning (reference.md s. 7)."""
    ref = _load(arm)
    block = copy.deepcopy(ref["controller"])
    if tuning == "robust":
        block.update(copy.deepcopy(ref["controller_robust"]))
    elif tuning != "reference":
        raise ValueError(f"controller tuning must be 'reference' or 'robust', got {tuning!r}")
    block["tuning"] = tuning
    return block


def robot(arm: str = "2dof") -> dict:
    """Robot metadata block (reference.md section 3; reference-3dof.md adds link 3)."""
    block = copy.deepcopy(_load(arm)["robot"])
    return block


def spectral() -> dict:
    """Welch parameters of Table IV plus the evaluation band."""
    return copy.deepcopy(_load()["spectral"])


def _level_row(levels: list, level: int, what: str) -> dict:
    if not isinstance(level, (int, np.integer)) or not 0 <= level < len(levels):
        raise ValueError(f"{what} level must be an integer 0..{len(levels) - 1}, got {level!r}")
    return levels[level]
