"""The exoskeleton under IMBIC with torque perturbations (the experiment this project
simulates): the plant FMU driven by the orchestrator at the control rate.

The declared set-up of the trials' metadata (controller and tuning, sensors, friction,
robot, posture) with the arm estimated from the measured trials is re-run with the trial's
own ``tau_delta`` columns as the perturbation (diagnosis.simulate). Candidate compliances
between the robot's sensors and the arm (transmission, cuff) are simulated with the arm
estimate seen through them removed (diagnosis.arm).
"""

from __future__ import annotations

from ..arm import arm_behind_cuff, arm_behind_transmission, estimate_arm, link_inertia
from ..errors import DiagnosisInputError
from ..evaluation import effects_key
from .base import Experiment

#: effects that sit between the robot's sensors and the arm: a candidate is simulated
#: with the arm estimate seen through it removed (arm.py)
COMPLIANCES = ("transmission_compliance", "interface_compliance")
#: the blocks of the set-up the plant and the controller need
REQUIRED_BLOCKS = ("posture_deg", "controller", "robot", "friction", "sensors")


class ExoskeletonIMBIC(Experiment):
    """Exoskeleton under IMBIC, torque perturbation ``tau_delta``, FMU plant.

    Inputs: ``tau_delta`` (the perturbation of the perturbed joint, or of every joint).
    Outputs compared: ``theta``, ``tau_h``, ``tau_m`` of every joint.
    """

    kind = "exoskeleton"
    uses_plant = True
    title = "exoskeleton under IMBIC, torque perturbation (plant FMU, orchestrator)"
    declared_keys = ("fs", "n_dof", "posture_deg", "controller", "sensors", "robot",
                     "friction")

    @classmethod
    def accepts(cls, trials) -> bool:
        return all(t.perturbation_kind == "torque" for t in trials)

    def check_metadata(self, trials) -> None:
        t = trials[0]
        missing = [k for k in REQUIRED_BLOCKS if k not in t.meta or t.meta[k] in (None, {})]
        if missing:
            raise DiagnosisInputError(
                f"trial {t.name!r}: the exoskeleton experiment of {self.n_dof} joint(s) needs "
                f"the metadata key(s) {missing} (no reference set-up of {self.n_dof} joints "
                f"fills them)")

    def estimate(self, trials):
        return estimate_arm(trials)

    def simulator(self, model, *, plant=None, rk4_step=None):
        from ..simulate import nominal_setup, simulate_like
        setup_for = setup_factory(self.meta, model, nominal_setup(self.meta, model))

        def simulate(trial, effects, n_samples):
            return simulate_like(trial, setup_for(effects), effects, n_samples, plant=plant,
                                 rk4_step=rk4_step)
        return simulate

    def divergence_hint(self) -> str:
        from ..simulate import NUMERICAL_RETRY_FACTOR
        return (f", also with the plant's RK4 step divided by {NUMERICAL_RETRY_FACTOR} (so "
                f"not a numerical failure)")

    def model_with(self, model, effects: dict):
        if not any(e in effects for e in COMPLIANCES):
            return None
        return arm_for(model, effects, self.meta)


def arm_for(arm, effects: dict, meta: dict):
    """The arm a candidate model simulates: the estimate with the candidate's
    transmission and/or cuff removed (motor side first), else the estimate itself.
    None when the removal fails."""
    out = arm
    trans = effects.get("transmission_compliance")
    if trans and out is not None:
        out = arm_behind_transmission(out, trans["k_t"], trans["c_t"], link_inertia(meta))
    cuff = effects.get("interface_compliance")
    if cuff and out is not None:
        out = arm_behind_cuff(out, cuff["k_s"], cuff["c_s"])
    return out


def setup_factory(meta: dict, arm, nominal):
    """effects -> Setup: the nominal one, or one with the arm behind a candidate
    compliance; cached per compliance."""
    from ..simulate import nominal_setup
    cache: dict = {}

    def setup_for(effects: dict):
        if not any(e in effects for e in COMPLIANCES):
            return nominal
        key = effects_key({e: effects.get(e) for e in COMPLIANCES})
        if key not in cache:
            behind = arm_for(arm, effects, meta)
            cache[key] = nominal if behind is None else nominal_setup(meta, behind)
        return cache[key]
    return setup_for
