"""The paper's figures and tables from a folder of trials (a grid run).

``make_report(folder, out)`` reads every trial, groups them into conditions by their
metadata, scores each condition (:func:`estimation.conditions.evaluate`) and writes:

- ``fig2_impedance.png``: true vs estimated Z (magnitude, unwrapped phase, relative error
  per element; one column per element for 2 joints, an n x n grid of elements for n >= 3)
  for the corner conditions (friction, resolution) in {0, 3}^2 at the
  highest perturbation level, the recommended variant beside the paper's T/R;
- ``fig3_accuracy.png``: VAF and R^2 of every element over all conditions (main variant;
  ``fig3_accuracy_{compare}.png`` for the compared one, by default the paper's);
- ``fig4_coherence.png``: band-mean derived coherence over all conditions (likewise);
- ``table_conditions.csv`` (every figure, per element) and ``table_conditions.md``
  (summaries), ``table_parameters.csv``/``.md`` (fitted M, B, K against the truth, mean
  and worst case over conditions), ``table_summary.csv``/``.md`` (worst case per variant,
  MIMO baselines included), ``report.json``.
The report is built in a temporary folder and renamed into place (a failure leaves no
partial report); conditions are scored in ``workers`` processes.
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import multiprocessing
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

import trialformat as tf  # noqa: E402
from trialformat import reference as ref  # noqa: E402
from trialformat.logs import current_umask, replace_dir  # noqa: E402
from trialformat.processes import new_pool, stop_pool  # noqa: E402
from trialformat.tempdirs import disown_temp_dir, own_temp_dir  # noqa: E402

from .accuracy import true_impedance  # noqa: E402
from .conditions import (PAPER, RECOMMENDED, VARIANT_LABELS, VARIANTS, condition_of,  # noqa: E402
                         evaluate,  # noqa: E402
                         group_conditions, variant_impedance, variant_spec)
from .errors import EstimationError  # noqa: E402
from .lab import element_names  # noqa: E402

ELEMENTS = ("11", "12", "21", "22")  # of a 2-joint report; see _elements(rows)


def _elements(rows) -> list:
    """Element names of the rows' joint count (``vaf_ik`` keys)."""
    n = max((int(k[4]) for r in rows for k in r if k.startswith("vaf_") and len(k) == 6),
            default=2)
    return element_names(n)


#: Truth of a report by name: Table I (reference.md) or reference-3dof.md's arm.
_TRUTH_ARMS = {"table1": "2dof", "reference-3dof": "3dof"}
#: How figures and tables name each truth.
TRUTH_LABELS = {"table1": "Table I", "reference-3dof": "the 3-joint reference (reference-3dof)"}


def trial_paths(sources) -> list[Path]:
    """Trial files of folders, files (``NAME.csv``/``.json``/``.mat``) or stems (``NAME``).

    A stem is taken the way ``trialformat.read_trial`` takes it, so ``armimp figures`` and
    ``armimp estimate`` accept the same arguments. Raises EstimationError naming the
    sources when none holds a trial.
    """
    paths = []
    for source in map(Path, sources):
        if source.is_dir():
            paths += tf.logs.folder_trials(source)
        elif source.name.lower().endswith((".csv", ".csv.gz", ".mat")) and source.is_file():
            paths.append(source)
        else:
            stem = tf.trial_stem(source)
            found = [q for q in (tf.logs.with_ending(stem, e) for e in (".csv", ".csv.gz", ".mat"))
                     if q.is_file()]
            if len(found) > 1:
                raise EstimationError(f"{source}: trial present as "
                                      f"{', '.join(q.name for q in found)}; name one file")
            paths += found
    if not paths:
        raise EstimationError(f"no trial (a folder of NAME.csv or NAME.mat, such a file, or "
                              f"its stem NAME) in {[str(s) for s in sources]}")
    return paths


