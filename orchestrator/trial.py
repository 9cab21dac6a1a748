"""One simulated trial: set-up + perturbation + hidden effects -> trialformat.Trial."""

from __future__ import annotations

import contextlib
import copy
import gc
import math
import os
import threading
from pathlib import Path

import numpy as np

from trialformat import Trial
from trialformat import reference as ref

from .controller import IMBIC
from .effects import parse_effects
from .errors import DivergenceError, FMUCallError, RateError, SetupError
from .master import DelayLine, Recorder, Sampler, check_angles, run_closed_loop, run_open_loop
from .perturbation import make_perturbation
from .plant import Plant
from .setup import reference_arm_of

_local = threading.local()


#: The built-in plants: the hand-written C FMU (the reference, and the fallback) and the
#: FMU exported from the Modelica source (fmus.modelica_build). Chosen by ``plant=``, else
#: by the environment variable ARMEXO_PLANT (``armimp --plant``), else "c".
PLANT_KINDS = ("c", "modelica")
PLANT_ENV = "ARMEXO_PLANT"


#: plant parameters (or inputs outside the contract) set for every trial of a run, as a
#: JSON object ``{"NAME": value}``: ``armimp diagnose --plant-parameter`` (its workers
#: inherit it, as they inherit ARMEXO_PLANT)
PLANT_PARAMETERS_ENV = "ARMEXO_PLANT_PARAMETERS"


def env_plant_parameters() -> dict:
    """The parameters of ``$ARMEXO_PLANT_PARAMETERS`` (empty when unset).

    Raises
    ------
    SetupError
        Not a JSON object of finite numbers (named).
    """
    import json
    import math

    text = os.environ.get(PLANT_PARAMETERS_ENV)
    if not text:
        return {}
    try:
        values = json.loads(text)
    except ValueError:
        values = None
    if not isinstance(values, dict) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            for v in values.values()):
        raise SetupError(f"{PLANT_PARAMETERS_ENV} = {text!r}: expected a JSON object of "
                         f"finite numbers, e.g. {{\"motor_enable\": 1}}")
    return {str(k): float(v) for k, v in values.items()}


def plant_kind(choice: str | None = None) -> str:
    """The built-in plant to use: ``choice``, else ``$ARMEXO_PLANT``, else ``"c"``.

    Raises
    ------
    SetupError
        Another value (named, with where it came from).
    """
    where = "plant"
    if choice is None:
        choice, where = os.environ.get(PLANT_ENV) or "c", PLANT_ENV
    if choice not in PLANT_KINDS:
        raise SetupError(f"{where} = {choice!r}: the built-in plants are {', '.join(PLANT_KINDS)}")
    return choice


def describe_plant(generation_tool: str) -> str:
    """Which plant an FMU is, from its generationTool: the C plant, the Modelica export, or
    another FMU."""
    if generation_tool.startswith("modelica "):
        return "exported from modelica/ArmExo (" + generation_tool + ")"
    if generation_tool == "fmus/generate.py":
        return "hand-written C plant (fmus/ArmExoPlant)"
    return f"external FMU ({generation_tool or 'generation tool not stated'})"


def default_fmu_path(n_dof: int = 2, plant: str | None = None) -> Path:
    """The built-in plant of n_dof links, built on first use: the C plant (package
    ``fmus``: ``ArmExoPlant.fmu`` for 2, ``ArmExoPlant3.fmu`` for 3) or, with
    ``plant="modelica"`` (or ``ARMEXO_PLANT=modelica``), the plant exported from the Modelica
    source (``ArmExoPlant_modelica.fmu``, ``ArmExoPlant3_modelica.fmu``).

    Raises
    ------
    SetupError
        ``fmus`` is not importable, it has no plant of n_dof links, an unknown plant kind,
        or the Modelica plant is asked for and cannot be exported (the reason in one line).
    """
    kind = plant_kind(plant)
    try:
        import fmus
        from fmus.variables import N_LINKS
    except ImportError as exc:  # the orchestrator can run other plants without it
        raise SetupError("no plant given and the reference plant package 'fmus' is not "
                         "importable; pass plant=<path to an FMU>") from exc
    if n_dof not in N_LINKS:
        raise SetupError(f"no built-in plant of {n_dof} joints (the C plant has n in "
                         f"{list(N_LINKS)}); pass plant=<path to an FMU of {n_dof} joints>")
    if kind == "modelica":
        from fmus import modelica_build

        try:
            return Path(modelica_build.default_fmu_path(n=n_dof))
        except modelica_build.BuildError as exc:
            raise SetupError(f"the Modelica plant of {n_dof} joints is not available: {exc}") from exc
    return Path(fmus.default_fmu_path(build_if_missing=True, n=n_dof))


