"""The paper grid (reference.md section 9): 4 friction x 4 resolution x 3 perturbation
levels x one trial per joint, run in parallel, resumable, failures reported.

The joints of a grid (``dofs``) are 1-based joints (decomposition trials, one joint
perturbed) and/or ``"all"`` (None): every joint perturbed at once by independent
perturbations, the trials of the MIMO baselines, named ``..._dofall``.

Seeds: the perturbation of a trial depends only on its perturbation level P and joint k,
``seed = base_seed + 10 * P + k`` with k = 0 for the all-joints trial, so the 16
friction/resolution conditions at one level and joint see the same tau_delta and differ
only by the factor. The all-joints trial draws every column from its own seed: its
perturbations are independent of each other and of the decomposition trials'.
"""

from __future__ import annotations

import glob
import json
import time
import traceback
from concurrent.futures import as_completed
from pathlib import Path

from tqdm import tqdm

from trialformat import atomic_write, trial_exists, write_trial

from .errors import SetupError

GRID_FORMAT = "arm-impedance-grid/1"
SEED_RULE = ("seed = base_seed + 10 * perturbation_level + k, k = perturbed_dof "
             "(0 for all joints)")
ALL_JOINTS = "all"
MANIFEST = "grid.json"
FAILURES = "failures.json"


def trial_name(friction_level, resolution_level, perturbation_level, dof) -> str:
    """``fric{F}_res{R}_pert{P}_dof{k}``, or ``..._dofall`` for all joints (dof None/"all")."""
    k = ALL_JOINTS if parse_dof(dof) is None else dof
    return f"fric{friction_level}_res{resolution_level}_pert{perturbation_level}_dof{k}"


def parse_dof(dof):
    """A grid joint: a 1-based int, or None for all joints (given as None or ``"all"``)."""
    if dof is None or (isinstance(dof, str) and dof.strip().lower() == ALL_JOINTS):
        return None
    try:
        k = int(dof)
    except (TypeError, ValueError):
        raise SetupError(f"dof must be a 1-based joint or 'all', got {dof!r}") from None
    if k < 1 or k != float(dof):
        raise SetupError(f"dof must be a 1-based joint or 'all', got {dof!r}")
    return k


def grid_seed(base_seed, perturbation_level, dof) -> int:
    """The perturbation seed of a grid trial (:data:`SEED_RULE`)."""
    k = parse_dof(dof)
    return int(base_seed) + 10 * int(perturbation_level) + (0 if k is None else k)


def grid_tasks(*, friction_levels=(0, 1, 2, 3), resolution_levels=(0, 1, 2, 3),
               perturbation_levels=(1, 2, 3), dofs=(1, 2), duration_s=50.0, base_seed=0,
               tuning="reference", effects=None, fmu_path=None, arm="2dof",
               plant_parameters=None) -> list:
    """The grid's trials as plain dicts (picklable task descriptions).

    ``dofs`` holds 1-based joints and/or ``"all"`` (or None): all joints perturbed at once.
    ``arm``: the reference configuration, ``"2dof"`` (reference.md) or ``"3dof"``
    (reference-3dof.md; joints 1-3). ``plant_parameters``: plant parameters or inputs
    outside the contract (name -> value) set in every trial.
    """
    from .setup import REFERENCE_ARMS

    if arm not in REFERENCE_ARMS:
        raise SetupError(f"arm must be one of {sorted(REFERENCE_ARMS)}, got {arm!r}")
    joints = [parse_dof(k) for k in dofs]
    if len(set(joints)) != len(joints):
        raise SetupError(f"dofs lists a joint twice: {list(dofs)!r}")
    bad = [k for k in joints if k is not None and k > REFERENCE_ARMS[arm]]
    if bad:
        raise SetupError(f"dofs {bad} beyond the {REFERENCE_ARMS[arm]} joints of arm {arm!r}")
    for what, levels in (("friction levels", friction_levels),
                         ("resolution levels", resolution_levels),
                         ("perturbation levels", perturbation_levels)):
        names = [str(v) for v in levels]
        if len(set(names)) != len(names):  # one name, one output (issue 22)
            raise SetupError(f"{what} list a level twice: {list(levels)!r}; each trial "
                             f"name (fric{{F}}_res{{R}}_pert{{P}}_dof{{k}}) is written once")
    tasks = []
    for f in friction_levels:
        for r in resolution_levels:
            for p in perturbation_levels:
                for k in joints:
                    tasks.append({"name": trial_name(f, r, p, k), "friction_level": f,
                                  "resolution_level": r, "perturbation_level": p,
                                  "perturbed_dof": k, "seed": grid_seed(base_seed, p, k),
                                  "duration_s": duration_s, "tuning": tuning,
                                  "effects": effects, "arm": arm,
                                  "plant_parameters": dict(plant_parameters or {}) or None,
                                  "fmu_path": None if fmu_path is None else str(fmu_path)})
    return tasks


