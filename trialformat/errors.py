"""Exceptions of the trial format, subclassing builtins so callers may catch either."""


class TrialFormatError(ValueError):
    """A trial (``NAME.csv`` + ``NAME.json``) breaks docs/spec/log-format.md.

    The message always names the file, and the row, column or key where it applies.
    """


class MatFileError(TrialFormatError):
    """A MATLAB ``.mat`` trial breaks the layout of docs/estimation.md ("MATLAB files").

    The message names the file and the variable or key.
    """


class OutputError(ValueError):
    """An output path that would replace or delete what this project did not write (an
    input, a folder that is not one of its reports, an existing file). The message names
    the path and what would work."""


class SchedulingError(ValueError):
    """A scheduling variable (trialformat.scheduling) that cannot be used: unknown, of
    another length, constant, not finite, or covering too narrow a range. The message names
    the variable, the trial and its file, and what would work."""