def make_report(folders, out, *, truth="table1", variant=RECOMMENDED, compare=PAPER,
                progress=True, workers=2) -> dict:
    """Score every condition of the trials in ``folders`` and write figures and tables.

    Parameters
    ----------
    folders : path or list of paths
        Trials (``.csv``+``.json`` or ``.mat``), e.g. a grid run and a folder of
        all-joints trials for the MIMO baselines; grouped by metadata, not by folder.
    out : path
        Report folder (created).
    truth : {"table1", "reference-3dof", "none"}
        Compare with Table I (simulated trials), or, for lab data, with each estimate's
        own second-order fit.
    variant : str
        Main variant (estimation.conditions.VARIANTS): drawn solid in Fig. 2, and in
        ``fig3_accuracy.png`` / ``fig4_coherence.png``. Default: the recommended
        bias-removing ``full_corrected``.
    compare : str or None
        Variant drawn dashed beside it in Fig. 2 and given its own
        ``fig3_accuracy_{compare}.png`` / ``fig4_coherence_{compare}.png``. Default: the
        paper's plain T/R (``decomposition``). None: main variant only.
    workers : int
        Processes scoring the conditions (1: in this process).

    Returns
    -------
    dict with ``rows`` (one per condition and variant), ``summary`` (worst case per tuning
    and variant, :func:`summarize`), ``skipped`` (condition and method pairs that could
    not be estimated, e.g. a trial missing, with the reason) and the output ``files``.
    """
    variants = [variant] + ([compare] if compare and compare != variant else [])
    for name in variants:
        variant_spec(name)  # unknown names fail before any work
    out = Path(out)
    arm = ref.arm_matrices(_TRUTH_ARMS[truth]) if truth in _TRUTH_ARMS else None
    folders = [folders] if isinstance(folders, (str, os.PathLike)) else list(folders)
    tf.logs.check_report_out(out, folders, kinds=("lab", "paper"))  # never over an input
    paths = trial_paths(folders)
    tasks = _condition_tasks(paths, arm, variants)
    pool = _pool(workers, len(tasks))
    try:
        results = _run_tasks(tasks, pool, progress)
        groups = {task["condition"]: task["names"] for task in tasks}
        rows, skipped, curves = [], [], {}
        for res in results:
            rows += res["rows"]
            skipped += res["skipped"]
            if res["curves"]:
                curves[res["condition"]] = res["curves"]
        if not rows:
            reasons = sorted({f"{k['condition']}: {k['reason']}" for k in skipped})
            raise EstimationError("no condition could be estimated: " + "; ".join(reasons))
        figures = [("fig2_impedance.png", "fig2",
                    (curves, arm, variants, TRUTH_LABELS.get(truth)))]
        for name in variants:
            suffix = "" if name == variant else f"_{name}"
            figures += [(f"fig3_accuracy{suffix}.png", "fig3", (rows, name)),
                        (f"fig4_coherence{suffix}.png", "fig4", (rows, name))]
        pngs = [pool.submit(render_png, kind, args) if pool else render_png(kind, args)
                for _, kind, args in figures]
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = own_temp_dir(f".{out.name}.tmp", out.parent)  # a killed run's: removed next run
        try:
            files = _write_report(tmp, rows, skipped, arm, folders, truth, variant, compare,
                                  paths, groups)
            for (name, *_), png in zip(figures, pngs):
                files.append(_atomic_bytes(tmp / name, png.result() if pool else png))
            os.chmod(tmp, 0o777 & ~current_umask())
            replace_dir(tmp, out, kind="paper")
            disown_temp_dir(tmp)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    except BaseException:
        if pool:
            stop_pool(pool)  # an error or Ctrl-C: pending work cancelled, workers ended
            pool = None
        raise
    finally:
        if pool:
            pool.shutdown()
    summary = summarize(rows)
    return {"rows": rows, "summary": summary, "skipped": skipped,
            "files": [str(out / Path(f).name) for f in files]}


