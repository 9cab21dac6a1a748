"""Sim-to-real gap diagnosis: where the gap lies, which unmodelled effect causes it, how far
it shrinks once that effect is added, checked on data whose effect is withheld.

Public API::

    from diagnosis import diagnose, DiagnosisConfig, DiagnosisReport, DiagnosisInputError
    from diagnosis import CATALOGUE, trial_features, FeatureConfig, set_gap
    from diagnosis.validation import SetSpec, make_set, draw_specs, run_validation
"""

_EXPORTS = {
    'CATALOGUE': '.catalogue',
    'catalogue_table': '.catalogue',
    'expand_effect': '.catalogue',
    'get_effect': '.catalogue',
    'VERDICT_CONVENTION': '.core',
    'VERDICT_EFFECT': '.core',
    'VERDICT_NONE': '.core',
    'VERDICT_PARTLY': '.core',
    'VERDICT_UNEXPLAINED': '.core',
    'DiagnosisConfig': '.core',
    'DiagnosisReport': '.core',
    'DiagnosisSet': '.core',
    'Experiment': '.experiments',
    'experiment_for': '.experiments',
    'diagnose': '.core',
    'split_units': '.core',
    'DiagnosisInputError': '.errors',
    'DiagnosisSimulationError': '.errors',
    'FeatureConfig': '.features',
    'FeatureVector': '.features',
    'grid_step': '.features',
    'trial_features': '.features',
    'GapResult': '.gap',
    'make_normaliser': '.gap',
    'set_gap': '.gap',
    'z_scores': '.gap',
}

__all__ = ["CATALOGUE", "catalogue_table", "expand_effect", "get_effect", "VERDICT_EFFECT",
           "VERDICT_CONVENTION", "VERDICT_NONE", "VERDICT_PARTLY", "VERDICT_UNEXPLAINED", "DiagnosisConfig", "DiagnosisReport", "DiagnosisSet", "Experiment", "experiment_for",
           "diagnose", "split_units", "DiagnosisInputError", "DiagnosisSimulationError",
           "FeatureConfig", "FeatureVector", "grid_step", "trial_features", "GapResult",
           "make_normaliser", "set_gap", "z_scores"]


from trialformat.firstuse import first_use  # noqa: E402

__getattr__, __dir__ = first_use(__name__, globals(), _EXPORTS)
