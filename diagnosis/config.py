"""Options of a diagnosis and the names of its verdicts (docs/diagnosis.md)."""

from __future__ import annotations

from dataclasses import dataclass

from . import catalogue as cat
from .features import FeatureConfig

VERDICT_EFFECT = "effect"
VERDICT_NONE = "no significant gap"
VERDICT_UNEXPLAINED = "unexplained"
VERDICT_PARTLY = "partly explained"
#: the only gap was a convention of the files (conventions.py), found and corrected
VERDICT_CONVENTION = "convention mismatch"
#: a residual whose coherent (FRF) part differs between perturbation levels of the same
#: joint by more than this (mean z^2 excess of the level difference) is amplitude-dependent
AMPLITUDE_GAP = 1.0


@dataclass(frozen=True)
class DiagnosisConfig:
    """Options of a diagnosis (defaults documented in docs/diagnosis.md).

    Attributes
    ----------
    features : FeatureConfig
    calibration_s : float [s]
        Length of the calibration segment simulated per calibration trial.
    held_out_s : float [s]
        Longest held-out segment simulated per held-out trial.
    time_split_fraction : float
        When a joint has one trial only: the first fraction is calibration, the rest
        held out.
    calibration_trials_per_joint : int
    significance_gap : float
        Nominal gap (all trials) above which a gap is significant; calibrated on
        nominal-vs-nominal sets (docs/diagnosis.md).
    explained_fraction : float
        Held-out gap reduction an effect needs to be reported at all ("partly
        explained").
    confident_fraction : float
        Held-out gap reduction an effect needs to be named as *the* explanation; between
        the two the verdict is "partly explained: EFFECT closes N %, the rest lies in ...".
    pair_gain : float
        A pair is preferred to the best single effect when its calibration gap is below
        this fraction of the single's.
    grid_points, refine_iterations : int
        Bounded 1-D search: coarse (log-)grid, then Brent refinement in the best bracket.
    effects : tuple of str
        Catalogue effects tried (those that do not apply to the experiment are skipped
        and listed in the report).
    """

    features: FeatureConfig = FeatureConfig()
    calibration_s: float = 12.0
    held_out_s: float = 16.0
    time_split_fraction: float = 0.6
    calibration_trials_per_joint: int = 1
    significance_gap: float = 0.25
    explained_fraction: float = 0.5
    confident_fraction: float = 0.9
    pair_gain: float = 0.5
    grid_points: int = 5
    refine_iterations: int = 6
    effects: tuple = tuple(cat.CATALOGUE)

    def to_dict(self) -> dict:
        out = {k: v for k, v in self.__dict__.items() if k != "features"}
        out["effects"] = list(self.effects)
        out["features"] = self.features.to_dict()
        return out