def _write_report(tmp, rows, skipped, arm, folders, truth, variant, compare, paths, groups):
    """The tables and report.json into ``tmp``; returns the paths."""
    summary = summarize(rows)
    files = [_write_rows(tmp / "table_conditions.csv", rows),
             _atomic_text(tmp / "table_conditions.md", conditions_markdown(rows, arm)),
             *parameter_tables(rows, arm, tmp),
             _write_rows(tmp / "table_summary.csv", summary),
             _atomic_text(tmp / "table_summary.md", summary_markdown(summary, arm,
                                                                        TRUTH_LABELS.get(truth)))]
    report = {"folders": [Path(f).name for f in folders], "truth": truth,
              "variant_in_figures": variant, "compared_variant": compare,
              "n_trials": len(paths), "n_conditions": len(groups), "skipped": skipped,
              "summary": summary, "rows": rows}
    files.append(_atomic_text(tmp / "report.json", json.dumps(report, indent=1)))
    return files


def render_png(kind, args) -> bytes:
    """One report figure as PNG bytes (run in a worker process)."""
    fig = {"fig2": fig2, "fig3": fig3, "fig4": fig4}[kind](*args)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


class _MetaOnly:
    """A trial's metadata without its samples, enough to group it (condition_of)."""

    def __init__(self, path):
        self.path = Path(path)
        self.name = tf.trial_stem(self.path).name
        if self.path.suffix.lower() == ".mat":
            self.meta = tf.read_trial(self.path, min_samples=0).meta
        else:
            json_path = tf.logs.with_ending(tf.trial_stem(self.path), ".json")
            self.meta = tf.logs._read_metadata(json_path)[0]

    @property
    def n_dof(self):
        return int(self.meta["n_dof"])


def _condition_tasks(paths, arm, variants) -> list[dict]:
    """One task per condition (grouped from the metadata alone, samples not read)."""
    by_cond = {}
    for p in paths:
        stub = _MetaOnly(p)
        by_cond.setdefault(condition_of(stub), []).append(stub)
    ordered = group_conditions([s for group in by_cond.values() for s in group])
    levels = [c.perturbation for c in ordered if isinstance(c.perturbation, int)]
    top = max(levels) if levels else None
    return [{"condition": cond, "paths": [str(s.path) for s in group],
             "names": [s.name for s in group], "arm": arm,
             "curve_variants": variants if (cond.perturbation == top and
                                            (cond.friction, cond.resolution) in CORNERS)
             else []}
            for cond, group in ordered.items()]


#: Conditions per worker below which starting processes (~2 s each) does not pay.
PROCESS_MIN_TASKS = 4


def _pool(workers, n_tasks):
    """Worker processes for the report, or None when they would not pay."""
    if workers is None or workers <= 1 or n_tasks < 2 * PROCESS_MIN_TASKS:
        return None
    # fork: no re-import per worker; the main process holds no threads or FMU here; the
    # workers ignore Ctrl-C and die with this process (trialformat.processes)
    methods = multiprocessing.get_all_start_methods()
    return new_pool(workers, context="fork" if "fork" in methods else "spawn")


def _run_tasks(tasks, pool, progress) -> list[dict]:
    bar = tqdm(total=len(tasks), desc="estimating conditions", disable=None if progress else True)
    try:
        out = []
        for res in (pool.map(score_condition, tasks) if pool else map(score_condition, tasks)):
            out.append(res)
            bar.update()
        return out
    finally:
        bar.close()


def score_condition(task) -> dict:
    """Read one condition's trials, score every method's variants, and the Fig. 2 curves."""
    cond = task["condition"]
    group = [tf.read_trial(p) for p in task["paths"]]
    rows, skipped = [], []
    methods = list(dict.fromkeys(m for _, m, *_ in VARIANTS))
    for method in methods:  # one method's missing trials must not hide the others
        try:
            scored = evaluate(group, truth=task["arm"],
                              variants=[v for v in VARIANTS if v[1] == method])
        except EstimationError as exc:  # e.g. a joint's trial failed: report, go on
            skipped.append({"condition": cond.label, "tuning": cond.tuning,
                            "method": method, "trials": [t.name for t in group],
                            "reason": str(exc)})
            continue
        for row in scored:
            rows.append({"friction": cond.friction, "resolution": cond.resolution,
                         "perturbation": cond.perturbation, "tuning": cond.tuning,
                         "n_trials": len(group), **row})
    curves = {}
    for name in task["curve_variants"]:
        try:
            curves[name] = variant_impedance(group, name)
        except EstimationError:  # trials of that kind missing: nothing to draw
            continue
    return {"condition": cond, "rows": rows, "skipped": skipped, "curves": curves}


