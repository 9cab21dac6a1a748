"""Estimation of multi-joint arm impedance from trials (reference.md section 8).

Stands alone: imports only trialformat, numpy, scipy, pandas and matplotlib (never the
orchestrator). Any number of joints. See docs/estimation.md.
"""

_EXPORTS = {
    'SecondOrderFit': '.accuracy',
    'corrected_impedance': '.accuracy',
    'fit_impedance': '.accuracy',
    'fit_second_order': '.accuracy',
    'left_limit_delay': '.accuracy',
    'true_impedance': '.accuracy',
    'vaf': '.accuracy',
    'PAPER': '.conditions',
    'RECOMMENDED': '.conditions',
    'VARIANTS': '.conditions',
    'Condition': '.conditions',
    'condition_of': '.conditions',
    'evaluate': '.conditions',
    'group_conditions': '.conditions',
    'variant_impedance': '.conditions',
    'EstimationError': '.errors',
    'MatFileError': '.errors',
    'METHODS': '.estimator',
    'ImpedanceEstimate': '.estimator',
    'band_mask': '.estimator',
    'default_method': '.estimator',
    'estimate_impedance': '.estimator',
    'perturbation_of': '.estimator',
    'read_trial': '.io',
    'read_trials': '.io',
    'read_trial_mat': '.matlab',
    'write_trial_mat': '.matlab',
    'auto_spectrum': '.spectral',
    'coherence': '.spectral',
    'cross_spectrum': '.spectral',
    'frequency_response': '.spectral',
    'ordinary_coherence': '.spectral',
}

__all__ = ["SecondOrderFit", "corrected_impedance", "fit_impedance", "fit_second_order", "left_limit_delay", "true_impedance", "vaf",
           "Condition", "condition_of", "evaluate", "group_conditions", "variant_impedance",
           "VARIANTS", "RECOMMENDED", "PAPER", "EstimationError",
           "MatFileError", "METHODS", "ImpedanceEstimate", "band_mask", "estimate_impedance",
           "default_method", "perturbation_of",
           "read_trial", "read_trials", "read_trial_mat", "write_trial_mat", "auto_spectrum",
           "coherence", "cross_spectrum", "frequency_response", "ordinary_coherence"]


from trialformat.firstuse import first_use  # noqa: E402

__getattr__, __dir__ = first_use(__name__, globals(), _EXPORTS)