def get_plant(path=None, n_dof: int = 2) -> Plant:
    """A Plant for ``path`` (default: the reference FMU of n_dof links), cached per thread
    and reused across trials (each trial resets it). A rebuilt file (new mtime/size) is
    reloaded."""
    path = Path(path) if path is not None else default_fmu_path(n_dof)
    stat = path.stat() if path.is_file() else None
    key = (str(path.resolve()), stat and (stat.st_mtime_ns, stat.st_size))
    cache = getattr(_local, "plants", None)
    if cache is None:
        cache = _local.plants = {}
    if key not in cache:
        cache[key] = Plant(path)
    return cache[key]


def _resolve_plant(plant, n_dof: int = 2) -> Plant:
    return plant if isinstance(plant, Plant) else get_plant(plant, n_dof)


def simulate_trial(setup, *, perturbed_dof, perturbation=None, level=3, seed=0,
                   duration_s=50.0, effects=None, plant=None, parameters=None,
                   communication_step_s=None, name="", human=None) -> Trial:
    """Simulate one trial of the closed loop (IMBIC at the control rate on a plant FMU).

    Parameters
    ----------
    setup : Setup
        Declared set-up (goes into the metadata) and the simulated arm.
    perturbed_dof : int or None
        1-based joint perturbed alone (decomposition masking), or None for all joints.
    perturbation : ndarray (N, n) [N m], optional
        Overrides ``level``/``seed``/``duration_s`` (its length sets N).
    level : int
        Perturbation level 1-3.
    seed : int
        Seed of the perturbation; the sensor noise uses the stream ``(seed, 1)``.
    duration_s : float [s]
        Trial length (N = duration_s * fs samples).
    effects : dict, optional
        Catalogue effects simulated but not declared (docs/spec/effects.md).
    plant : Plant or path, optional
        The plant FMU (default: the reference C plant, one cached instance per thread).
    parameters : dict, optional
        Extra FMU parameters by name (refused when the plant lacks one), over those of
        ``$ARMEXO_PLANT_PARAMETERS`` (:func:`env_plant_parameters`: ``armimp diagnose
        --plant-parameter``, inherited by the workers).
    communication_step_s : float [s], optional
        Communication step (default: the control period); it must divide the period.
    name : str
        Trial name (used in error messages and as ``Trial.name``).
    human : callable, optional
        An active torque of the limb, ``human(n, outputs)`` (master.run_closed_loop);
        a test model outside the catalogue, recorded as ``repr(human)`` under
        ``meta["simulation"]["human"]``.

    Returns
    -------
    trialformat.Trial
        Declared set-up in the standard keys; what was really simulated under
        ``meta["simulation"]``.

    Raises
    ------
    SetupError, EffectError, ParameterError, RateError, ContractError
        Bad input, named.
    DivergenceError
        The loop diverged (no trial is returned).
    FMUCallError
        The plant reported an error.
    """
    n, fs, ts = setup.n_dof, setup.fs, setup.Ts
    tau_delta, pert_meta = _perturbation(setup, perturbed_dof, perturbation, level, seed,
                                         duration_s)
    hidden = parse_effects(effects, n)
    plant = _resolve_plant(plant, n)
    if plant.n_dof != n:
        raise SetupError(f"plant {plant.path.name} has {plant.n_dof} joints, the set-up {n}")
    n_dec = plant.decimation(ts, communication_step_s)
    required = dict(hidden.plant_parameters)
    required.update(env_plant_parameters())
    required.update(parameters or {})
    _choose_rk4_step(plant, required, ts / n_dec)
    absent = plant.start(required, optional=setup.plant_parameters())

    sampler, noise_seed = _sampler(setup, hidden, seed, tau_delta.shape[0])
    controller = IMBIC(setup.controller_config(), perturbed_dof)
    delay = DelayLine(hidden.delay_samples, n) if hidden.delay_samples else None
    recorder = Recorder(("measured", "tau_m"))
    condition = _condition(name, setup, perturbed_dof, pert_meta, hidden.normalized)
    with _gc_paused(), _held_inputs_named(plant):
        try:
            run_closed_loop(plant.io, controller, sampler, tau_delta.tolist(), recorder,
                            control_period=ts, n_decimation=n_dec, delay=delay,
                            condition=condition, human=human)
        except FMUCallError as exc:
            raise plant.log.explain(exc) from exc
        rec = recorder.arrays()
        rec = {"tau_delta": tau_delta, "theta": rec["measured"][:, :n],
               "tau_h": rec["measured"][:, n:], "tau_m": rec["tau_m"]}
        check_angles(rec["theta"], condition, ts)

    meta = setup.to_metadata()
    meta.update(perturbed_dof=perturbed_dof, perturbation=pert_meta,
                source=f"simulated: orchestrator IMBIC master on plant FMU {plant.model_name}")
    meta["simulation"] = {
        "simulator": "orchestrator",
        "fmu": {"file": plant.path.name, "model_name": plant.model_name, "guid": plant.guid,
                "generation_tool": plant.generation_tool,
                "plant": describe_plant(plant.generation_tool)},
        "arm": setup.arm_metadata(),
        "effects": copy.deepcopy(hidden.normalized),
        "rk4_step": required.get("rk4_step", plant.parameters.get("rk4_step")),
        "communication_step_s": ts / n_dec,
        "parameters": required,
        "declared_parameters_not_in_plant": absent,
        "seed": pert_meta.get("seed"),
        "noise_seed": noise_seed,
    }
    if human is not None:
        meta["simulation"]["human"] = repr(human)
    t = np.arange(tau_delta.shape[0]) / fs
    return Trial(meta=meta, t=t, name=name, **rec)


