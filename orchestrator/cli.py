"""Command line: ``python -m orchestrator`` / ``armimp`` with subcommands.

Only argument parsing lives here; the work is done by library functions. The estimation
and diagnosis packages add their own subcommands through ``register(subparsers)`` in their
``cli`` modules, when those modules exist.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import os
import sys
from pathlib import Path

from trialformat.cliargs import MAX_SAMPLES, check_samples, number

from .errors import SetupError

# parse-time checks of the numbers (trialformat.cliargs): out-of-range values are refused
# in one line naming the option and a value that works
_DURATION = number("--duration", 0, MAX_SAMPLES / 1000, 50, unit="s")
_FS = number("--fs", 0, 100_000, 1000, unit="Hz")
_RK4 = number("--rk4-step", 0, 0.01, 1e-5, unit="s")
_COMM = number("--comm-step", 0, 1, 0.001, unit="s")
_WORKERS = number("--workers", 1, 1024, 2, integer=True, lo_open=False)
_TOTALS = number("--totals", 0, MAX_SAMPLES / 1000, 70, unit="s")


def main(argv=None) -> int:
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
    except KeyboardInterrupt:
        print("armimp: interrupted", file=sys.stderr)
        return 130
    import os

    if args.plant is not None:  # every subcommand's default plant (grid workers inherit it)
        os.environ["ARMEXO_PLANT"] = args.plant
        if getattr(args, "fmu", None) is not None:  # said once, not resolved silently
            print(f"note: the plant is {args.fmu} (--fmu); --plant {args.plant} chooses the "
                  f"built-in plant only when no FMU is given", file=sys.stderr)
    if not hasattr(args, "func"):
        parser.print_help()
        return 2
    _plain_warnings()
    terminated = _sigterm_as_interrupt()
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt as exc:
        # Ctrl-C or SIGTERM (a job scheduler): the workers are stopped and what finished is
        # recorded (a re-run resumes); one line, exit 130 (SIGINT) or 143 (SIGTERM)
        detail = f": {exc}" if str(exc) else ""
        print(f"armimp {args.command}: interrupted{detail}", file=sys.stderr)
        return 128 + signal_number(terminated)
    except (ValueError, KeyError, RuntimeError, OSError) as exc:
        # escaped: a file's bytes (a binary header, escape sequences) never reach the
        # terminal raw
        from trialformat.csvtable import printable
        print(f"armimp {args.command}: error: {printable(str(exc), lines=True)}", file=sys.stderr)
        return 1


def _sigterm_as_interrupt() -> dict:
    """SIGTERM (a job scheduler's stop, ``kill PID``) raises KeyboardInterrupt as Ctrl-C
    does, so the same path stops the workers and keeps what finished; a second SIGTERM
    during that clean-up is ignored. Returns ``{"signal": signum or None}``, set when the
    signal came."""
    import signal

    state = {"signal": None}

    def handler(signum, frame):
        state["signal"] = signum
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt

    try:
        signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread (main() called from a library's thread)
        pass
    return state


def signal_number(state: dict) -> int:
    """The signal that interrupted the command: SIGTERM's number, else SIGINT's (2)."""
    import signal

    return int(state["signal"] or signal.SIGINT)


def _plain_warnings() -> None:
    """A library warning (metadata filled from defaults, few Welch segments) reaches the
    terminal as one escaped line ``note: ...``, not with Python's source line."""
    import warnings

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, (DeprecationWarning, FutureWarning)):
            return  # a library's notice to its own callers (mat-io on pandas), not the user's
        from trialformat.csvtable import printable
        print(f"note: {printable(str(message), lines=True)}", file=sys.stderr)

    warnings.showwarning = show


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="armimp", description="Arm impedance co-simulation: IMBIC master, trials, grid.")
    parser.add_argument("--plant", choices=("c", "modelica"), default=None,
                        help="built-in plant when no --fmu is given: the hand-written C FMU "
                             "(default) or the FMU exported from modelica/ArmExo (also "
                             "$ARMEXO_PLANT)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_simulate(sub)
    _add_grid(sub)
    _add_paper(sub)
    _add_tractability(sub)
    _add_info(sub)
    for module in ("estimation.cli", "diagnosis.cli"):
        try:
            mod = importlib.import_module(module)
        except ImportError:
            continue
        register = getattr(mod, "register", None)
        if register is not None:
            register(sub)
    return parser


# ----------------------------------------------------------------------------- simulate
def _add_simulate(sub):
    p = sub.add_parser("simulate", help="simulate one trial and write NAME.csv/.json")
    p.add_argument("--out", required=True, help="output stem (NAME: NAME.csv + NAME.json; "
                   "NAME.mat: one .mat; FOLDER/: FOLDER/FOLDER.csv in it); an "
                   "existing NAME.csv/.json is replaced only when it is an earlier simulated "
                   "trial of this project, or with --force")
    p.add_argument("--force", action="store_true",
                   help="replace an existing NAME.csv/.json that is not a simulated trial")
    p.add_argument("--friction", type=int, default=0, help="declared friction level 0-3")
    p.add_argument("--resolution", type=int, default=0, help="declared sensor level 0-3")
    p.add_argument("--perturbation", type=int, default=3, help="perturbation level 1-3")
    p.add_argument("--dof", default="1", help="perturbed joint (1-based) or 'all'")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=_DURATION, default=50.0, help="trial length [s]")
    p.add_argument("--tuning", default="reference", choices=("reference", "robust"))
    p.add_argument("--arm", default="2dof", choices=("2dof", "3dof"),
                   help="reference configuration: two joints (reference.md) or shoulder, "
                        "elbow, wrist (reference-3dof.md)")
    p.add_argument("--no-tde", action="store_true",
                   help="switch the controller's time-delay estimation off")
    p.add_argument("--effects", default=None,
                   help='hidden effects as JSON, e.g. \'{"delay": {"samples": 2}}\'')
    p.add_argument("--comm-step", type=_COMM, default=None,
                   help="communication step [s] (default: the control period)")
    p.add_argument("--fmu", default=None, help="plant FMU (default: the reference plant)")
    p.add_argument("--fs", type=_FS, default=None,
                   help="control and sampling rate [Hz] (default: the reference 1000 Hz)")
    p.add_argument("--rk4-step", type=_RK4, default=None,
                   help="the plant's internal RK4 step [s]; it must divide the "
                        "communication step (default: the plant's, or the step nearest it "
                        "that divides the communication step)")
    _add_plant_parameter(p)
    p.set_defaults(func=_simulate)


