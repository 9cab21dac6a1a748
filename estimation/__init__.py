"""Estimation of multi-joint arm impedance from trials (reference.md section 8).

Stands alone: imports only trialformat, numpy, scipy, pandas and matplotlib (never the
orchestrator). Any number of joints. See docs/estimation.md.
"""

from .accuracy import (SecondOrderFit, corrected_impedance, fit_impedance, fit_second_order,
                       left_limit_delay, true_impedance, vaf)
from .conditions import (PAPER, RECOMMENDED, VARIANTS, Condition, condition_of, evaluate,
                         group_conditions, variant_impedance)
from .errors import EstimationError, MatFileError
from .estimator import (METHODS, ImpedanceEstimate, band_mask, default_method,
                        estimate_impedance, perturbation_of)
from .io import read_trial, read_trials
from .matlab import read_trial_mat, write_trial_mat
from .spectral import (auto_spectrum, coherence, cross_spectrum, frequency_response,
                       ordinary_coherence)

__all__ = ["SecondOrderFit", "corrected_impedance", "fit_impedance", "fit_second_order", "left_limit_delay", "true_impedance", "vaf",
           "Condition", "condition_of", "evaluate", "group_conditions", "variant_impedance",
           "VARIANTS", "RECOMMENDED", "PAPER", "EstimationError",
           "MatFileError", "METHODS", "ImpedanceEstimate", "band_mask", "estimate_impedance",
           "default_method", "perturbation_of",
           "read_trial", "read_trials", "read_trial_mat", "write_trial_mat", "auto_spectrum",
           "coherence", "cross_spectrum", "frequency_response", "ordinary_coherence"]
