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


#: a run whose plant state became non-finite is retried down this ladder of divisors of
#: the plant's RK4 step until a run is finite (LuGre sigma0 = 1e6 N m/rad diverges at
#: 5e-7 s and runs at 1e-7 s where the reference is 1e-5 s); each rung costs its factor
#: in plant time, so the ladder stops at 1e-8 s for the reference step
NUMERICAL_RETRY_FACTORS = (20, 100, 1000)
NUMERICAL_RETRY_FACTOR = NUMERICAL_RETRY_FACTORS[0]  # the first rung (kept for callers)


def simulate_like(trial, setup, effects: dict | None, n_samples: int, *, plant=None,
                  rk4_step: float | None = None):
    """Simulate the first ``n_samples`` of ``trial``'s experiment with ``effects`` added.

    The plant's RK4 step divides the control period at any rate (``rk4_step`` or the
    orchestrator's choice near the plant's default). A run whose plant failed (an FMI
    error: a non-finite state) is retried with the step divided by each of
    NUMERICAL_RETRY_FACTORS in turn until a run is finite: if one succeeds, the failure
    was numerical (a stiff model such as a large LuGre sigma0 at 1e-5 s), not the model;
    the run returned then records ``meta["simulation"]["numerical_retry"]`` (the steps
    that failed and the one that ran). A loop that leaves its torque or
    angle limits is a model that cannot reproduce the experiment (None), not retried.

    Returns
    -------
    trialformat.Trial or None
        None when the model cannot reproduce the experiment even with the smaller step.
    """
    from orchestrator import simulate_trial
    from orchestrator.trial import get_plant, rk4_step_for
    seed = int((trial.meta.get("perturbation") or {}).get("seed", 0) or 0) + SEED_OFFSET

    def run(step):
        return simulate_trial(setup, perturbed_dof=trial.perturbed_dof,
                              perturbation=np.asarray(trial.tau_delta[:n_samples]),
                              seed=seed, effects=effects or None, plant=plant,
                              name=f"{trial.name}-sim",
                              parameters=None if step is None else {"rk4_step": step})
    try:
        sim = run(rk4_step)
        if _finite(sim):
            return sim
        failure = "non-finite signals"
    except (RuntimeError, FloatingPointError, OverflowError) as exc:
        if not _model_failure(exc):
            raise DiagnosisSimulationError(f"simulating {trial.name}: {exc}") from exc
        if type(exc).__name__ != "FMUCallError":
            return None  # the loop left its limits: the model, not the numerics
        failure = f"{type(exc).__name__}: {exc}"
    default = (get_plant(plant) if not hasattr(plant, "parameters") else plant
               ).parameters.get("rk4_step")
    if default is None:
        return None
    first = rk4_step if rk4_step is not None else rk4_step_for(1.0 / trial.fs, float(default))
    failed = [first]
    for factor in NUMERICAL_RETRY_FACTORS:
        smaller = first / factor
        try:
            sim = run(smaller)
        except (RuntimeError, FloatingPointError, OverflowError) as exc:
            if not _model_failure(exc):
                raise DiagnosisSimulationError(f"simulating {trial.name}: {exc}") from exc
            if type(exc).__name__ != "FMUCallError":
                return None  # the loop left its limits: the model, not the numerics
            failed.append(smaller)
            continue
        if not _finite(sim):
            failed.append(smaller)
            continue
        sim.meta["simulation"]["numerical_retry"] = {
            "failed_rk4_step": first, "failed_rk4_steps": failed, "rk4_step": smaller,
            "failure": failure[:300]}
        return sim
    return None


def _model_failure(exc) -> bool:
    """A diverging loop, or a plant that refuses this model or fails numerically (e.g. an
    interface compliance with an estimated arm whose M_h is not positive definite)."""
    return type(exc).__name__ in ("DivergenceError", "FMUCallError") or isinstance(
        exc, (FloatingPointError, OverflowError))


def _finite(sim) -> bool:
    return all(np.isfinite(sim.signal(s)).all() for s in ("theta", "tau_h", "tau_m"))
