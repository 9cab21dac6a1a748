"""The trial interchange format (docs/spec/log-format.md) and the reference configuration.

Shared by the orchestrator (which writes trials) and the estimation and diagnosis packages
(which read them); it imports neither. Readers: CSV of any common writer (pyarrow) and
MATLAB ``.mat`` v4-v7.3 (scipy.io, h5py).

Public names load their submodule on first use (PEP 562): importing the package, or a
light submodule such as ``trialformat.cliargs``, loads no numpy, so the CLI's --help and
option errors print at once.
"""

_EXPORTS = {
    "MatFileError": ".errors", "OutputError": ".errors", "TrialFormatError": ".errors",
    "SchedulingError": ".errors",
    "Scheduling": ".scheduling", "check_range": ".scheduling", "narrow_range": ".scheduling",
    "scheduling_of": ".scheduling",
    "FORMAT": ".logs", "MIN_SAMPLES": ".logs", "SIGNALS": ".logs", "Trial": ".logs",
    "atomic_write": ".logs", "check_out_parent": ".logs", "check_trial": ".logs",
    "check_trial_out": ".logs", "column_names": ".logs",
    "default_metadata": ".logs", "read_trial": ".logs", "read_trials": ".logs",
    "required_columns": ".logs", "seal_simulated": ".logs", "trial_exists": ".logs", "trial_stem": ".logs",
    "write_trial": ".logs", "misspelled_keys": ".logs",
    "is_mat": ".matlab", "read_trial_mat": ".matlab", "read_trials_mat": ".matlab",
    "write_trial_mat": ".matlab",
}
_SUBMODULES = ("cliargs", "csvtable", "errors", "firstuse", "logs", "matlab", "nlid",
               "processes", "reference", "scheduling", "tempdirs")

__all__ = ["reference", *_EXPORTS]


from .firstuse import first_use  # noqa: E402

__getattr__, __dir__ = first_use(__name__, globals(), _EXPORTS, _SUBMODULES)