def _simulate(args) -> int:
    from trialformat import check_trial_out, write_trial

    from .setup import Setup
    from .trial import simulate_trial

    dof = None if args.dof == "all" else _int(args.dof, "--dof")
    effects = _json(args.effects, "--effects")
    out, as_mat = simulate_target(args.out)
    check_trial_out(out, "--out", force=args.force)  # before the run, never after it
    if as_mat and Path(out).with_suffix(".mat").exists() and not args.force:
        from trialformat import OutputError
        raise OutputError(f"--out {args.out}: {out}.mat exists; it is left as it is: give "
                          f"a new name, or --force to replace it")
    setup = Setup.reference(args.friction, args.resolution, args.tuning, args.arm)
    check_samples(args.duration, args.fs or setup.fs)
    if args.fs is not None:
        setup = dataclasses.replace(setup, fs=float(args.fs))
    if args.no_tde:
        setup = setup.with_controller(time_delay_estimation=False)
    parameters = dict(args.plant_parameter or {})
    given = parameters.get("rk4_step")
    if args.rk4_step is not None and given is not None and given != args.rk4_step:
        raise SetupError(f"--rk4-step {args.rk4_step:g} and --plant-parameter "
                         f"rk4_step={given:g} disagree; give the plant's RK4 step once "
                         f"(--rk4-step {args.rk4_step:g})")
    if args.rk4_step is not None:
        from .trial import check_rk4_step
        # refused before the plant loads: the range follows from the communication step
        check_rk4_step(args.rk4_step, args.comm_step or setup.Ts, option="--rk4-step")
        parameters["rk4_step"] = args.rk4_step
    trial = simulate_trial(setup, perturbed_dof=dof, level=args.perturbation, seed=args.seed,
                           duration_s=args.duration, effects=effects, plant=args.fmu,
                           communication_step_s=args.comm_step, name=Path(out).name,
                           parameters=parameters or None)
    if as_mat:
        from trialformat import write_trial_mat
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        path = write_trial_mat(Path(str(out) + ".mat"), trial)
    else:
        from trialformat import seal_simulated
        path = write_trial(out, trial)
        seal_simulated(path)  # replaced by a later run only while it is this file
    print(f"wrote {path} ({trial.n_samples} samples)")
    return 0


def simulate_target(out) -> tuple[Path, bool]:
    """The trial stem ``simulate --out`` writes and whether as ``.mat``.

    ``NAME`` / ``NAME.csv`` / ``NAME.json``: ``NAME.csv`` + ``NAME.json``; ``NAME.mat``:
    one ``NAME.mat`` (metadata inside); a folder (an existing one, or a path ending in
    ``/``): the trial is written into it, named after the folder (``S5/`` ->
    ``S5/S5.csv``), never beside it."""
    from trialformat import trial_stem
    text = str(out)
    path = Path(text)
    if text.endswith(("/", os.sep)) or path.is_dir():
        return path / path.resolve().name, False
    return trial_stem(path), path.name.lower().endswith(".mat")


