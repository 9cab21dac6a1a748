"""Exceptions of the trial format, subclassing builtins so callers may catch either."""


class TrialFormatError(ValueError):
    """A trial (``NAME.csv`` + ``NAME.json``) breaks docs/spec/log-format.md.

    The message always names the file, and the row, column or key where it applies.
    """


class MatFileError(TrialFormatError):
    """A MATLAB ``.mat`` trial breaks the layout of docs/estimation.md ("MATLAB files").

    The message names the file and the variable or key.
    """