def summarize(rows) -> list[dict]:
    """Worst case over the conditions, per tuning and variant (in VARIANTS order).

    VAF, R^2 and band-mean derived coherence: minimum over conditions and elements;
    parameter errors (when the rows have a truth): largest |relative error| [%].
    """
    order = {name: i for i, (name, *_) in enumerate(VARIANTS)}
    keys = sorted({(r["tuning"], r["variant"]) for r in rows},
                  key=lambda k: (k[0], order.get(k[1], len(order))))
    out = []
    for tuning, name in keys:
        sel = [r for r in rows if r["tuning"] == tuning and r["variant"] == name]
        line = {"tuning": tuning, "variant": name,
                "description": VARIANT_LABELS.get(name, ""), "n_conditions": len(sel),
                "vaf_min": min(r["vaf_min"] for r in sel),
                "r2_min": min(r["r2_min"] for r in sel),
                "coh_min": min(r["coh_min"] for r in sel)}
        for p in "MBK":
            if f"err_{p}_max" in sel[0]:
                line[f"err_{p}_max"] = max(r[f"err_{p}_max"] for r in sel)
        out.append(line)
    return out


def summary_markdown(summary, arm, truth_label="Table I") -> str:
    """The worst-case table of :func:`summarize`, as Markdown.

    Errors are per element, each relative to that element's own true value (an
    off-diagonal element is small, so its relative error is large); the targets of
    ``armimp paper`` normalise off-diagonal errors by sqrt(X_ii X_kk) instead."""
    cols = ["tuning", "variant", "description", "n_conditions", "vaf_min", "r2_min",
            "coh_min"] + (["err_M_max", "err_B_max", "err_K_max"] if arm else [])
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(_fmt(r.get(c)) for c in cols) + " |" for r in summary]
    legend = ("\nWorst case over the conditions and all elements: vaf_min [%], r2_min, "
              "coh_min (band-mean derived coherence) are minima; err_*_max [%] the largest "
              f"|relative error| of the fitted M, B, K against {truth_label}, each element "
              "relative to its own true value (X_ik). The targets block of `armimp paper` "
              "normalises off-diagonal errors by sqrt(X_ii X_kk) instead, so its numbers "
              "are smaller for the same estimator.\n")
    return "\n".join(lines) + "\n" + legend


# ----------------------------------------------------------------------------- tables


def conditions_markdown(rows, arm) -> str:
    """One line per condition and variant: worst element of each measure."""
    cols = ["friction", "resolution", "perturbation", "tuning", "variant", "vaf_min",
            "r2_min", "coh_min"] + (["err_M_max", "err_B_max", "err_K_max"] if arm else [])
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r.get(c)) for c in cols) + " |")
    legend = ("\nvaf_min [%], r2_min, coh_min: worst element; err_*_max [%]: largest "
              "|relative error| of the fitted parameter over all elements, each relative to "
              "its own true value.\n")
    return "\n".join(lines) + "\n" + legend