# ----------------------------------------------------------------------------- grid
def _add_grid(sub):
    p = sub.add_parser("grid", help="run the paper grid (48 conditions x 2 joints)",
                       description="Run a grid of trials into OUT (resumable). Seeds: "
                                   "base + 10 P + k, k = 0 for all joints.")
    p.add_argument("out", help="output folder (re-running skips completed trials)")
    p.add_argument("--workers", type=_WORKERS, default=2, help="local processes (default 2)")
    p.add_argument("--scheduler", default=None,
                   help="Dask distributed scheduler address (e.g. tcp://127.0.0.1:8786)")
    p.add_argument("--duration", type=_DURATION, default=50.0, help="trial length [s]")
    p.add_argument("--friction", type=int, nargs="+", default=[0, 1, 2, 3])
    p.add_argument("--resolution", type=int, nargs="+", default=[0, 1, 2, 3])
    p.add_argument("--perturbation", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--dofs", type=_dof, nargs="+", default=[1, 2],
                   help="perturbed joints (1-based) and/or 'all' (every joint at once, "
                        "named ..._dofall), e.g. --dofs 1 2 all (default: 1 2)")
    p.add_argument("--seed", type=int, default=0, help="base seed")
    p.add_argument("--tuning", default="reference", choices=("reference", "robust"))
    p.add_argument("--effects", default=None, help="hidden effects as JSON")
    p.add_argument("--arm", default="2dof", choices=("2dof", "3dof"),
                   help="reference configuration (3dof: reference-3dof.md, --dofs 1 2 3 ...)")
    p.add_argument("--fmu", default=None, help="plant FMU (default: the reference plant)")
    _add_plant_parameter(p)
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_grid)


def _grid(args) -> int:
    from .grid import run_grid

    manifest = run_grid(args.out, workers=args.workers, scheduler=args.scheduler,
                        progress=not args.no_progress, friction_levels=args.friction,
                        resolution_levels=args.resolution,
                        perturbation_levels=args.perturbation, dofs=args.dofs,
                        duration_s=args.duration, base_seed=args.seed, tuning=args.tuning,
                        effects=_json(args.effects, "--effects"), fmu_path=args.fmu,
                        arm=args.arm, plant_parameters=dict(args.plant_parameter or {}) or None)
    print(f"grid: {manifest['n_done']} done, {manifest['n_skipped']} skipped, "
          f"{manifest['n_failed']} failed in {manifest['wall_s']:.1f} s -> {args.out}")
    for r in manifest["trials"]:
        if r["status"] == "failed":
            print(f"  FAILED {r['name']}: {r['error']}")
    return 1 if manifest["n_failed"] else 0


