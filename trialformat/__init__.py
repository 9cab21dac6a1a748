"""The trial interchange format (docs/spec/log-format.md) and the reference configuration.

Shared by the orchestrator (which writes trials) and the estimation and diagnosis packages
(which read them); it imports neither. Readers: CSV of any common writer (pyarrow) and
MATLAB ``.mat`` v4-v7.3 (scipy.io, h5py).
"""

from . import reference
from .errors import MatFileError, TrialFormatError
from .logs import (FORMAT, MIN_SAMPLES, SIGNALS, Trial, atomic_write, check_trial,
                   column_names, default_metadata, read_trial, read_trials, required_columns,
                   trial_exists, write_trial)
from .matlab import is_mat, read_trial_mat, read_trials_mat, write_trial_mat

__all__ = ["reference", "TrialFormatError", "MatFileError", "FORMAT", "MIN_SAMPLES",
           "SIGNALS", "Trial", "atomic_write", "check_trial", "column_names",
           "default_metadata", "read_trial", "read_trials", "required_columns",
           "trial_exists", "write_trial", "is_mat", "read_trial_mat", "read_trials_mat",
           "write_trial_mat"]