def run_grid_task(task: dict, out_dir: str) -> dict:
    """Simulate and write one grid trial; never raises (a failure is returned)."""
    from .setup import Setup
    from .trial import simulate_trial

    start = time.perf_counter()
    result = {k: v for k, v in task.items() if k != "fmu_path"}
    try:
        setup = Setup.reference(task["friction_level"], task["resolution_level"],
                                task["tuning"], task.get("arm", "2dof"))
        trial = simulate_trial(setup, perturbed_dof=task["perturbed_dof"],
                               level=task["perturbation_level"], seed=task["seed"],
                               duration_s=task["duration_s"], effects=task["effects"],
                               plant=task["fmu_path"], name=task["name"],
                               parameters=task.get("plant_parameters"))
        write_trial(Path(out_dir) / task["name"], trial)
        result["status"] = "done"
    except Exception as exc:  # one failed trial must not stop the grid
        result.update(status="failed", error=f"{type(exc).__name__}: {exc}",
                      traceback=traceback.format_exc(limit=4))
    result["wall_s"] = round(time.perf_counter() - start, 3)
    return result


def run_grid(out_dir, *, workers=2, scheduler=None, progress=True, **grid_options) -> dict:
    """Run the paper grid into ``out_dir``; skip trials already written.

    Parameters
    ----------
    out_dir : path
        Folder for the trials (``fric{F}_res{R}_pert{P}_dof{k}.csv/.json``, ``k`` a joint
        or ``all``), the manifest
        ``grid.json`` and ``failures.json``.
    workers : int
        Local processes (1: run in this process). Ignored with ``scheduler``.
    scheduler : str, optional
        Address of a Dask distributed scheduler (e.g. ``tcp://127.0.0.1:8786``), or a
        ``distributed.Client``.
    progress : bool
        Show a tqdm progress bar.
    **grid_options
        Passed to :func:`grid_tasks` (levels, dofs, duration_s, base_seed, tuning,
        effects, fmu_path).

    Returns
    -------
    dict
        The manifest: every trial's condition, seed, status (done, skipped, failed) and
        wall time; failures also in ``failures.json``.
    """
    out = Path(out_dir)
    tasks = grid_tasks(**grid_options)
    check_fmu(grid_options.get("fmu_path"))
    options = _manifest_options(grid_options)
    check_resume(out, options)  # before any trial is skipped as "already there"
    check_grid_out(out, tasks)
    out.mkdir(parents=True, exist_ok=True)
    if not (out / MANIFEST).is_file():  # a killed run still says what it was made with
        _write_json(out / MANIFEST, {"format": GRID_FORMAT, "status": "running",
                                     "options": options})
    if grid_options.get("fmu_path") is None:
        from .setup import REFERENCE_ARMS
        from .trial import default_fmu_path
        # build once here, not in every worker
        path = str(default_fmu_path(REFERENCE_ARMS[grid_options.get("arm", "2dof")]))
        for t in tasks:
            t["fmu_path"] = path
    results = {}
    todo = []
    for t in tasks:
        if trial_exists(out / t["name"]):
            results[t["name"]] = {**{k: v for k, v in t.items() if k != "fmu_path"},
                                  "status": "skipped"}
        else:
            todo.append(t)
    start = time.perf_counter()
    bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), desc="grid", unit="trial",
               disable=None if progress else True)
    fresh = scheduler is None and bool(todo) and _once_per_process(todo[0]["fmu_path"])
    runs = _execute(todo, str(out), workers, scheduler, fresh_worker=fresh)
    interrupted = False
    try:
        for res in runs:
            results[res["name"]] = res
            bar.update(1)
            if res["status"] == "failed":
                bar.write(f"FAILED {res['name']}: {res['error']}")
    except KeyboardInterrupt:
        interrupted = True  # Ctrl-C: the pool is stopped, the manifest says what finished
    finally:
        runs.close()  # stops the workers when the loop was left early
        bar.close()
    for t in todo:
        if t["name"] not in results:
            results[t["name"]] = _unreported(out, t)
    manifest = _manifest(tasks, results, options, time.perf_counter() - start)
    _write_json(out / MANIFEST, manifest)
    _write_json(out / FAILURES, {"failures": [r for r in manifest["trials"]
                                              if r["status"] == "failed"]})
    if interrupted:
        raise KeyboardInterrupt(f"{manifest['n_done']} trial(s) done, "
                                f"{manifest['n_interrupted']} not run; manifest "
                                f"{out / MANIFEST}")
    return manifest


