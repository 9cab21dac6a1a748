"""The paper's figures and tables from a folder of trials (a grid run).

``make_report(folder, out)`` reads every trial, groups them into conditions by their
metadata, scores each condition (:func:`estimation.conditions.evaluate`) and writes:

- ``fig2_impedance.png``: true vs estimated Z (magnitude, phase; 2x2 elements) for the four
  corner conditions (friction, resolution) in {0, 3}^2 at the highest perturbation level;
- ``fig3_accuracy.png``: VAF and R^2 of every element over all conditions;
- ``fig4_coherence.png``: band-mean derived coherence over all conditions;
- ``table_conditions.csv`` (every figure, per element) and ``table_conditions.md``
  (summaries), ``table_parameters.csv``/``.md`` (fitted M, B, K against Table I, mean
  and worst case over conditions), ``report.json``.
Files are written atomically (temporary name, then rename).
"""

from __future__ import annotations

import csv
import io
import json
import os
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from trialformat import reference as ref  # noqa: E402

from .accuracy import true_impedance  # noqa: E402
from .conditions import VARIANTS, evaluate, group_conditions  # noqa: E402
from .estimator import estimate_impedance  # noqa: E402
from .io import read_trials  # noqa: E402

ELEMENTS = ("11", "12", "21", "22")