@contextlib.contextmanager
def _gc_paused():
    """Pause Python's cyclic garbage collector over a loop that only allocates acyclic
    rows: its full collections would traverse every recorded row again and again
    (~10 % of a 50 s trial); reference counting still frees everything."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


#: the reference plant's internal RK4 step [s] (docs/plant.md)
REFERENCE_RK4_STEP_S = 1e-5


def rk4_step_for(period_s: float, reference_s: float = REFERENCE_RK4_STEP_S) -> float:
    """The RK4 step nearest ``reference_s`` that divides ``period_s`` a whole number of
    times: period / round(period / reference) (1e-5 s at 1 kHz, 9.96e-6 s at 1024 Hz,
    9.77e-6 s at 2048 Hz, 1e-5 s at 500 Hz)."""
    if not period_s > 0 or not reference_s > 0:
        raise RateError(f"period {period_s!r} s and RK4 step {reference_s!r} s must be > 0")
    return period_s / max(1, round(period_s / reference_s))


def _choose_rk4_step(plant, required: dict, step_s: float) -> None:
    """A plant with an ``rk4_step`` parameter left at its default is run with the step
    nearest that default that divides the communication step (any sample rate); one set
    by the caller must divide it, else it is refused up front with both values."""
    if "rk4_step" not in plant.parameters:
        return
    if "rk4_step" not in required:
        default = float(plant.parameters["rk4_step"])
        chosen = rk4_step_for(step_s, default)
        if chosen != default:
            required["rk4_step"] = chosen
        return
    var = plant.model_description and {v.name: v for v in
                                        plant.model_description.modelVariables}.get("rk4_step")
    check_rk4_step(required["rk4_step"], step_s, where=plant.path.name,
                   declared=(_number(getattr(var, "min", None)),
                             _number(getattr(var, "max", None))))


def _number(text):
    try:
        return None if text is None else float(text)
    except (TypeError, ValueError):
        return None


#: the most RK4 steps per communication step a run may take: at rk4_step = communication
#: step / 1e6 (1e-9 s at 1 kHz) a 0.5 s trial took 88 s (loaded machine), a 50 s trial
#: would take hours; the diagnosis' numerical retry goes down to a thousandth of the
#: default step (1e-8 s at 1 kHz, 1e5 steps)
MAX_RK4_STEPS_PER_COMM_STEP = 10 ** 6


def check_rk4_step(rk4_step, step_s: float, *, option: str = "rk4_step", where: str = "",
                   declared=(None, None)) -> None:
    """Refuse up front a plant RK4 step outside the accepted range or that does not divide
    the communication step ``step_s`` [s].

    The range is ``step_s / MAX_RK4_STEPS_PER_COMM_STEP`` to ``step_s``, within the
    plant's declared ``(min, max)`` of ``rk4_step`` where given (``where`` names the
    plant). ``option`` names the value in the message (``--rk4-step`` for the CLI).

    Raises
    ------
    RateError
        Naming ``option``, the value, the accepted range and a step that works.
    """
    if rk4_step is None:
        return
    value = float(rk4_step)
    lo, hi = step_s / MAX_RK4_STEPS_PER_COMM_STEP, step_s
    dmin, dmax = declared
    said = [f"{k} {v:g} s" for k, v in (("min", dmin), ("max", dmax)) if v is not None]
    plant = f" ({where or 'the plant'} declares rk4_step {', '.join(said)})" if said else ""
    lo = lo if dmin is None else max(lo, dmin)
    hi = hi if dmax is None else min(hi, dmax)
    if not (math.isfinite(value) and lo <= value <= hi and value > 0):
        raise RateError(
            f"{option} {rk4_step!r} s: outside the accepted range {lo:g} ... {hi:g} s for "
            f"the communication step {step_s!r} s (at most "
            f"10^{round(math.log10(MAX_RK4_STEPS_PER_COMM_STEP))} RK4 steps per "
            f"communication step, and at most one communication step){plant}; e.g. {option} "
            f"{rk4_step_for(step_s)!r} s (it must divide the communication step)")
    ratio = step_s / float(rk4_step)
    if not float(rk4_step) > 0 or round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-9 * ratio:
        what = "the plant's rk4_step" if option == "rk4_step" else option
        raise RateError(f"{what} {rk4_step!r} s does not divide the "
                        f"communication step {step_s!r} s (ratio {ratio:.9g}); use "
                        f"{option} {rk4_step_for(step_s, float(rk4_step) if float(rk4_step) > 0 else REFERENCE_RK4_STEP_S)!r} s")


def _perturbation(setup, perturbed_dof, perturbation, level, seed, duration_s):
    n, fs = setup.n_dof, setup.fs
    if perturbed_dof is not None and (isinstance(perturbed_dof, bool)
                                      or not isinstance(perturbed_dof, (int, np.integer))
                                      or not 1 <= perturbed_dof <= n):
        raise SetupError(f"perturbed_dof must be None or an integer in 1..{n}, "
                         f"got {perturbed_dof!r}")
    spec = ref.reference()["perturbation"]
    if perturbation is None:
        if not duration_s > 0:
            raise SetupError(f"duration_s must be > 0, got {duration_s!r}")
        n_samples = int(round(duration_s * fs))
        arm = reference_arm_of(n)
        if arm is None:
            raise SetupError(f"no reference perturbation peaks for {n} joints; pass "
                             f"perturbation=<(N, {n}) array> (e.g. make_perturbation(..., "
                             f"peak=...))")
        tau_delta = make_perturbation(level, seed, n_samples, n, fs, perturbed_dof)
        meta = {"level": level, "peak": ref.perturbation_peak(level, arm), "seed": seed,
                "cutoff_hz": spec["cutoff_hz"], "order": spec["butterworth_order"]}
        return tau_delta, meta
    tau_delta = np.array(perturbation, dtype=float)
    if tau_delta.ndim != 2 or tau_delta.shape[1] != n or not np.all(np.isfinite(tau_delta)):
        raise SetupError(f"perturbation must be a finite (N, {n}) array, got shape "
                         f"{tau_delta.shape}")
    if perturbed_dof is not None:
        others = np.delete(tau_delta, perturbed_dof - 1, axis=1)
        if np.any(others):
            raise SetupError(f"perturbation has non-zero columns besides the perturbed joint "
                             f"{perturbed_dof}")
    meta = {"level": None, "peak": np.max(np.abs(tau_delta), axis=0).tolist(), "seed": None,
            "custom": True}
    return tau_delta, meta


def _sampler(setup, hidden, seed, n_samples):
    enc_deg = (setup.sensors["encoder_resolution_deg"] if hidden.encoder_resolution_deg is None
               else hidden.encoder_resolution_deg)
    tau_res = (setup.sensors["torque_resolution_nm"] if hidden.torque_resolution_nm is None
               else hidden.torque_resolution_nm)
    theta_noise = tau_noise = noise_seed = None
    if any(hidden.theta_noise_std) or any(hidden.tau_noise_std):
        noise_seed = [int(seed), 1]
        rng = np.random.default_rng(noise_seed)
        n = setup.n_dof
        theta_noise = rng.standard_normal((n_samples, n)) * np.asarray(hidden.theta_noise_std)
        tau_noise = rng.standard_normal((n_samples, n)) * np.asarray(hidden.tau_noise_std)
    sampler = Sampler(setup.n_dof, np.radians(float(enc_deg)), float(tau_res),
                      theta_noise, tau_noise)
    return sampler, noise_seed


@contextlib.contextmanager
def _held_inputs_named(plant):
    """A divergence of a plant with inputs outside the contract held at their start values
    names them: an enable input left at 0 is a likely cause, and the fix is an option."""
    try:
        yield
    except DivergenceError as exc:
        held = getattr(plant, "held_inputs", None)
        if not held:
            raise
        shown = ", ".join(f"{k} = {v}" for k, v in held.items())
        raise DivergenceError(f"{exc}; the plant's input(s) outside the contract were held at "
                              f"their start values ({shown}): if one disables or changes the "
                              f"plant, set it with --plant-parameter NAME=VALUE") from None


def _condition(name, setup, perturbed_dof, pert_meta, effects) -> str:
    levels = setup.levels
    parts = [name] if name else []
    if levels:
        parts.append(f"friction level {levels.get('friction_level')}, resolution level "
                     f"{levels.get('resolution_level')}")
    parts.append(f"perturbation level {pert_meta.get('level')}, seed {pert_meta.get('seed')}, "
                 f"perturbed_dof {perturbed_dof}, tuning {setup.controller.get('tuning')}")
    if effects:
        parts.append(f"effects {effects}")
    return "[" + "; ".join(parts) + "]"


def simulate_plant(setup, tau_applied, *, plant=None, effects=None, parameters=None,
                   communication_step_s=None) -> dict:
    """Step the plant alone under a torque history (no controller, no sampler).

    Parameters
    ----------
    setup : Setup
    tau_applied : ndarray (N, n) [N m]
        Torque held over each control period.
    plant, effects, parameters, communication_step_s
        As in :func:`simulate_trial` (only plant-side effects apply).

    Returns
    -------
    dict
        ``theta``, ``tau_h`` (N, n) plant outputs at each sample (before its torque acts).
    """
    plant = _resolve_plant(plant, setup.n_dof)
    hidden = parse_effects(effects, setup.n_dof)
    required = dict(hidden.plant_parameters)
    required.update(env_plant_parameters())
    required.update(parameters or {})
    plant.start(required, optional=setup.plant_parameters())
    recorder = Recorder(("outputs",))
    run_open_loop(plant.io, np.asarray(tau_applied, dtype=float).tolist(), recorder,
                  control_period=setup.Ts,
                  n_decimation=plant.decimation(setup.Ts, communication_step_s))
    out = recorder.arrays()["outputs"]
    n = setup.n_dof
    return {"theta": out[:, :n], "tau_h": out[:, n:2 * n]}

