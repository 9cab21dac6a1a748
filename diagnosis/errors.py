"""Exceptions of the diagnosis package, subclassing builtins so callers may catch either."""


class DiagnosisInputError(ValueError):
    """The trials given to a diagnosis cannot be diagnosed together.

    Raised for a folder with no trial, trials whose declared set-ups disagree, trials
    too short for the spectral segment, or a bad option value. The message names the
    file (or option) and the offending value.
    """


class DiagnosisSimulationError(RuntimeError):
    """A simulation the diagnosis needs failed (e.g. an unstable closed loop)."""