def _unreported(out: Path, task: dict) -> dict:
    """The manifest entry of a trial whose result never reached this process (Ctrl-C).

    A worker ignores SIGINT, so it may finish writing its trial between the Ctrl-C and its
    termination: a trial whose both files are there (the JSON is written last) is done;
    anything else of it is removed, so that "interrupted" always means "absent"."""
    entry = {k: v for k, v in task.items() if k != "fmu_path"}
    if trial_exists(out / task["name"]):
        return {**entry, "status": "done", "note": "finished as the run was interrupted"}
    _remove_partial(out, task["name"])
    return {**entry, "status": "interrupted"}


def _remove_partial(out: Path, name: str) -> None:
    """Remove what a stopped worker left of a trial: the temporary files of the atomic
    writes (``.NAME.csv.*.tmp``, ``.NAME.json.*.tmp``) and a CSV without its JSON."""
    partial = list(out.glob(f".{glob.escape(name)}.*.tmp"))
    partial += [out / f"{name}{ending}" for ending in (".csv", ".csv.gz")]
    for path in partial:
        try:
            path.unlink()
        except OSError:
            pass


def _once_per_process(fmu_path) -> bool:
    """True when the plant declares canBeInstantiatedOnlyOncePerProcess (each trial then
    runs in a fresh worker process); False when it cannot be read (the trials report why)."""
    try:
        from .plant import read_model_description

        md = read_model_description(Path(fmu_path))
        return bool(getattr(md.coSimulation, "canBeInstantiatedOnlyOncePerProcess", False))
    except Exception:
        return False


def _execute(tasks, out_dir, workers, scheduler, fresh_worker=False):
    if not tasks:
        return
    if scheduler is not None:
        yield from _execute_dask(tasks, out_dir, scheduler)
    elif workers is None or workers < 1:
        raise SetupError(f"workers must be >= 1, got {workers!r}")
    elif workers == 1 and not fresh_worker:
        for t in tasks:
            yield run_grid_task(t, out_dir)
    else:
        from trialformat.processes import process_pool

        # spawn: workers start clean (no inherited FMU instances or threads); they die with
        # this process, and Ctrl-C or closing this generator stops them at once; a plant
        # that can be instantiated only once per process gets a fresh worker per trial
        with process_pool(workers, max_tasks_per_child=1 if fresh_worker else None) as ex:
            futures = [ex.submit(run_grid_task, t, out_dir) for t in tasks]
            for fut in as_completed(futures):
                yield fut.result()


def _execute_dask(tasks, out_dir, scheduler):
    from distributed import Client, as_completed as dask_completed

    client = scheduler if isinstance(scheduler, Client) else Client(scheduler)
    try:
        futures = [client.submit(run_grid_task, t, out_dir, pure=False, key=f"grid-{t['name']}")
                   for t in tasks]
        for fut in dask_completed(futures):
            yield fut.result()
    finally:
        if client is not scheduler:
            client.close()


#: Options that decide a trial's content, with their defaults (grid_tasks) and the CLI
#: option: a resumed grid must agree on them, or its skipped trials would be another run's.
RESUME_CHECKED = {"duration_s": (50.0, "--duration"), "base_seed": (0, "--seed"),
                  "tuning": ("reference", "--tuning"), "effects": (None, "--effects"),
                  "arm": ("2dof", "--arm"), "fmu": (None, "--fmu"),
                  "plant_parameters": (None, "--plant-parameter")}
#: The plant's identity, checked besides :data:`RESUME_CHECKED`: the built-in plant kind
#: (``plant``: c or modelica, when no --fmu; runs recorded before it ran the C plant) and the
#: given FMU's content (``fmu_sha256``; compared when both runs recorded it).
PLANT_CHECKED = {"plant": "--plant", "fmu_sha256": "--fmu"}


def check_fmu(fmu_path) -> None:
    """Refuse up front a plant FMU that is not there or not a zip archive (otherwise every
    trial of a grid would fail on it in turn)."""
    if fmu_path is None:
        return
    import zipfile
    path = Path(fmu_path)
    if not path.is_file():
        raise SetupError(f"--fmu {path}: no such file (give a plant .fmu; without --fmu "
                         f"the reference plant is used)")
    if not zipfile.is_zipfile(path):
        raise SetupError(f"--fmu {path}: not an FMU (an FMU is a zip archive)")


