"""MATLAB ``.mat`` trials: the reader lives in :mod:`trialformat.matlab`; kept here for callers."""

from trialformat.matlab import is_mat, read_trial_mat, write_trial_mat

__all__ = ["is_mat", "read_trial_mat", "write_trial_mat"]