def parameter_tables(rows, arm, out) -> list:
    """Fitted M, B, K per element and variant: the true value (Table I or reference-3dof),
    mean, worst error over conditions."""
    table = []
    for name, *_ in VARIANTS:
        sel = [r for r in rows if r["variant"] == name]
        if not sel:
            continue
        for p, true in zip("MBK", arm if arm else (None,) * 3):
            for e in _elements(sel):
                vals = np.array([r[f"{p}_{e}"] for r in sel])
                line = {"variant": name, "parameter": f"{p}_{e}", "n_conditions": len(sel),
                        "fitted_mean": vals.mean(), "fitted_min": vals.min(),
                        "fitted_max": vals.max()}
                if true is not None:
                    errs = np.array([r[f"err_{p}_{e}"] for r in sel])
                    line.update(true_value=float(true[int(e[0]) - 1, int(e[1]) - 1]),
                                err_mean_pct=errs.mean(),
                                err_worst_pct=errs[np.argmax(np.abs(errs))])
                table.append(line)
    cols = list(table[0]) if table else []
    md = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    md += ["| " + " | ".join(_fmt(r.get(c)) for c in cols) + " |" for r in table]
    return [_write_rows(out / "table_parameters.csv", table),
            _atomic_text(out / "table_parameters.md", "\n".join(md) + "\n")]


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return "" if v is None else str(v)


# ----------------------------------------------------------------------------- figures


CORNERS = ((0, 0), (0, 3), (3, 0), (3, 3))
CORNER_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red")
VARIANT_STYLES = ("-", "--", "-.")
TRUTH_STYLE = {"color": "k", "ls": ":", "lw": 1.6, "zorder": 5}


def _corner_label(friction, resolution) -> str:
    return f"friction {friction}, resolution {resolution}"


def unwrapped_phase_deg(z, valid=None) -> np.ndarray:
    """Phase of ``z`` [deg] unwrapped along frequency, NaN where ``valid`` is False.

    Only the valid points are unwrapped (noise where the phase means nothing cannot add
    360 deg jumps to the rest), then shifted by a multiple of 360 deg so that the first
    valid point lies in (-180, 180]. Shape of ``z``; ``valid``: bool array of that shape.
    """
    z = np.asarray(z)
    valid = np.isfinite(z) & (np.abs(z) > 0) if valid is None else valid & np.isfinite(z)
    out = np.full(z.shape, np.nan)
    if valid.any():
        ph = np.unwrap(np.angle(z[valid]))
        ph -= 2 * np.pi * np.round((ph[0] - np.angle(z[valid][0])) / (2 * np.pi))
        out[valid] = np.degrees(ph)
    return out


def element_axes(fig, n, quantities):
    """Axes of a Bode-type figure: ``{(i, k): [axis per quantity]}`` (0-based i, k).

    n <= 2: one column per element, one row per quantity (a 2 x 2 arm: 4 columns). n >= 3:
    an n x n grid of elements (row i, column k, as in the matrix), each a block of the
    quantities stacked, so that the figure stays readable when scaled.
    """
    q = len(quantities)
    if n <= 2:
        axes = fig.subplots(q, n * n, sharex=True, squeeze=False)
        return {(i, k): list(axes[:, i * n + k]) for i in range(n) for k in range(n)}
    axes = fig.subplots(q * n, n, sharex=True, squeeze=False)
    return {(i, k): list(axes[q * i:q * (i + 1), k]) for i in range(n) for k in range(n)}


def _fig2_title(corners, arm, truth_label, top):
    pairs = [(c.friction, c.resolution) for c, _ in corners]
    if len(pairs) == len(CORNERS):
        which = "the four corner conditions"
    elif len(pairs) == 1:
        which = f"one condition ({_corner_label(*pairs[0])})"
    else:
        which = f"{len(pairs)} corner conditions"
    truth = f" vs {truth_label}" if arm is not None and truth_label else ""
    return f"Fig. 2: estimated impedance{truth}, {which} at perturbation level {top}"


#: Marker of each corner condition (with its colour), so that overlapping curves stay
#: apart in print and for colour-blind readers.
CORNER_MARKERS = ("o", "s", "^", "D")