def check_grid_out(out, tasks) -> None:
    """Refuse a grid folder that is a file, lies below a file, or holds trials of the
    grid's names (or a ``failures.json``) without the manifest ``grid.json`` of a grid run:
    those files are not this project's, and would be skipped as done or replaced.

    Raises
    ------
    trialformat.errors.OutputError
    """
    from trialformat import OutputError, check_out_parent

    out = Path(out)
    check_out_parent(out, "grid OUT")
    if out.exists() and not out.is_dir():
        raise OutputError(f"grid OUT {out}: is an existing file; the grid is a folder: give "
                          f"a new folder name")
    if not out.is_dir() or (out / MANIFEST).is_file():
        return
    clash = [out / FAILURES] if (out / FAILURES).exists() else []
    clash += [out / t["name"] for t in tasks if trial_exists(out / t["name"])]
    if clash:
        raise OutputError(f"grid OUT {out}: holds {clash[0].name}{'' if clash[0].suffix else '.csv/.json'}"
                          f" but no {MANIFEST} of a grid run; it is left as it is (its "
                          f"trials would be counted as done): give a new or empty folder")


def check_resume(out, options: dict) -> None:
    """Refuse to resume the grid in ``out`` with options (:data:`RESUME_CHECKED`) other
    than those its ``grid.json`` records, naming each option and both values.

    Raises
    ------
    SetupError
        ``out/grid.json`` records other options, or is not a grid manifest.
    """
    path = Path(out) / MANIFEST
    if not path.is_file():
        return
    try:
        previous = json.loads(path.read_text(encoding="utf-8"))["options"]
        if not isinstance(previous, dict):
            raise TypeError("options is not an object")
    except (ValueError, KeyError, TypeError) as exc:
        raise SetupError(f"{path}: not a grid manifest ({exc}); remove it or use another "
                         f"output folder") from None

    def norm(value):
        return json.dumps(value, sort_keys=True)

    def value(doc, k, d):
        v = doc.get(k, d)
        return None if k == "plant_parameters" and not v else v  # {} is none given

    diff = [f"{flag} {value(previous, k, d)!r} there, {value(options, k, d)!r} now"
            for k, (d, flag) in RESUME_CHECKED.items()
            if norm(value(previous, k, d)) != norm(value(options, k, d))]
    if previous.get("fmu") is None and options.get("fmu") is None:
        was, now = previous.get("plant", "c"), options.get("plant", "c")
        if was != now:
            diff.append(f"--plant {was!r} there, {now!r} now (the built-in plant)")
    was, now = previous.get("fmu_sha256"), options.get("fmu_sha256")
    if was and now and was != now:
        diff.append(f"--fmu {options.get('fmu')!r} has other content than the FMU of that "
                    f"run (sha256 {was[:12]}... there, {now[:12]}... now)")
    if diff:
        raise SetupError(f"{out} holds a grid made with other options ({'; '.join(diff)}): "
                         f"its trials would be skipped as done; use another output folder, "
                         f"or the options of that run")


def _manifest_options(grid_options) -> dict:
    options = {k: (list(v) if isinstance(v, tuple) else v) for k, v in grid_options.items()
               if k != "fmu_path"}
    if "dofs" in options:
        options["dofs"] = [ALL_JOINTS if parse_dof(k) is None else k for k in options["dofs"]]
    if options.get("plant_parameters"):
        options["plant_parameters"] = dict(sorted(dict(options["plant_parameters"]).items()))
    else:
        options.pop("plant_parameters", None)
    if grid_options.get("fmu_path") is not None:
        options["fmu"] = Path(grid_options["fmu_path"]).name
        options["fmu_sha256"] = _sha256(grid_options["fmu_path"])
    else:
        from .trial import plant_kind
        options["plant"] = plant_kind()
    return options


def _sha256(path) -> str | None:
    """The SHA-256 of a file (the identity of a plant FMU), None when it cannot be read."""
    import hashlib

    digest = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    except OSError:
        return None
    return digest.hexdigest()


def _manifest(tasks, results, options, wall_s) -> dict:
    trials = [results[t["name"]] for t in tasks]
    return {"format": GRID_FORMAT,
            "seeds": SEED_RULE,
            "options": options, "n_trials": len(trials),
            "n_done": sum(r["status"] == "done" for r in trials),
            "n_skipped": sum(r["status"] == "skipped" for r in trials),
            "n_failed": sum(r["status"] == "failed" for r in trials),
            "n_interrupted": sum(r["status"] == "interrupted" for r in trials),
            "wall_s": round(wall_s, 3), "trials": trials}


def _write_json(path: Path, data) -> None:
    # atomic, and with the user's umask (a bare mkstemp file would stay 0600)
    atomic_write(path, lambda fh: fh.write(json.dumps(data, indent=2).encode("utf-8")))
