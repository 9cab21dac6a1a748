"""Exceptions of the estimation package, subclassing builtins so callers may catch either."""


class EstimationError(ValueError):
    """Trials or arrays that cannot give an estimate (wrong shape, missing joint, bad option).

    The message names the trial, variable or value at fault.
    """


class MatFileError(ValueError):
    """A MATLAB ``.mat`` trial breaks the layout of docs/estimation.md.

    The message names the file and the variable or key.
    """