def make_report(folders, out, *, truth="table1", variant="decomposition",
                progress=True) -> dict:
    """Score every condition of the trials in ``folders`` and write figures and tables.

    Parameters
    ----------
    folders : path or list of paths
        Trials (``.csv``+``.json`` or ``.mat``), e.g. a grid run and a folder of
        all-joints trials for the MIMO baselines; grouped by metadata, not by folder.
    out : path
        Report folder (created).
    truth : {"table1", "none"}
        Compare with Table I (simulated trials), or, for lab data, with each estimate's
        own second-order fit.
    variant : str
        Variant (estimation.conditions.VARIANTS) shown in Figs. 2-4; Fig. 2 plots the raw
        estimate of its method.

    Returns
    -------
    dict with ``rows`` (one per condition and variant) and the output ``files``.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    arm = ref.arm_matrices() if truth == "table1" else None
    folders = [folders] if isinstance(folders, (str, os.PathLike)) else list(folders)
    paths = [p for folder in folders for p in
             sorted(Path(folder).glob("*.csv")) + sorted(Path(folder).glob("*.mat"))]
    trials = [t for p in tqdm(paths, desc="reading trials", disable=not progress)
              for t in read_trials([p])]
    groups = group_conditions(trials)
    rows = []
    for cond, group in tqdm(groups.items(), desc="estimating", disable=not progress):
        for row in evaluate(group, truth=arm):
            rows.append({"friction": cond.friction, "resolution": cond.resolution,
                         "perturbation": cond.perturbation, "tuning": cond.tuning,
                         "n_trials": len(group), **row})
    files = [_write_rows(out / "table_conditions.csv", rows),
             _atomic_text(out / "table_conditions.md", conditions_markdown(rows, arm)),
             *parameter_tables(rows, arm, out)]
    method = next(m for name, m, *_ in VARIANTS if name == variant)
    files.append(_save(fig2(groups, arm, method), out / "fig2_impedance.png"))
    files.append(_save(fig3(rows, variant), out / "fig3_accuracy.png"))
    files.append(_save(fig4(rows, variant), out / "fig4_coherence.png"))
    summary = {"folders": [Path(f).name for f in folders], "truth": truth, "variant_in_figures": variant,
               "n_trials": len(trials),
               "n_conditions": len(groups), "rows": rows}
    files.append(_atomic_text(out / "report.json", json.dumps(summary, indent=1)))
    return {"rows": rows, "files": [str(f) for f in files]}


# ----------------------------------------------------------------------------- tables


def conditions_markdown(rows, arm) -> str:
    """One line per condition and variant: worst element of each measure."""
    cols = ["friction", "resolution", "perturbation", "tuning", "variant", "vaf_min",
            "r2_min", "coh_min"] + (["err_M_max", "err_B_max", "err_K_max"] if arm else [])
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r.get(c)) for c in cols) + " |")
    legend = ("\nvaf_min [%], r2_min, coh_min: worst element; err_*_max [%]: largest "
              "|relative error| of the fitted parameter over the four elements.\n")
    return "\n".join(lines) + "\n" + legend


def parameter_tables(rows, arm, out) -> list:
    """Fitted M, B, K per element and variant: Table I, mean, worst error over conditions."""
    table = []
    for name, *_ in VARIANTS:
        sel = [r for r in rows if r["variant"] == name]
        if not sel:
            continue
        for p, true in zip("MBK", arm if arm else (None,) * 3):
            for e in ELEMENTS:
                vals = np.array([r[f"{p}_{e}"] for r in sel])
                line = {"variant": name, "parameter": f"{p}_{e}", "n_conditions": len(sel),
                        "fitted_mean": vals.mean(), "fitted_min": vals.min(),
                        "fitted_max": vals.max()}
                if true is not None:
                    errs = np.array([r[f"err_{p}_{e}"] for r in sel])
                    line.update(table_I=float(true[int(e[0]) - 1, int(e[1]) - 1]),
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


def fig2(groups, arm, method):
    """True vs estimated Z for the corner conditions at the highest perturbation level."""
    levels = [c.perturbation for c in groups if isinstance(c.perturbation, int)]
    top = max(levels) if levels else None
    corners = [(c, g) for c, g in groups.items() if c.perturbation == top
               and (c.friction, c.resolution) in ((0, 0), (0, 3), (3, 0), (3, 3))]
    fig, axes = plt.subplots(2, 4, figsize=(14, 6), sharex=True)
    f_true = None
    for cond, group in corners:
        use = [t for t in group if (t.perturbed_dof is not None) ==
               (method in ("decomposition", "full"))]
        if not use:
            continue
        est = estimate_impedance(use, method=method)
        b = est.band
        f_true = est.f[b]
        for j, e in enumerate(ELEMENTS):
            z = est.Z[b, int(e[0]) - 1, int(e[1]) - 1]
            axes[0, j].loglog(f_true, np.abs(z), label=f"F{cond.friction}R{cond.resolution}")
            axes[1, j].semilogx(f_true, np.degrees(np.angle(z)))
    if arm is not None and f_true is not None:
        zt = true_impedance(f_true, *arm)
        for j, e in enumerate(ELEMENTS):
            z = zt[:, int(e[0]) - 1, int(e[1]) - 1]
            axes[0, j].loglog(f_true, np.abs(z), "k--", label="Table I")
            axes[1, j].semilogx(f_true, np.degrees(np.angle(z)), "k--")
    for j, e in enumerate(ELEMENTS):
        axes[0, j].set_title(f"Z{e}")
        axes[1, j].set_xlabel("frequency [Hz]")
    axes[0, 0].set_ylabel("|Z| [N m/rad]")
    axes[1, 0].set_ylabel("phase [deg]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"Fig. 2: true vs estimated impedance ({method}, perturbation level {top})")
    fig.tight_layout()
    return fig


def _by_level(rows, variant):
    sel = [r for r in rows if r["variant"] == variant]
    levels = sorted({r["perturbation"] for r in sel}, key=str)
    return sel, levels


def fig3(rows, variant):
    """VAF and R^2 of each element over the conditions, one row of panels per level."""
    sel, levels = _by_level(rows, variant)
    fig, axes = plt.subplots(max(len(levels), 1), 2, figsize=(12, 3 * max(len(levels), 1)),
                             squeeze=False)
    for a, level in enumerate(levels):
        part = [r for r in sel if r["perturbation"] == level]
        x = np.arange(len(part))
        labels = [f"F{r['friction']}R{r['resolution']}" for r in part]
        for e in ELEMENTS:
            axes[a, 0].plot(x, [r[f"vaf_{e}"] for r in part], "o-", label=f"Z{e}")
            axes[a, 1].plot(x, [r[f"r2_{e}"] for r in part], "o-", label=f"Z{e}")
        for ax, name in zip(axes[a], ("VAF [%]", "R^2")):
            ax.ticklabel_format(axis="y", useOffset=False)
            ax.set_xticks(x, labels, rotation=90, fontsize=7)
            ax.set_ylabel(f"{name}, level {level}")
    if levels:
        axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"Fig. 3: accuracy ({variant})")
    fig.tight_layout()
    return fig


def fig4(rows, variant):
    """Band-mean derived coherence of each element over the conditions."""
    sel, levels = _by_level(rows, variant)
    fig, axes = plt.subplots(max(len(levels), 1), 1, figsize=(8, 3 * max(len(levels), 1)),
                             squeeze=False)
    for a, level in enumerate(levels):
        part = [r for r in sel if r["perturbation"] == level]
        x = np.arange(len(part))
        for e in ELEMENTS:
            axes[a, 0].plot(x, [r[f"coh_{e}"] for r in part], "o-", label=f"Z{e}")
        axes[a, 0].set_xticks(x, [f"F{r['friction']}R{r['resolution']}" for r in part],
                              rotation=90, fontsize=7)
        axes[a, 0].set_ylabel(f"mean coherence, level {level}")
        axes[a, 0].ticklabel_format(axis="y", useOffset=False)
    if levels:
        axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"Fig. 4: reliability ({variant})")
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- writing


def _save(fig, path: Path) -> Path:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return _atomic_bytes(path, buf.getvalue())


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
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
