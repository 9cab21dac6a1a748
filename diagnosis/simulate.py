"""Thin adapter to the orchestrator: re-simulate a measured experiment with a model.

"The same experiment" is the declared set-up of the trial's metadata (controller and its
tuning, sensors, friction, robot, posture), the arm estimated from the measured trials,
and the trial's own ``tau_delta`` columns as the perturbation array.
"""

from __future__ import annotations

import numpy as np

from .errors import DiagnosisSimulationError

#: offset of the simulator's noise seed from the measured trial's, so a noisy model never
#: reuses the measured noise realisation
SEED_OFFSET = 7919


def nominal_setup(meta: dict, arm):
    """The orchestrator Setup declared by ``meta`` with the estimated arm."""
    from orchestrator import Setup
    return Setup.from_metadata(meta).with_arm(arm.M, arm.B, arm.K)


def simulate_like(trial, setup, effects: dict | None, n_samples: int, *, plant=None):
    """Simulate the first ``n_samples`` of ``trial``'s experiment with ``effects`` added.

    Returns
    -------
    trialformat.Trial or None
        None when the closed loop diverges or the simulation fails for this model (a
        candidate that cannot reproduce the experiment).
    """
    from orchestrator import simulate_trial
    seed = int((trial.meta.get("perturbation") or {}).get("seed", 0) or 0) + SEED_OFFSET
    try:
        sim = simulate_trial(setup, perturbed_dof=trial.perturbed_dof,
                             perturbation=np.asarray(trial.tau_delta[:n_samples]),
                             seed=seed, effects=effects or None, plant=plant,
                             name=f"{trial.name}-sim")
    except (RuntimeError, FloatingPointError, OverflowError) as exc:
        # a diverging loop, or a plant that refuses this model (e.g. an interface
        # compliance with an estimated arm whose M_h is not positive definite)
        if type(exc).__name__ in ("DivergenceError", "FMUCallError") or isinstance(
                exc, (FloatingPointError, OverflowError)):
            return None
        raise DiagnosisSimulationError(f"simulating {trial.name}: {exc}") from exc
    if not all(np.isfinite(sim.signal(s)).all() for s in ("theta", "tau_h", "tau_m")):
        return None
    return sim