def marker_indices(f, slot, n_slots, n_marks=9) -> np.ndarray:
    """Indices of ``f`` (increasing, > 0) at which to draw the markers of curve ``slot``
    of ``n_slots``: about ``n_marks`` points evenly spaced on a log axis, each curve's
    shifted by ``1 / n_slots`` of the spacing and taken among the bins ``slot``,
    ``slot + n_slots``, ... only, so that the markers of overlapping curves interleave
    and never share a bin."""
    f = np.asarray(f, dtype=float)
    own = np.arange(slot % n_slots, len(f), n_slots)
    if not len(own):
        return own
    lo, hi = np.log(f[0]), np.log(f[-1])
    step = (hi - lo) / n_marks
    targets = np.exp(lo + step * (np.arange(n_marks) + (slot + 0.5) / n_slots))
    near = np.abs(f[own][None, :] - targets[:, None]).argmin(axis=1)
    return np.unique(own[near])


def fig2(curves, arm, variants, truth_label="Table I"):
    """Estimated vs true Z for the corner conditions at the highest perturbation level.

    ``curves``: ``{Condition: {variant: (f_band, Z_band)}}`` (see :func:`score_condition`).
    Per element: magnitude and phase (unwrapped) of the truth (black, dotted) and of the
    main variant's estimate of each condition (colour and marker: corner condition
    (friction, resolution) in {0, 3}^2; markers interleaved, :func:`marker_indices`).
    With a truth and 1-2 joints, below them one row per condition (small multiples) of
    the relative error ``|Zhat - Z| / |Z|`` [%] of every variant (line style: variant,
    the first solid), on one shared log axis, which separates what the Bode rows cannot;
    for 3 joints (elements laid out by :func:`element_axes`) one error panel per element
    with the conditions' markers. ``truth_label`` names the truth in the title and legend.
    """
    corners = sorted(curves.items(), key=lambda cc: (cc[0].friction, cc[0].resolution))
    top = corners[0][0].perturbation if corners else None
    n = next((Z.shape[1] for _, cv in corners for _, Z in cv.values()), 2)
    multiples = arm is not None and n <= 2 and len(corners) > 1
    err_rows = len(corners) if multiples else (1 if arm is not None else 0)
    quantities = ("mag", "phase") + ("err",) * err_rows
    q = len(quantities)
    if n <= 2:
        ratios = [1.5, 1.5] + [1.0] * err_rows
        fig = plt.figure(figsize=(4 * n * n, 1.9 * sum(ratios) + 1.4))
        grid = fig.subplots(q, n * n, sharex=True, squeeze=False,
                            gridspec_kw={"height_ratios": ratios})
        axes = {(i, k): list(grid[:, i * n + k]) for i in range(n) for k in range(n)}
    else:
        fig = plt.figure(figsize=(4.4 * n, 2.3 * q * n + 1.6))
        axes = element_axes(fig, n, quantities)
    err_axes = [a for ax in axes.values() for a in ax[2:]]
    for a in err_axes[1:]:
        a.sharey(err_axes[0])
    f_band = None
    drawn = set()
    main = variants[0]
    for row, (cond, by_variant) in enumerate(corners):
        slot = CORNERS.index((cond.friction, cond.resolution))
        color, marker = CORNER_COLORS[slot], CORNER_MARKERS[slot]
        for style, name in zip(VARIANT_STYLES, variants):
            if name not in by_variant:
                continue
            f_band, Z = by_variant[name]
            drawn.add((cond.friction, cond.resolution, name))
            Zt = true_impedance(f_band, *arm) if arm is not None else None
            marks = {"marker": marker, "ms": 5, "mfc": "white", "mew": 1.2,
                     "markevery": marker_indices(f_band, slot, len(CORNERS))}
            for (i, k), ax in axes.items():
                z = Z[:, i, k]
                if name == main:
                    ax[0].loglog(f_band, np.abs(z), style, color=color, lw=1.0, **marks)
                    ax[1].semilogx(f_band, unwrapped_phase_deg(z), style, color=color,
                                   lw=1.0, **marks)
                if Zt is not None:
                    zt = Zt[:, i, k]
                    err = 100 * np.abs(z - zt) / np.abs(zt)
                    target = ax[2 + row] if multiples else ax[2]
                    target.loglog(f_band, err, style, color=color, lw=1.0,
                                  **({} if multiples else marks))
    if arm is not None and f_band is not None:
        zt = true_impedance(f_band, *arm)
        for (i, k), ax in axes.items():
            ax[0].loglog(f_band, np.abs(zt[:, i, k]), **TRUTH_STYLE)
            ax[1].semilogx(f_band, unwrapped_phase_deg(zt[:, i, k]), **TRUTH_STYLE)
    for (i, k), ax in axes.items():
        e = f"Z{i + 1}{k + 1}"
        ax[0].set_title(e, fontsize=10)
        ax[0].set_ylabel(f"|{e}| [N m/rad]")
        ax[1].set_ylabel("phase [deg]")
        for row, a in enumerate(ax[2:]):
            if multiples:
                c = corners[row][0]
                a.set_ylabel(f"error [%]\nF{c.friction}R{c.resolution}", fontsize=9)
            else:
                a.set_ylabel("error [%]")
        if n <= 2 or i == n - 1:
            ax[-1].set_xlabel("frequency [Hz]")
        for a in ax:
            a.grid(True, which="both", alpha=0.3)
    legend = _fig2_legend([(c, None) for c, _ in corners], variants, arm, drawn,
                          truth_label)
    fig.legend(handles=legend, loc="lower center", ncol=min(len(legend), 4 if n <= 2 else 3),
               fontsize=9, frameon=False)
    errs = ""
    if arm is not None:
        errs = ("\nrows 3-: error |Zhat - Z| / |Z| [%] of each condition (FfRr: friction "
                "level f, resolution level r), one axis for all" if multiples
                else "\nerror: |Zhat - Z| / |Z| [%]")
    fig.suptitle(_fig2_title(corners, arm, truth_label, top) + errs, fontsize=12)
    legend_h = 0.35 + 0.22 * np.ceil(len(legend) / (4 if n <= 2 else 3))
    fig.tight_layout(rect=(0, legend_h / fig.get_size_inches()[1], 1, 1))
    return fig


