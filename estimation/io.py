"""Reading trials: CSV+JSON or MATLAB ``.mat``, by :mod:`trialformat` (kept here for callers)."""

from trialformat import read_trial, read_trials

__all__ = ["read_trial", "read_trials"]
