"""Exceptions of the orchestrator, in one place, each subclassing a builtin.

Callers may catch the builtin (``ValueError``, ``RuntimeError``...) or the specific class.
Every message names the file, variable, value or simulated time it is about.
"""


class PlantFileError(ValueError):
    """The plant file is not a readable FMU (not a zip, no modelDescription.xml...)."""


class ContractError(ValueError):
    """The plant FMU breaks docs/spec/plant-contract.md; the message lists every problem."""


class ParameterError(KeyError):
    """A configuration sets a parameter the plant does not have (or that is not a parameter).

    ``str()`` of a KeyError shows the repr of its argument; this class shows the message.
    """

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class RateError(ValueError):
    """A communication step or rate that does not divide the control period evenly."""


class EffectError(ValueError):
    """An effects specification names an unknown effect or parameter, or a bad value."""


class SetupError(ValueError):
    """A set-up (levels, tuning, arm matrices, joint numbers, durations) is invalid."""


class FMUCallError(RuntimeError):
    """An FMI function returned a status above Warning (or Discard where none is allowed)."""


class DivergenceError(RuntimeError):
    """The closed loop diverged; the message gives the condition, the time and the value."""


class PlantWarning(UserWarning):
    """A plant FMU complaint that does not stop simulation (e.g. its model structure)."""