def _fig2_legend(corners, variants, arm, drawn, truth_label="Table I"):
    from matplotlib.lines import Line2D

    handles = []
    for c, _ in corners:
        slot = CORNERS.index((c.friction, c.resolution))
        handles.append(Line2D([], [], color=CORNER_COLORS[slot], marker=CORNER_MARKERS[slot],
                              mfc="white", mew=1.2,
                              label=f"F{c.friction}R{c.resolution}: "
                                    + _corner_label(c.friction, c.resolution)))
    handles += [Line2D([], [], color="k", ls=style,
                       label=f"{name}: {VARIANT_LABELS.get(name, '')}"
                       + (" (Bode rows)" if j == 0 and len(variants) > 1 else "")
                       + ("" if any(d[2] == name for d in drawn) else " (no trials)"))
                for j, (style, name) in enumerate(zip(VARIANT_STYLES, variants))]
    if arm is not None:
        handles.append(Line2D([], [], **TRUTH_STYLE, label=f"true impedance: {truth_label or 'truth'}"))
    return handles


def _by_level(rows, variant):
    sel = [r for r in rows if r["variant"] == variant]
    levels = sorted({r["perturbation"] for r in sel}, key=str)
    return sel, levels


def _condition_axis(ax, part, bottom):
    x = np.arange(len(part))
    ax.set_xticks(x, [f"F{r['friction']}R{r['resolution']}" for r in part], rotation=90,
                  fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.ticklabel_format(axis="y", useOffset=False)
    if bottom:
        ax.set_xlabel("condition: friction level F, sensor resolution level R")
    return x


#: The study's VAF target [%] (orchestrator.paper.TARGETS["vaf_min"]), drawn in Fig. 3.
VAF_TARGET = 99.5
#: Markers of the elements in Figs. 3 and 4 (up to 3 joints).
ELEMENT_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">")


