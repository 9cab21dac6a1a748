"""The experiment interface: what the diagnosis needs to know about an apparatus.

An :class:`Experiment` is the model of one kind of measurement set-up that the diagnosis
re-simulates. It says

- which signal is the known perturbation (the *input*) and which are compared (the
  *outputs*) (:meth:`perturbation_signal`, :meth:`output_signals`), hence the features;
- which catalogue effects apply to it (:meth:`applicable_effects`, from each effect's
  ``experiments`` in catalogue.py);
- how the limb (arm) is estimated from the measured trials (:meth:`estimate`), with the
  sampling and leakage handling the trials declare, as ``armimp estimate`` does;
- how one measured trial is re-simulated with a model and effects (:meth:`simulator`).

The pipeline (diagnosis.pipeline) calls only these; a new apparatus is one new subclass
registered in diagnosis/experiments/__init__.py.
"""

from __future__ import annotations

from ..catalogue import CATALOGUE
from ..features import SIGNALS, trial_features


class Experiment:
    """Base class of the experiments (see the module docstring).

    Attributes
    ----------
    kind : str
        The name catalogue effects use in their ``experiments`` (e.g. ``"exoskeleton"``).
    title : str
        One line for the report.
    meta : dict
        The declared set-up (metadata of the first trial; all trials declare the same).
    """

    kind = "abstract"
    title = "abstract experiment"
    #: metadata keys every trial of one diagnosis must declare identically
    declared_keys: tuple = ("fs", "n_dof")
    #: feature kinds compared (features.py)
    feature_kinds: tuple = ("frf", "noise", "static", "grid")
    #: True: only the best-ranked fit can be named (pipeline.verdict.choose); False: the
    #: best fit not flagged at a search bound
    name_best_fit_only: bool = False
    #: re-simulated through a plant FMU (``--fmu``, ``--rk4-step`` apply); False: the
    #: experiment has its own model and refuses those options (pipeline.conventions)
    uses_plant: bool = False
    #: the model is linear in the scale of angles and torques (K, B, I and gains scale
    #: with tau/theta): trials far from typical magnitudes are rescaled by a power of two
    #: (conventions.normalise_units) and the report's values scaled back
    scale_free: bool = False

    def __init__(self, trials):
        self.meta = trials[0].meta
        self.n_dof = trials[0].n_dof
        self.check_metadata(trials)

    # ------------------------------------------------------------------ which
    @classmethod
    def accepts(cls, trials) -> bool:
        """True when this class models the experiment that made ``trials``."""
        raise NotImplementedError

    def check_metadata(self, trials) -> None:
        """Refuse a set-up this experiment cannot model (DiagnosisInputError naming the
        file and key)."""

    def describe(self) -> dict:
        return {"kind": self.kind, "class": type(self).__name__, "title": self.title,
                "n_dof": self.n_dof}

    # ------------------------------------------------------------------ signals
    def perturbation_signal(self, trial) -> str:
        """The known input of ``trial`` (features are FRFs from it)."""
        return "tau_delta"

    def output_signals(self, trial) -> tuple:
        """The signals the gap compares."""
        return SIGNALS

    def features(self, trial, config, *, start=0, stop=None, context=None):
        """The features (features.trial_features) of ``trial`` for this experiment."""
        return trial_features(trial, config, start=start, stop=stop, context=context,
                              perturbation=self.perturbation_signal(trial),
                              signals=self.output_signals(trial), kinds=self.feature_kinds)

    def applicable_effects(self, names) -> tuple:
        """The effects of ``names`` that apply to this experiment (catalogue order kept).

        An effect applies when its catalogue entry lists this experiment's kind in its
        ``kinds`` (catalogue.Effect.applies_to) and :meth:`not_applicable` gives no
        reason against it.
        """
        return tuple(n for n in names if self.not_applicable(n) is None)

    def not_applicable(self, name: str) -> str | None:
        """Why catalogue effect ``name`` cannot be fitted to these trials (one phrase),
        or None when it can."""
        if CATALOGUE[name].applies_to(self.kind):
            return None
        return f"not applicable to the {self.kind} experiment ({self.title})"

    def check_selected_effects(self, names) -> None:
        """Refuse an explicit selection of effects (``--effects``) naming one that does
        not apply to these trials: silently skipping it left "no catalogue effect could
        be fitted" as the verdict.

        Raises
        ------
        DiagnosisInputError
            ``"--effects gravity: not applicable to the position experiment (...); the
            effects that apply: torque_sensor_lag, ... (or leave --effects out for all
            of them)"``.
        """
        from ..errors import DiagnosisInputError
        bad = [n for n in names if self.not_applicable(n) is not None]
        if not bad:
            return
        usable = self.applicable_effects(tuple(CATALOGUE))
        reasons = "; ".join(f"{n}: {self.not_applicable(n)}" for n in bad)
        offer = (f"the effects that apply: {', '.join(usable)} (or leave --effects out for "
                 f"all of them)" if usable else
                 "no catalogue effect applies to these trials: leave --effects out")
        raise DiagnosisInputError(f"--effects {','.join(names)}: {reasons}; {offer}")

    # ------------------------------------------------------------------ model
    def estimate(self, trials):
        """The limb model estimated from ``trials`` (diagnosis.arm.ArmModel)."""
        raise NotImplementedError

    def simulator(self, model, *, plant=None, rk4_step=None):
        """``simulate(trial, effects, n_samples) -> Trial or None`` for ``model``: the
        first ``n_samples`` of ``trial``'s experiment re-run with ``effects`` (None: the
        model cannot reproduce it, e.g. the loop diverges)."""
        raise NotImplementedError

    def divergence_hint(self) -> str:
        """Appended to the message of a nominal model that diverges."""
        return ""

    def model_with(self, model, effects: dict):
        """The limb a candidate model simulates (e.g. the estimate seen through a
        candidate compliance, removed); for the report. Default: ``model``."""
        return model
