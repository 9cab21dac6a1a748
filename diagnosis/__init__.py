"""Sim-to-real gap diagnosis: where the gap lies, which unmodelled effect causes it, how far
it shrinks once that effect is added, checked on data whose effect is withheld.

Public API::

    from diagnosis import diagnose, DiagnosisConfig, DiagnosisReport, DiagnosisInputError
    from diagnosis import CATALOGUE, trial_features, FeatureConfig, set_gap
    from diagnosis.validation import SetSpec, make_set, draw_specs, run_validation
"""

from .catalogue import CATALOGUE, catalogue_table, expand_effect, get_effect
from .core import (VERDICT_CONVENTION, VERDICT_EFFECT, VERDICT_NONE, VERDICT_PARTLY, VERDICT_UNEXPLAINED, DiagnosisConfig,
                   DiagnosisReport, DiagnosisSet, diagnose, split_units)
from .experiments import Experiment, experiment_for
from .errors import DiagnosisInputError, DiagnosisSimulationError
from .features import FeatureConfig, FeatureVector, grid_step, trial_features
from .gap import GapResult, make_normaliser, set_gap, z_scores

__all__ = ["CATALOGUE", "catalogue_table", "expand_effect", "get_effect", "VERDICT_EFFECT",
           "VERDICT_CONVENTION", "VERDICT_NONE", "VERDICT_PARTLY", "VERDICT_UNEXPLAINED", "DiagnosisConfig", "DiagnosisReport", "DiagnosisSet", "Experiment", "experiment_for",
           "diagnose", "split_units", "DiagnosisInputError", "DiagnosisSimulationError",
           "FeatureConfig", "FeatureVector", "grid_step", "trial_features", "GapResult",
           "make_normaliser", "set_gap", "z_scores"]