def fig3(rows, variant):
    """VAF and R^2 of each element over the conditions, one row of panels per level.

    Markers without lines (the conditions are categories), the elements side by side
    within each condition; the VAF axis reaches down past the target
    (:data:`VAF_TARGET`, drawn dashed) so that the margin to it shows to scale, and the
    R^2 axis spans the same fraction (0.994-1) unless a value lies lower.
    """
    panels = (("vaf", "VAF [%]", "VAF, perturbation level {level}"),
              ("r2", "R² [-]", "R², perturbation level {level}"))
    return _level_figure(rows, variant, panels, width=13,
                         title="Fig. 3: VAF and R² of each element per condition")


def fig4(rows, variant):
    """Band-mean derived coherence of each element over the conditions (markers)."""
    panels = (("coh", "mean coherence [-]",
               "derived coherence, band mean 0-15 Hz, perturbation level {level}"),)
    return _level_figure(rows, variant, panels, width=9,
                         title="Fig. 4: band-mean derived coherence of each element per "
                               "condition")


def _scale(ax, key, values) -> None:
    """Fig. 3's y axes: the VAF axis from below the target to 100 %, R^2 alike."""
    low = float(np.nanmin(values)) if len(values) else 100.0
    if key == "vaf":
        ax.axhline(VAF_TARGET, color="tab:red", ls="--", lw=1.0,
                   label=f"target {VAF_TARGET:g} %")
        bottom = min(VAF_TARGET - 0.1, low - 0.05 * (100.0 - low))
        ax.set_ylim(bottom, 100.0 + 0.05 * (100.0 - bottom))
    elif key == "r2":
        bottom = min(1.0 - (100.0 - VAF_TARGET + 0.1) / 100.0, low - 0.05 * (1.0 - low))
        ax.set_ylim(bottom, 1.0 + 0.05 * (1.0 - bottom))


def _level_figure(rows, variant, panels, *, width, title):
    """One row per perturbation level, one panel per (row key, y label, panel title)."""
    sel, levels = _by_level(rows, variant)
    n = max(len(levels), 1)
    fig, axes = plt.subplots(n, len(panels), figsize=(width, 3.3 * n + 0.8), squeeze=False)
    for a, level in enumerate(levels):
        part = [r for r in sel if r["perturbation"] == level]
        for ax, (key, ylabel, panel_title) in zip(axes[a], panels):
            x = _condition_axis(ax, part, a == len(levels) - 1)
            elements = _elements(part)
            spread = 0.5 / max(len(elements), 1)
            values = []
            for j, e in enumerate(elements):
                y = [r[f"{key}_{e}"] for r in part]
                values += y
                ax.plot(x + (j - (len(elements) - 1) / 2) * spread, y,
                        ELEMENT_MARKERS[j % len(ELEMENT_MARKERS)], ls="none", ms=5,
                        label=f"Z{e}")
            _scale(ax, key, np.asarray(values, dtype=float))
            ax.set_xlim(-0.5, len(part) - 0.5)
            ax.set_ylabel(ylabel)
            ax.set_title(panel_title.format(level=level), fontsize=10)
    if levels:  # outside the data, right of the first row
        handles, labels = axes[0, 0].get_legend_handles_labels()
        axes[0, -1].legend(handles, labels, fontsize=8, loc="upper left",
                           bbox_to_anchor=(1.01, 1.0), frameon=False)
    count = len({(r["friction"], r["resolution"], r["perturbation"]) for r in sel})
    fig.suptitle(f"{title} ({count} condition{'s' if count != 1 else ''})\n{variant} "
                 f"[{VARIANT_LABELS.get(variant, '')}]", fontsize=11)
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- writing


def _write_rows(path: Path, rows) -> Path:
    cols = []
    for r in rows:
        cols += [c for c in r if c not in cols]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=cols)
    writer.writeheader()
    writer.writerows(rows)
    return _atomic_text(path, buf.getvalue())


def _atomic_text(path: Path, text: str) -> Path:
    return _atomic_bytes(path, text.encode("utf-8"))


def _atomic_bytes(path: Path, data: bytes) -> Path:
    tf.atomic_write(path, lambda fh: fh.write(data))
    return path
