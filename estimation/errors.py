"""Exceptions of the estimation package, subclassing builtins so callers may catch either."""


class EstimationError(ValueError):
    """Trials or arrays that cannot give an estimate (wrong shape, missing joint, bad option).

    The message names the trial, variable or value at fault.
    """


from trialformat.errors import MatFileError  # noqa: E402  (moved there with the reader)
