"""Validation of the diagnosis on data whose effect is withheld (docs/diagnosis.md).

:func:`make_validation_sets` writes sets of trials made by "truth" models (nominal model
plus withheld effects drawn from the catalogue's realistic ranges) with ``NAME.truth.json``
beside each trial; :func:`run_validation` diagnoses every set blind (the diagnosis reads
only ``NAME.csv``/``NAME.json``) and :func:`score` compares the verdicts with the truth.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

import trialformat as tf

from . import catalogue as cat
from .core import VERDICT_EFFECT, VERDICT_NONE, DiagnosisConfig, diagnose

TRUTH_SUFFIX = ".truth.json"


@dataclass(frozen=True)
class SetSpec:
    """One validation set.

    Attributes
    ----------
    name : str
    effects : tuple of (name, primary params)
        Withheld effects (empty: nothing withheld).
    seeds : tuple of int
        One trial per joint per seed.
    level : int
        Perturbation level.
    duration_s : float
    friction_level, resolution_level : int
        Declared (nominal) friction and sensor levels (reference.md).
    extra : dict
        Out-of-catalogue truth (plant parameters, e.g. an arm that differs), recorded in
        the truth file; empty for catalogue sets.
    """

    name: str
    effects: tuple = ()
    seeds: tuple = (1,)
    level: int = 3
    duration_s: float = 12.0
    friction_level: int = 0
    resolution_level: int = 0
    extra: dict = field(default_factory=dict)

    def tuning(self) -> str:
        robust = any(cat.get_effect(n).needs_robust_tuning(p) for n, p in self.effects)
        return "robust" if robust else "reference"

    def truth(self) -> dict:
        return {"effects": [{"name": n, "params": p} for n, p in self.effects],
                **({"outside_catalogue": self.extra} if self.extra else {})}


def draw_specs(rng: np.random.Generator, *, n_per_effect: int = 1, n_nominal: int = 2,
               n_pairs: int = 2, pairs: tuple = (), **common) -> list[SetSpec]:
    """Validation specs: each effect ``n_per_effect`` times at realistic magnitudes,
    ``n_nominal`` sets with nothing withheld, ``n_pairs`` sets of two effects."""
    specs = []
    for name, effect in cat.CATALOGUE.items():
        for i in range(n_per_effect):
            specs.append(SetSpec(f"{name}-{i}", ((name, effect.draw(rng)),),
                                 seeds=(int(rng.integers(1, 10_000)),), **common))
    for i in range(n_nominal):
        specs.append(SetSpec(f"nominal-{i}", (), seeds=(int(rng.integers(1, 10_000)),),
                             **common))
    names = list(cat.CATALOGUE)
    for i in range(n_pairs):
        a, b = pairs[i % len(pairs)] if pairs else rng.choice(names, 2, replace=False)
        specs.append(SetSpec(f"pair-{a}+{b}-{i}", ((a, cat.get_effect(a).draw(rng)),
                                                  (b, cat.get_effect(b).draw(rng))),
                             seeds=(int(rng.integers(1, 10_000)),), **common))
    return specs


def make_set(spec: SetSpec, folder, *, plant=None) -> Path:
    """Simulate the set's trials with its truth model and write them with truth files.

    Skips trials already written (resumable); returns the set's folder.
    """
    from orchestrator import Setup, simulate_trial

    folder = Path(folder) / spec.name
    folder.mkdir(parents=True, exist_ok=True)
    setup = Setup.reference(friction_level=spec.friction_level,
                            resolution_level=spec.resolution_level, tuning=spec.tuning())
    n = setup.n_dof
    effects = {name: cat.expand_effect(name, params, n) for name, params in spec.effects}
    for seed in spec.seeds:
        for k in range(1, n + 1):
            stem = folder / f"{spec.name}_s{seed}_j{k}"
            if tf.trial_exists(stem) and Path(str(stem) + TRUTH_SUFFIX).is_file():
                continue
            trial = simulate_trial(setup, perturbed_dof=k, level=spec.level, seed=seed,
                                   duration_s=spec.duration_s, effects=effects or None,
                                   parameters=spec.extra.get("parameters") or None,
                                   plant=plant, name=stem.name)
            trial.meta["source"] = "diagnosis validation set (truth withheld)"
            _atomic_json(Path(str(stem) + TRUTH_SUFFIX), spec.truth())
            tf.write_trial(stem, trial)
    return folder


def _atomic_json(path: Path, obj) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        json.dump(obj, fh, indent=2)
    os.replace(tmp, path)


def read_truth(folder) -> dict:
    """The truth of a set (for scoring only; the diagnosis never calls this)."""
    files = sorted(Path(folder).glob("*" + TRUTH_SUFFIX))
    return json.loads(files[0].read_text()) if files else {"effects": []}


def score_one(report, truth: dict) -> dict:
    """Compare one diagnosis with its truth."""
    true_names = sorted(e["name"] for e in truth["effects"])
    named = sorted(report.named)
    row = {"truth": true_names, "verdict": report.verdict, "named": named,
           "outside_catalogue": bool(truth.get("outside_catalogue")),
           "nominal_gap": report.gap["nominal_all"],
           "held_out_reduction": report.gap["named_held_out_reduction"],
           "elapsed_s": report.elapsed_s, "n_simulations": report.n_simulations}
    if not true_names:
        row["correct"] = report.verdict == VERDICT_NONE if not row["outside_catalogue"] \
            else report.verdict != VERDICT_EFFECT
        row["false_alarm"] = report.verdict != VERDICT_NONE
        return row
    row["top1"] = bool(report.ranking) and report.verdict == VERDICT_EFFECT and \
        report.named[0] in true_names if len(true_names) == 1 else None
    row["correct"] = named == true_names
    errors = {}
    for e in truth["effects"]:
        if e["name"] in report.fitted:
            errors[e["name"]] = cat.relative_parameter_error(e["name"], report.fitted[e["name"]],
                                                             e["params"])
    row["parameter_error"] = errors
    row["max_parameter_error"] = max((v for d in errors.values() for v in d.values()),
                                     default=None)
    # held-out reduction of the *true* effect's fit, whatever was named
    for r in report.ranking:
        if r["effects"] == true_names:
            row["true_effect_held_out_reduction"] = r["held_out_reduction"]
            row["true_effect_rank"] = report.ranking.index(r) + 1
            row["true_effect_fit"] = r["params"]
    return row
