"""The trial interchange format (docs/spec/log-format.md) and the reference configuration.

Shared by the orchestrator (which writes trials) and the estimation and diagnosis packages
(which read them); it imports neither.
"""

from . import reference
from .errors import TrialFormatError
from .logs import (FORMAT, MIN_SAMPLES, SIGNALS, Trial, check_trial, column_names,
                   default_metadata, read_trial, read_trials, trial_exists, write_trial)

__all__ = ["reference", "TrialFormatError", "FORMAT", "MIN_SAMPLES", "SIGNALS", "Trial",
           "check_trial", "column_names", "default_metadata", "read_trial", "read_trials",
           "trial_exists", "write_trial"]
