"""Results a lab uses, written all or nothing: FRF tables, parameters, Bode plots.

``write_lab_report(results, out)`` writes, per result (recording or condition) ``LABEL``:

- ``frf_LABEL.csv`` / ``frf_LABEL.json``: frequency [Hz], magnitude [N m/rad], phase [deg]
  and coherence [-] of every element Z_ik, with the fitted model's magnitude and phase;
- ``bode_LABEL.png``: magnitude, phase (unwrapped per coherent stretch) and coherence of
  every element over the whole coherent range (one column per element for 1-2 joints, an
  n x n grid for n >= 3), the estimate with its confidence band (Bendat & Piersol), the
  fitted model and the band, the flags of the fit in red, the fitted parameters with
  their intervals and sensitivity ranges in a caption;

and for all results ``parameters.csv`` / ``parameters.md`` (M, B, K with confidence
intervals and units, R^2, VAF, coherence per element) and ``results.json`` (everything,
with the analysis options and the warnings). The report is built in a temporary folder
beside ``out`` and renamed into place at the end, so a failure leaves no partial report
(and an older report at ``out`` untouched).
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import shutil
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from trialformat import atomic_write  # noqa: E402
from trialformat.logs import current_umask, replace_dir  # noqa: E402
from trialformat.tempdirs import disown_temp_dir, own_temp_dir  # noqa: E402

from .lab import (COHERENT, FRF_UNITS, MIN_RUN_BINS, UNITS, WEIGHTING_TEXT,  # noqa: E402
                  effective_averages, element_indices, frf_confidence, result_rows, runs)


def safe_name(label: str) -> str:
    """A file-name-safe form of a label."""
    return re.sub(r"[^A-Za-z0-9._+-]+", "_", label).strip("_") or "result"


def write_lab_report(results, out, *, options=None) -> list[str]:
    """Write the lab report of ``results`` (list of LabResult) into folder ``out``.

    Returns the paths of the files written (inside ``out``).
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = own_temp_dir(f".{out.name}.tmp", out.parent)  # a killed run's: removed next run
    try:
        names = []
        for r in results:
            stem = safe_name(r.label)
            names += write_frf(r, tmp / f"frf_{stem}")
            names.append(_save(bode(r), tmp / f"bode_{stem}.png"))
        names += write_parameters(results, tmp)
        if any(getattr(r, "reflex", None) for r in results):
            from .reflex import write_reflex_tables
            names += write_reflex_tables(results, tmp)
        doc = {"options": options or {}, "results": [r.to_json() for r in results]}
        names.append(_text(tmp / "results.json", json.dumps(doc, indent=1)))
        os.chmod(tmp, 0o777 & ~current_umask())
        replace_dir(tmp, out, kind="lab")
        disown_temp_dir(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return [str(out / Path(n).name) for n in names]


def write_frf(result, stem: Path) -> list[Path]:
    """``stem.csv`` (units in the header) and ``stem.json`` (columns and units)."""
    cols = result.frf_table()
    header = [f"{c} [{_unit(c)}]" for c in cols]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    data = [np.asarray(v, dtype=float) for v in cols.values()]
    writer.writerows(zip(*[[f"{x:.10g}" for x in col] for col in data]))
    doc = {"label": result.label, "trials": result.trials, "method": result.method,
           "band_hz": list(result.band_hz),
           "units": {c: _unit(c) for c in cols},
           "columns": {c: np.asarray(v, dtype=float).tolist() for c, v in cols.items()}}
    stem = Path(stem)  # names keep their dots: frf_day1.left.csv, not frf_day1.csv
    return [_text(stem.with_name(stem.name + ".csv"), buf.getvalue()),
            _text(stem.with_name(stem.name + ".json"), json.dumps(doc))]


def _unit(column: str) -> str:
    if column in FRF_UNITS:
        return FRF_UNITS[column]
    return FRF_UNITS[column.split("_", 1)[1]]


def write_parameters(results, folder: Path) -> list[Path]:
    rows = result_rows(results)
    cols = list(rows[0]) if rows else []
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    md = [parameters_markdown(results)]
    return [_text(folder / "parameters.csv", buf.getvalue()),
            _text(folder / "parameters.md", "\n".join(md))]


def parameters_markdown(results) -> str:
    """M, B, K +- CI per element and result, with R^2, VAF, coherence and warnings."""
    lines = []
    for r in results:
        lines.append(f"### {r.label} ({r.method}, {', '.join(r.trials)})\n")
        lines.append(f"band {r.band_hz[0]:.4g}-{r.band_hz[1]:.4g} Hz ({r.band_source}), "
                     f"{r.n_segments} segments of {r.welch['nperseg']}, corrections: "
                     f"sampling {'on' if r.corrections['left_limit_sampling'] else 'off'}, "
                     f"leakage {'on' if r.corrections['window_leakage'] else 'off'}; fit: "
                     f"{WEIGHTING_TEXT[r.weighting]} ({r.weighting})\n")
        head = (["element"] + [f"{symbol(p, r.n_dof)} [{UNITS[p]}]" for p in "MBK"]
                + ["R^2", "VAF [%]", "coherence"])
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        conf = int(round(100 * r.fit.confidence))
        for i, k in element_indices(r.n_dof):
            cells = [f"Z{i + 1}{k + 1}" if r.n_dof > 1 else "Z"]
            for p in "MBK":
                cells.append(f"{getattr(r.fit, p)[i, k]:.5g} ± "
                             f"{getattr(r.fit, f'{p}_ci')[i, k]:.2g}")
            cells += [f"{r.fit.r2[i, k]:.4f}", f"{r.vaf[i, k]:.2f}",
                      f"{r.coherence_band[i, k]:.3f}"]
            lines.append("| " + " | ".join(cells) + " |")
        if r.sensitivity:
            nv = len(r.sensitivity["variants"])
            for i, k in element_indices(r.n_dof):
                rng = r.sensitivity["range"]
                lines.append(f"| range over {nv} band/weighting choices "
                             + ("" if r.n_dof == 1 else f"Z{i + 1}{k + 1} ") + "| "
                             + " | ".join(f"{rng[p][0][i][k]:.5g} ... {rng[p][1][i][k]:.5g}"
                                          for p in "MBK") + " | | | |")
        lines.append(f"\n± : {conf} % confidence interval half-widths. "
                     + ("1 joint: I is the inertia (column M in parameters.csv and "
                        "results.json).\n" if r.n_dof == 1 else "\n"))
        lines += [f"- warning: {w}" for w in r.warnings] + [""]
    return "\n".join(lines)


def symbol(p: str, n_dof: int) -> str:
    """Name of parameter ``p`` ("M", "B", "K") shown to a user: the inertia of one joint is
    I (the CLI's and the docs' name), of n joints the matrix M. Machine-readable files keep
    the key M for every joint count."""
    return "I" if p == "M" and n_dof == 1 else p


#: The estimate's phase is drawn where the element's coherence reaches this, in stretches
#: of at least lab.MIN_RUN_BINS bins, each unwrapped on its own (lab.COHERENT).
PHASE_MIN_COHERENCE = COHERENT


def stretch_phase_deg(z, coherence, reference_deg=None, threshold=PHASE_MIN_COHERENCE):
    """Phase of ``z`` [deg], unwrapped within each coherent stretch, NaN elsewhere.

    A stretch is a run of at least MIN_RUN_BINS bins with ``coherence >= threshold``. Each
    is unwrapped alone (never through a coherence gap, where the phase means nothing) and
    shifted by the multiple of 360 deg that brings its first bin nearest
    ``reference_deg`` there (the fitted model's unwrapped phase; else the principal
    value). Shape of ``z``.
    """
    z = np.asarray(z)
    out = np.full(z.shape, np.nan)
    for a, b in runs(np.asarray(coherence) >= threshold):
        if b - a < MIN_RUN_BINS:
            continue
        ph = np.degrees(np.unwrap(np.angle(z[a:b])))
        target = np.degrees(np.angle(z[a])) if reference_deg is None else reference_deg[a]
        out[a:b] = ph - 360.0 * np.round((ph[0] - target) / 360.0)
    return out


def bode(result):
    """Magnitude, phase and coherence of every element; estimate, fitted model and band.

    Drawn over the whole coherent range (:attr:`LabResult.f_max`). The estimate's phase is
    unwrapped per coherent stretch (:func:`stretch_phase_deg`); a shaded confidence band
    on magnitude and phase from the coherence and the equivalent number of Welch averages
    (Bendat & Piersol eqs. 9.52-9.53, :func:`estimation.lab.frf_confidence`) where the
    coherence is at least :data:`PHASE_MIN_COHERENCE`; the flags (non-physical or poor
    fit, reversed torque sign, band-sensitive or time-varying parameters) in red in each
    element's magnitude panel; the fitted K, B, M (I for one joint) in a caption below.
    """
    from .report import element_axes, unwrapped_phase_deg

    n = result.n_dof
    f_max = result.f_max
    sel = (result.f > 0) & (result.f <= f_max)
    f = result.f[sel]
    caption = _parameter_caption(result)
    width = max(4.2 * n * n + 1, 6.5) if n <= 2 else 4.4 * n
    height = (6.6 if n <= 2 else 6.6 * n) + 0.9 + 0.22 * len(caption)
    fig = plt.figure(figsize=(width, height))
    axes = element_axes(fig, n, ("mag", "phase", "coherence"))
    nd = effective_averages(result.n_segments, result.welch)
    conf = int(round(100 * result.fit.confidence))
    flags = sorted(set(result.flags))
    for (i, k), (ax_m, ax_p, ax_c) in axes.items():
        z, m, c = result.Z[sel, i, k], result.model[sel, i, k], result.coherence[sel, i, k]
        e = f"Z{i + 1}{k + 1}" if n > 1 else "Z"
        coherent = c >= PHASE_MIN_COHERENCE
        rel = np.where(coherent, frf_confidence(c, nd, result.fit.confidence), np.nan)
        model_phase = unwrapped_phase_deg(m)
        phase = stretch_phase_deg(z, c, model_phase)
        ax_m.fill_between(f, np.abs(z) * np.exp(-rel), np.abs(z) * np.exp(rel),
                          color="tab:blue", alpha=0.25, lw=0, label=f"{conf} % band")
        ax_m.loglog(f, np.where(coherent, np.abs(z), np.nan), color="tab:blue", lw=1.0,
                    label="estimate")
        ax_m.loglog(f, np.where(coherent, np.nan, np.abs(z)), color="0.6", lw=0.6,
                    label=f"estimate, coherence < {PHASE_MIN_COHERENCE:g}")
        ax_m.loglog(f, np.abs(m), "k--", lw=1.2, label="fitted model")
        ax_p.fill_between(f, phase - np.degrees(rel), phase + np.degrees(rel),
                          color="tab:blue", alpha=0.25, lw=0)
        ax_p.semilogx(f, phase, color="tab:blue", lw=1.0)
        ax_p.semilogx(f, model_phase, "k--", lw=1.2)
        ax_c.semilogx(f, c, color="tab:green", lw=1.0)
        ax_c.axhline(PHASE_MIN_COHERENCE, color="0.5", lw=0.6, ls=":")
        ax_c.set_ylim(0, 1.05)
        ax_m.set_title(e, fontsize=10)
        ax_m.set_ylabel(f"|{e}| [N m/rad]")
        ax_p.set_ylabel("phase [deg]")
        ax_c.set_ylabel("coherence [-]")
        for ax in (ax_m, ax_p, ax_c):
            ax.axvspan(max(result.band_hz[0], f[0]), result.band_hz[1], color="0.9", zorder=0)
            ax.grid(True, which="both", alpha=0.3)
            ax.set_xlim(f[0], f[-1])
        if flags and (i == k or n == 1):
            ax_m.text(0.02, 0.02, "FLAGGED: " + ", ".join(flags), transform=ax_m.transAxes,
                      color="tab:red", fontsize=8, va="bottom", ha="left", wrap=True,
                      bbox={"facecolor": "white", "edgecolor": "tab:red", "alpha": 0.85})
        if n <= 2 or i == n - 1:
            ax_c.set_xlabel("frequency [Hz]")
    axes[(0, 0)][0].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"{result.label}: {result.method}, fit band {result.band_hz[0]:.3g}-"
                 f"{result.band_hz[1]:.3g} Hz (shaded), {result.weighting} weighting\n"
                 f"phase unwrapped per stretch of coherence >= {PHASE_MIN_COHERENCE:g}\n"
                 f"{conf} % band: coherence, {nd:.1f} equivalent averages (Bendat & "
                 f"Piersol 9.52-9.53)", fontsize=9)
    bottom = (0.25 + 0.22 * len(caption)) / height
    fig.text(0.5, 0.15 / height, "\n".join(caption), ha="center", va="bottom", fontsize=8,
             family="monospace")
    fig.tight_layout(rect=(0, bottom, 1, 1 - 0.55 / height))
    return fig


def _parameter_caption(result) -> list[str]:
    """One line per fitted parameter: ``K = [...] +- [...] N m/rad`` (I for one joint),
    with the sensitivity range over bands and weightings when computed."""
    lines = []
    for p in ("K", "B", "M"):
        text = (f"{symbol(p, result.n_dof)} = " + _matrix_text(getattr(result.fit, p))
                + " +- " + _matrix_text(getattr(result.fit, f"{p}_ci")) + f" {UNITS[p]}")
        if result.sensitivity:
            lo, hi = result.sensitivity["range"][p]
            text += f"  (range {_matrix_text(lo)} ... {_matrix_text(hi)})"
        lines.append(text)
    return lines


def _matrix_text(a) -> str:
    a = np.asarray(a)
    if a.size == 1:
        return f"{a.item():.4g}"
    return "[" + "; ".join(" ".join(f"{v:.3g}" for v in row) for row in a) + "]"


def _save(fig, path: Path) -> Path:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    atomic_write(path, lambda fh: fh.write(buf.getvalue()))
    return path


def _text(path: Path, text: str) -> Path:
    atomic_write(path, lambda fh: fh.write(text.encode("utf-8")))
    return path