# ----------------------------------------------------------------------------- paper
def _add_paper(sub):
    p = sub.add_parser(
        "paper", help="the paper's study end to end: grid + all-joints trials + report",
        description="Simulate the decomposition grid (96 trials) and the all-joints trials "
                    "(48) into OUT/trials (resumable), then write the estimation report "
                    "(Figs. 2-4, tables against Table I, or reference-3dof with --arm "
                    "3dof) into OUT/report and print the worst cases. --quick: the four "
                    "corner conditions at perturbation level 3 with 20 s trials (12 "
                    "trials, 16 with --arm 3dof; 15-25 s).")
    p.add_argument("--out", required=True, help="run folder (re-running resumes)")
    p.add_argument("--tuning", default="reference", choices=("reference", "robust"))
    p.add_argument("--duration", type=_DURATION, default=None,
                   help="trial length [s] (default 50; 20 with --quick)")
    p.add_argument("--workers", type=_WORKERS, default=2, help="local processes (default 2)")
    p.add_argument("--scheduler", default=None,
                   help="Dask distributed scheduler address (e.g. tcp://127.0.0.1:8786)")
    p.add_argument("--quick", action="store_true",
                   help="small built-in default: corners F0/F3 x R0/R3, level 3, 20 s")
    p.add_argument("--seed", type=int, default=0, help="base seed")
    p.add_argument("--arm", default="2dof", choices=("2dof", "3dof"),
                   help="reference configuration: 2dof (the paper's two joints) or 3dof "
                        "(shoulder, elbow, wrist, reference-3dof.md: 48 conditions x 3 "
                        "decomposition trials + 48 all-joints trials)")
    p.add_argument("--fmu", default=None, help="plant FMU (default: the reference plant)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_paper)


def _paper(args) -> int:
    from .paper import run_paper, summary_lines

    result = run_paper(args.out, quick=args.quick, tuning=args.tuning,
                       duration_s=args.duration, workers=args.workers,
                       scheduler=args.scheduler, progress=not args.no_progress,
                       fmu_path=args.fmu, base_seed=args.seed, arm=args.arm)
    print("\n".join(summary_lines(result)))
    incomplete = result["grid"]["n_failed"] or result["skipped_conditions"]
    return 1 if incomplete else 0


# ----------------------------------------------------------------------------- tractability
def _add_tractability(sub):
    p = sub.add_parser(
        "tractability", help="decomposition vs MIMO as the number of joints grows (n = 2..7)",
        description="The tractability study of docs/spec/reference-3dof.md: per n and total "
                    "experiment time T, n decomposition trials of T/n against one all-joints "
                    "trial of T (n = 2, 3 on the C FMU, n = 3..7 on the linear pythonfmu "
                    "plant); writes OUT/tractability.json, OUT/table.md and "
                    "OUT/fig_tractability.png (resumable).")
    p.add_argument("--out", required=True, help="run folder (re-running resumes)")
    p.add_argument("--n", type=int, nargs="+", default=None, help="numbers of joints (2..7)")
    p.add_argument("--totals", type=_TOTALS, nargs="+", default=None,
                   help="total experiment times T [s] (default 70 175 350)")
    p.add_argument("--quick", action="store_true", help="n = 2, 3, 4 at T = 70 s")
    p.add_argument("--workers", type=_WORKERS, default=2, help="local processes (default 2)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_tractability)


def _tractability(args) -> int:
    from . import tractability as tr

    kwargs = {}
    if args.n:
        kwargs["ns"] = tuple(args.n)
    if args.totals:
        kwargs["totals_s"] = tuple(args.totals)
    result = tr.run_tractability(args.out, quick=args.quick, workers=args.workers,
                                 progress=not args.no_progress, **kwargs)
    print("\n".join(tr.summary_lines(result)))
    print(f"table: {Path(args.out) / 'table.md'}; figure: "
          f"{Path(args.out) / 'fig_tractability.png'}")
    return 1 if result["failures"] else 0


# ----------------------------------------------------------------------------- info
def _add_info(sub):
    p = sub.add_parser("info", help="check a plant FMU's contract and list its parameters")
    p.add_argument("fmu", nargs="?", default=None, help="plant FMU (default: reference)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_info)


def _info(args) -> int:
    from .plant import Plant
    from .trial import default_fmu_path, describe_plant

    path = args.fmu if args.fmu is not None else default_fmu_path()
    with Plant(path) as plant:
        info = plant.describe()
    info["plant"] = describe_plant(info["generation_tool"])
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"{info['file']}: FMI {info['fmi_version']} Co-Simulation, model "
          f"{info['model_name']}, GUID {info['guid']}, generated by "
          f"{info['generation_tool'] or '?'}")
    print(f"plant: {info['plant']}")
    extra = info.get("inputs_outside_contract") or {}
    print(f"contract: OK, {info['n_dof']} joints (tau_m, theta, tau_h"
          f"{', omega' if info['has_omega'] else ''})"
          + (f"; {len(extra)} input(s) outside the contract: "
             + ", ".join(f"{k} (start {v})" for k, v in extra.items()) if extra else ""))
    if info["fixed_communication_step_s"]:
        print(f"fixed communication step: {info['fixed_communication_step_s']} s "
              f"(stepped at it)")
    if info["converted_units"]:
        print("units: declared units other than rad, N m, rad/s, converted by the master")
    if extra:
        print(f"inputs outside the contract ({len(extra)}; the master never drives them, they "
              f"stay at these values unless set with --plant-parameter NAME=VALUE):")
        for name, value in extra.items():
            print(f"  {name} = {value}")
    if info.get("once_per_process"):
        print("canBeInstantiatedOnlyOncePerProcess: one instance at a time; a grid runs each "
              "trial in a fresh worker process")
    print(f"parameters ({len(info['parameters'])}):")
    for name, value in info["parameters"].items():
        print(f"  {name} = {value}")
    return 0


def _add_plant_parameter(p):
    p.add_argument("--plant-parameter", action="append", type=_name_value, default=None,
                   metavar="NAME=VALUE",
                   help="set a plant parameter, or an input outside the contract (listed by "
                        "'armimp info', e.g. motor_enable=1), before each trial; repeatable")


def _name_value(text):
    """``NAME=VALUE`` -> (name, float value); argparse reports a bad one naming it."""
    import math

    name, sep, value = text.partition("=")
    name = name.strip()
    try:
        number = float(value)
    except ValueError:
        number = None
    if not sep or not name or number is None or not math.isfinite(number):
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE with a finite number, got "
                                         f"{text!r}")
    return name, number


def _dof(text):
    from .grid import parse_dof

    try:
        k = parse_dof(text)
    except SetupError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return "all" if k is None else k


def _int(text, option):
    try:
        return int(text)
    except ValueError:
        raise SetupError(f"{option} must be an integer or 'all', got {text!r}") from None


def _json(text, option):
    if text is None:
        return None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise SetupError(f"{option} is not valid JSON: {exc}") from None
