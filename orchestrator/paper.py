"""The paper's study from one call: the grid of trials, then the estimation report.

``run_paper(out)`` simulates into ``out/trials`` the decomposition grid (4 friction x 4
resolution x 3 perturbation levels x joints 1 and 2 = 96 trials) and, for the MIMO
baselines, one all-joints trial per condition (48), then writes the estimation report
(Figs. 2-4, tables against Table I, every estimator variant side by side) into
``out/report`` and ``out/paper.json`` (options, counts, worst-case summary, wall times).

Re-running resumes: trials already written are skipped and the report is rebuilt. A
folder holding a run made with other options is refused, so that one report never mixes
trials of two set-ups.

``quick=True`` is a small built-in default that runs in about a minute: the four corner
conditions (friction and resolution levels 0 and 3) at perturbation level 3, 20 s trials
(12 trials).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from .errors import SetupError
from .grid import ALL_JOINTS, _manifest_options, _write_json, check_resume, run_grid

PAPER_FORMAT = "arm-impedance-paper/1"
PAPER_FILE = "paper.json"
TRIALS_DIR = "trials"
REPORT_DIR = "report"
#: Decomposition trials of joints 1 and 2, plus the all-joints trial (MIMO baselines).
PAPER_DOFS = (1, 2, ALL_JOINTS)
FULL_PLAN = {"friction_levels": [0, 1, 2, 3], "resolution_levels": [0, 1, 2, 3],
             "perturbation_levels": [1, 2, 3], "duration_s": 50.0}
QUICK_PLAN = {"friction_levels": [0, 3], "resolution_levels": [0, 3],
              "perturbation_levels": [3], "duration_s": 20.0}
#: Options that must match between a run and the trials already in its folder.
_CHECKED = ("friction_levels", "resolution_levels", "perturbation_levels", "dofs",
            "duration_s", "base_seed", "tuning", "fmu", "arm", "plant")
#: Truth of the report per reference arm (estimation.report.make_report).
_TRUTH = {"2dof": "table1", "3dof": "reference-3dof"}


def paper_plan(*, quick=False, tuning="reference", duration_s=None, base_seed=0,
               friction_levels=None, resolution_levels=None,
               perturbation_levels=None, arm="2dof") -> dict:
    """The grid options of a paper run (:func:`orchestrator.grid.run_grid` keywords).

    Parameters
    ----------
    quick : bool
        The quick default (:data:`QUICK_PLAN`) instead of the paper's grid (:data:`FULL_PLAN`).
    tuning : {"reference", "robust"}
        Controller tuning of every trial.
    duration_s : float [s], optional
        Trial length; default 50 s (20 s with ``quick``).
    base_seed : int
        Base of the seed rule (``orchestrator.grid.SEED_RULE``).
    friction_levels, resolution_levels, perturbation_levels : list of int, optional
        Override the plan's levels (e.g. one condition for a test).
    arm : {"2dof", "3dof"}
        The reference configuration: the paper's two joints, or shoulder-elbow-wrist
        (reference-3dof.md: decomposition trials of joints 1, 2 and 3).
    """
    from .setup import REFERENCE_ARMS

    if arm not in REFERENCE_ARMS:
        raise SetupError(f"arm must be one of {sorted(REFERENCE_ARMS)}, got {arm!r}")
    plan = dict(QUICK_PLAN if quick else FULL_PLAN)
    for key, value in (("friction_levels", friction_levels),
                       ("resolution_levels", resolution_levels),
                       ("perturbation_levels", perturbation_levels)):
        if value is not None:
            plan[key] = [int(v) for v in value]
    if duration_s is not None:
        plan["duration_s"] = float(duration_s)
    if not plan["duration_s"] > 0:
        raise SetupError(f"duration_s must be positive, got {plan['duration_s']!r}")
    if tuning not in ("reference", "robust"):
        raise SetupError(f"tuning must be 'reference' or 'robust', got {tuning!r}")
    dofs = list(range(1, REFERENCE_ARMS[arm] + 1)) + [ALL_JOINTS]
    plan.update(dofs=dofs, base_seed=int(base_seed), tuning=tuning, arm=arm)
    return plan


def run_paper(out, *, quick=False, tuning="reference", duration_s=None, workers=2,
              scheduler=None, progress=True, fmu_path=None, base_seed=0,
              friction_levels=None, resolution_levels=None,
              perturbation_levels=None, arm="2dof") -> dict:
    """Run the paper's study into ``out``: trials, then the estimation report.

    Parameters
    ----------
    out : path
        Run folder: ``trials/`` (trials, ``grid.json``, ``failures.json``), ``report/``
        (figures and tables, estimation.report) and ``paper.json``.
    quick, tuning, duration_s, base_seed, friction_levels, resolution_levels,
    perturbation_levels, arm
        The plan, see :func:`paper_plan` (``arm="3dof"``: the three-joint study).
    workers : int
        Local processes for the trials (1: in this process).
    scheduler : str or distributed.Client, optional
        Dask scheduler address for the trials instead of local processes.
    progress : bool
        tqdm progress bars.
    fmu_path : path, optional
        Plant FMU (default: the reference C plant).

    Returns
    -------
    dict
        ``out``, ``trials_dir``, ``report_dir``, ``options``, ``grid`` (counts and
        failures), ``skipped_conditions``, ``summary`` (worst case per tuning and variant,
        estimation.report.summarize), ``files`` and ``wall_s`` (grid, report, total);
        also written to ``out/paper.json``.

    Raises
    ------
    SetupError
        ``out`` holds a run made with other options, or a bad option.
    """
    from estimation.report import make_report

    start = time.perf_counter()
    out = Path(out)
    plan = paper_plan(quick=quick, tuning=tuning, duration_s=duration_s, base_seed=base_seed,
                      friction_levels=friction_levels, resolution_levels=resolution_levels,
                      perturbation_levels=perturbation_levels, arm=arm)
    from .trial import plant_kind

    options = {**plan, "quick": bool(quick),
               "fmu": None if fmu_path is None else Path(fmu_path).name,
               # the built-in plant that runs without --fmu (c or modelica, armimp --plant)
               "plant": plant_kind() if fmu_path is None else None}
    from trialformat import check_out_parent

    check_out_parent(out, "--out")
    _check_previous(out, options)
    # the trials' own record too (the FMU's content, a manifest older than paper.json's
    # plant key), before paper.json is rewritten
    check_resume(out / TRIALS_DIR, _manifest_options({**plan, "fmu_path": fmu_path}))
    out.mkdir(parents=True, exist_ok=True)
    _write_json(out / PAPER_FILE, {"format": PAPER_FORMAT, "status": "running",
                                   "options": options})
    trials_dir, report_dir = out / TRIALS_DIR, out / REPORT_DIR
    manifest = run_grid(trials_dir, workers=workers, scheduler=scheduler, progress=progress,
                        fmu_path=fmu_path, **plan)
    grid_s = time.perf_counter() - start
    report = make_report(trials_dir, report_dir, truth=_TRUTH[arm], progress=progress,
                         workers=workers if scheduler is None else 2)
    result = {
        "format": PAPER_FORMAT, "status": "done", "out": str(out),
        "trials_dir": str(trials_dir), "report_dir": str(report_dir), "options": options,
        "grid": {k: manifest[k] for k in ("n_trials", "n_done", "n_skipped", "n_failed")}
        | {"failures": [{"name": r["name"], "error": r["error"]}
                        for r in manifest["trials"] if r["status"] == "failed"]},
        "skipped_conditions": report["skipped"], "summary": report["summary"],
        "acceptance": acceptance(report["rows"], arm),
        "files": report["files"],
        "wall_s": {"grid": round(grid_s, 2),
                   "report": round(time.perf_counter() - start - grid_s, 2),
                   "total": round(time.perf_counter() - start, 2)}}
    _write_json(out / PAPER_FILE, result)
    return result


#: Targets of the three-joint study (issue 10): VAF [%] at least, M, B, K errors [%] at most.
TARGETS = {"vaf_min": 99.5, "M": 2.0, "B": 3.0, "K": 2.0}


def normalized_errors(row: dict, truth) -> dict:
    """Largest |error| [%] of the fitted M, B, K of one scored row over every element:
    diagonal elements relative to themselves, off-diagonal ones relative to
    sqrt(X_ii X_kk) (the wrist couplings are small, reference-3dof.md).

    Parameters
    ----------
    row : dict
        A row of estimation.report.make_report (``M_ik``... fitted values).
    truth : (M, B, K) ndarrays (n, n)
    """
    out = {}
    for p, X in zip("MBK", truth):
        n = len(X)
        d = np.sqrt(np.abs(np.outer(np.diag(X), np.diag(X))))
        err = [abs(row[f"{p}_{i + 1}{k + 1}"] - X[i, k]) / d[i, k] * 100
               for i in range(n) for k in range(n)]
        out[p] = float(max(err))
    return out


def acceptance(rows, arm="2dof") -> list[dict]:
    """Worst case per tuning and variant against :data:`TARGETS`, with the normalised
    errors of :func:`normalized_errors`: ``vaf_min``, ``err_M_max``..., ``worst`` (the
    condition of each worst case) and ``meets`` (every target met in every condition)."""
    from trialformat import reference as ref

    truth = ref.arm_matrices(arm)
    out = {}
    for r in rows:
        key = (r["tuning"], r["variant"])
        cond = f"F{r['friction']}R{r['resolution']}P{r['perturbation']}"
        e = normalized_errors(r, truth)
        a = out.setdefault(key, {"tuning": key[0], "variant": key[1], "n_conditions": 0,
                                 "vaf_min": np.inf, "err_M_max": 0.0, "err_B_max": 0.0,
                                 "err_K_max": 0.0, "worst": {}})
        a["n_conditions"] += 1
        if r["vaf_min"] < a["vaf_min"]:
            a["vaf_min"], a["worst"]["vaf"] = r["vaf_min"], cond
        for p in "MBK":
            if e[p] > a[f"err_{p}_max"]:
                a[f"err_{p}_max"], a["worst"][p] = e[p], cond
    for a in out.values():
        a["meets"] = bool(a["vaf_min"] >= TARGETS["vaf_min"]
                          and all(a[f"err_{p}_max"] <= TARGETS[p] for p in "MBK"))
    return list(out.values())


def _check_previous(out: Path, options: dict) -> None:
    path = out / PAPER_FILE
    if not path.is_file():
        return
    try:
        previous = json.loads(path.read_text())["options"]
    except (ValueError, KeyError, TypeError) as exc:
        raise SetupError(f"{path}: not a paper run record ({exc}); remove it or use another "
                         f"--out") from None
    previous.setdefault("arm", "2dof")  # runs made before the option existed
    previous.setdefault("plant", "c" if previous.get("fmu") is None else None)
    diff = [f"{k}: {previous.get(k)!r} there, {options.get(k)!r} now" for k in _CHECKED
            if previous.get(k) != options.get(k)]
    if diff:
        raise SetupError(f"{out} holds a paper run with other options ({'; '.join(diff)}); "
                         f"use another --out, or remove that folder")


def _worst_text(worst) -> str:
    """``{'vaf': 'F0R3P3', 'M': 'F0R3P3'}`` as ``VAF F0R3P3, M F0R3P3`` (friction,
    resolution and perturbation levels of the worst condition of each measure)."""
    if not isinstance(worst, dict):
        return str(worst)
    return ", ".join(f"{'VAF' if k == 'vaf' else k} {v}" for k, v in worst.items())


def summary_lines(result, variants=None) -> list[str]:
    """A short text summary of a :func:`run_paper` result: counts, worst cases, paths.

    ``variants``: the variants to show (default: the paper's plain T/R and the recommended
    bias-removing estimator).
    """
    from estimation.conditions import PAPER, RECOMMENDED, VARIANT_LABELS
    from estimation.report import TRUTH_LABELS

    variants = variants or (PAPER, RECOMMENDED)
    g = result["grid"]
    lines = [f"trials: {g['n_trials']} ({g['n_done']} simulated, {g['n_skipped']} already "
             f"there, {g['n_failed']} failed) in {result['wall_s']['grid']:.1f} s; report "
             f"in {result['wall_s']['report']:.1f} s; total {result['wall_s']['total']:.1f} s"]
    lines += [f"  FAILED {f['name']}: {f['error']}" for f in g["failures"]]
    lines += [f"  not estimated: {s['condition']} ({s['tuning']}) {s['method']}: {s['reason']}"
              for s in result["skipped_conditions"]]
    truth = TRUTH_LABELS[_TRUTH[result.get("options", {}).get("arm", "2dof")]]
    lines.append(f"worst case over conditions and elements (VAF, R^2: minimum; M, B, K: "
                 f"largest |error| vs {truth}, each element relative to its own true "
                 f"value X_ik):")
    for row in result["summary"]:
        if row["variant"] in variants:
            lines.append(
                f"  {row['tuning']:9s} {row['variant']:15s} VAF {row['vaf_min']:7.3f} %  "
                f"R^2 {row['r2_min']:.5f}  M {row['err_M_max']:5.2f} %  "
                f"B {row['err_B_max']:5.2f} %  K {row['err_K_max']:5.2f} %  "
                f"({VARIANT_LABELS.get(row['variant'], '')}, {row['n_conditions']} conditions)")
    if result.get("acceptance"):
        lines.append(f"targets (VAF >= {TARGETS['vaf_min']} %, M/B/K within {TARGETS['M']}/"
                     f"{TARGETS['B']}/{TARGETS['K']} % vs {truth}; off-diagonal errors "
                     f"relative to sqrt(X_ii X_kk), hence smaller than above):")
        for a in result["acceptance"]:
            if a["variant"] in variants or a["variant"].startswith("closed_loop_corrected"):
                lines.append(
                    f"  {a['tuning']:9s} {a['variant']:22s} VAF {a['vaf_min']:7.3f} %  "
                    f"M {a['err_M_max']:5.2f} %  B {a['err_B_max']:5.2f} %  "
                    f"K {a['err_K_max']:5.2f} %  {'met' if a['meets'] else 'NOT met'} "
                    f"(worst conditions FfRrPp: {_worst_text(a['worst'])})")
    lines.append(f"report: {result['report_dir']} (table_summary.md: every estimator, MIMO "
                 f"baselines included)")
    return lines
