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
import sys
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
from .numbers import at_decimals, decimals_of, plus_minus  # noqa: E402


from .grouping import safe_name  # noqa: E402,F401  the one label-to-file-name rule


def write_lab_report(results, out, *, options=None, grouping=None) -> list[str]:
    """Write the lab report of ``results`` (list of LabResult) into folder ``out``;
    ``grouping``, the line saying how the trials were grouped (estimation.grouping), goes
    into ``results.json``. Labels that map to one file name get unique names (``_2``),
    each said in a note (stderr and ``results.json`` ``notes``).

    Returns the paths of the files written (inside ``out``).
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = own_temp_dir(f".{out.name}.tmp", out.parent)  # a killed run's: removed next run
    try:
        names = []
        from .grouping import unique_file_names
        stems, renamed = unique_file_names([r.label for r in results], safe_name)
        for note in renamed:  # one name, one output (issue 22)
            print(f"note: figures: {note}", file=sys.stderr)
        for r, stem in zip(results, stems):
            names += write_frf(r, tmp / f"frf_{stem}")
            names.append(_save(bode(r), tmp / f"bode_{stem}.png"))
            from .pvlab import write_varying_files  # K, B, I over the scheduling variable
            names += write_varying_files(r, tmp, stem)
            from .segmentlab import write_segment_files  # piecewise-constant K, B, I
            names += write_segment_files(r, tmp, stem)
        names += write_parameters(results, tmp, torque_sign=(options or {}).get("torque_sign"))
        if any(getattr(r, "reflex", None) for r in results):
            from .reflex import write_reflex_tables
            names += write_reflex_tables(results, tmp)
        doc = {"options": options or {}, "results": [
            {**r.to_json(), "files": f"frf_{stem}.csv"} for r, stem in zip(results, stems)],
            "notes": renamed, "grouping": grouping}
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


def write_parameters(results, folder: Path, *, torque_sign=None) -> list[Path]:
    """``parameters.csv`` and ``parameters.md``: the second-order fit of every result and,
    where the reflex fit was asked, one row (and a table) per fitted trial of the
    intrinsic + reflex model (column ``model``; its VAFs in ``VAF_*`` columns).
    ``torque_sign`` (``--torque-sign``, or None) is stated at the top of parameters.md."""
    rows = result_rows(results)
    md = [] if torque_sign is None else [
        f"Torque sign {torque_sign:+d} given on the command line (--torque-sign), over what "
        f"the recordings' metadata declare.\n"]
    md.append(parameters_markdown(results))
    if any(getattr(r, "reflex", None) is not None for r in results):
        from .reflex import reflex_markdown, reflex_parameter_rows
        for row in rows:
            row["model"] = "second-order (frequency domain)"
        rows += reflex_parameter_rows(results)
        md.append(reflex_markdown(results))
        md += [f"- {r.label}: reflex fit not done for {s['trial']}: {s['reason']}"
               for r in results for s in r.reflex_not_fitted if s["kind"] == "joints"]
    cols = kbi_columns(list(dict.fromkeys(c for row in rows for c in row)))
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n", restval="")
    writer.writeheader()
    writer.writerows(rows)
    return [_text(folder / "parameters.csv", buf.getvalue()),
            _text(folder / "parameters.md", "\n".join(md))]


#: Order of the fitted parameters in every table and figure of the lab report.
PARAMETER_ORDER = "KBM"


def _parameter_of(column: str):
    """``"K"``, ``"B"`` or ``"M"`` for a column of that parameter (its value, ``_ci``,
    ``_range_min``/``_range_max`` or ``err_`` column), else None."""
    name = column.split(" [", 1)[0].removeprefix("err_")
    for suffix in ("_ci", "_range_min", "_range_max"):
        name = name.removesuffix(suffix)
    return name if name in PARAMETER_ORDER else None


def kbi_columns(cols: list) -> list:
    """``cols`` with the K, B, M (I) columns grouped in that order at the place of the
    first of them (value, interval, range, error each kept in their order); the others
    where they were."""
    params = [c for c in cols if _parameter_of(c)]
    if not params:
        return list(cols)
    at = cols.index(params[0])
    ordered = sorted(params, key=lambda c: (PARAMETER_ORDER.index(_parameter_of(c)),
                                            c.startswith("err_"), params.index(c)))
    rest = [c for c in cols if not _parameter_of(c)]
    return rest[:at] + ordered + rest[at:]


def parameters_markdown(results) -> str:
    """K, B, M (I for one joint) ± CI per element and result, rounded to the interval
    (:func:`estimation.numbers.plus_minus`), with R^2, VAF, coherence and warnings."""
    lines = []
    for r in results:
        nd = effective_averages(r.n_segments, r.welch)
        lines.append(f"### {r.label} ({r.method}, {', '.join(r.trials)})\n")
        lines.append(f"band {r.band_hz[0]:.4g}-{r.band_hz[1]:.4g} Hz ({r.band_source}), "
                     f"{r.n_segments} segments of {r.welch['nperseg']}, corrections: "
                     f"sampling {'on' if r.corrections['left_limit_sampling'] else 'off'}, "
                     f"leakage {'on' if r.corrections['window_leakage'] else 'off'}; fit: "
                     f"{WEIGHTING_TEXT[r.weighting]} ({r.weighting}); confidence band of the "
                     f"FRF in the Bode plot: from the coherence and {nd:.1f} equivalent "
                     f"Welch averages (Bendat & Piersol eqs. 9.52-9.53); phase unwrapped "
                     f"per stretch of coherence >= {PHASE_MIN_COHERENCE:g}\n")
        head = (["element"] + [f"{symbol(p, r.n_dof)} [{UNITS[p]}]" for p in PARAMETER_ORDER]
                + ["R^2", "VAF [%]", "coherence"])
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        conf = int(round(100 * r.fit.confidence))
        for i, k in element_indices(r.n_dof):
            cells = [f"Z{i + 1}{k + 1}" if r.n_dof > 1 else "Z"]
            for p in PARAMETER_ORDER:
                cells.append(plus_minus(getattr(r.fit, p)[i, k],
                                        getattr(r.fit, f"{p}_ci")[i, k]))
            cells += [f"{r.fit.r2[i, k]:.4f}", f"{r.vaf[i, k]:.2f}",
                      f"{r.coherence_band[i, k]:.3f}"]
            lines.append("| " + " | ".join(cells) + " |")
        if r.sensitivity:
            nv = len(r.sensitivity["variants"])
            rng = r.sensitivity["range"]
            for i, k in element_indices(r.n_dof):
                lines.append(f"| range over {nv} band/weighting choices "
                             + ("" if r.n_dof == 1 else f"Z{i + 1}{k + 1} ") + "| "
                             + " | ".join(
                                 f"{_same_place(rng[p][0][i][k], getattr(r.fit, f'{p}_ci')[i, k])}"
                                 f" ... "
                                 f"{_same_place(rng[p][1][i][k], getattr(r.fit, f'{p}_ci')[i, k])}"
                                 for p in PARAMETER_ORDER) + " | | | |")
        lines.append(f"\n± : {conf} % confidence interval half-widths (2 significant "
                     f"digits, the value to the same decimal place; parameters.csv and "
                     f"results.json keep every digit). "
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


#: The Bode plot's frequency axis ends at the coherent range's top, but at most this factor
#: above the fit band's top (the FRF table keeps the whole coherent range).
PLOT_BEYOND_BAND = 2.0

#: Plain words for each estimator (the figure's caption; docs/estimation.md has the rest).
METHOD_TEXT = {"direct": "angle to torque (no recorded reference)",
               "full": "through the recorded perturbation",
               "decomposition": "through the recorded perturbation (T/R)",
               "closed_loop": "through the perturbations of all joints"}


def plot_top_hz(result) -> float:
    """Top of a Bode plot's frequency axis [Hz]: the coherent range's top
    (:attr:`LabResult.f_max`), at most :data:`PLOT_BEYOND_BAND` times the fit band's top."""
    return min(result.f_max, PLOT_BEYOND_BAND * result.band_hz[1])


def low_coherence_spans(f, coherence, threshold=PHASE_MIN_COHERENCE) -> list[tuple]:
    """(lo, hi) [Hz] of the runs of bins whose coherence is below ``threshold``, each bin
    widened by half a bin on either side (``f``: the uniform Welch grid, (nf,))."""
    df = float(f[1] - f[0]) if len(f) > 1 else 0.0
    return [(max(f[a] - df / 2, f[0]), min(f[b - 1] + df / 2, f[-1]))
            for a, b in runs(np.asarray(coherence) < threshold)]


def bode(result):
    """Magnitude, phase and coherence of every element; estimate, fitted model and band.

    Frequency axis: from the first bin to :func:`plot_top_hz` (the coherent range, not far
    past the fit band). The estimate's phase is unwrapped per coherent stretch
    (:func:`stretch_phase_deg`); a shaded confidence band on magnitude and phase from the
    coherence and the equivalent number of Welch averages (Bendat & Piersol eqs.
    9.52-9.53, :func:`estimation.lab.frf_confidence`) where the coherence is at least
    :data:`PHASE_MIN_COHERENCE`; the fit band shaded grey, and the bins whose coherence is
    below :data:`PHASE_MIN_COHERENCE` hatched in every panel (inside the fit band they are
    fitted, with their weight) and drawn grey. Title: the label and, for one joint, K, B, I
    with their intervals (:func:`estimation.numbers.plus_minus`); the flags (non-physical
    or poor fit, reversed torque sign, band-sensitive or time-varying parameters) in red
    above each diagonal element's magnitude panel, outside the data; below, a box with the
    parameters (n joints: the K, B, M matrices; ranges over bands and weightings; the
    parallel-cascade fit) and a one-line caption of the method.
    """
    from .report import element_axes, unwrapped_phase_deg

    n = result.n_dof
    top = plot_top_hz(result)
    sel = (result.f > 0) & (result.f <= top)
    f = result.f[sel]
    box = _parameter_caption(result)
    width = max(4.2 * n * n + 1, 7.0) if n <= 2 else 4.4 * n
    if n == 1 and result.reflex:  # room for the parallel-cascade lines
        width = 8.5
    axes_h = 6.0 if n <= 2 else 6.0 * n
    fig = plt.figure(figsize=(width, axes_h + 2.0))
    axes = element_axes(fig, n, ("mag", "phase", "coherence"))
    nd = effective_averages(result.n_segments, result.welch)
    conf = int(round(100 * result.fit.confidence))
    flags = sorted(set(result.flags))
    thr = PHASE_MIN_COHERENCE
    band = (max(result.band_hz[0], f[0]), result.band_hz[1])
    for (i, k), (ax_m, ax_p, ax_c) in axes.items():
        z, m, c = result.Z[sel, i, k], result.model[sel, i, k], result.coherence[sel, i, k]
        e = f"Z{i + 1}{k + 1}" if n > 1 else "Z"
        coherent = c >= thr
        rel = np.where(coherent, frf_confidence(c, nd, result.fit.confidence), np.nan)
        model_phase = unwrapped_phase_deg(m)
        phase = stretch_phase_deg(z, c, model_phase)
        ax_m.fill_between(f, np.abs(z) * np.exp(-rel), np.abs(z) * np.exp(rel),
                          color="tab:blue", alpha=0.25, lw=0, label=f"{conf} % band")
        ax_m.loglog(f, np.where(coherent, np.abs(z), np.nan), color="tab:blue", lw=1.0,
                    label="estimate")
        ax_m.loglog(f, np.where(coherent, np.nan, np.abs(z)), color="0.55", lw=0.7,
                    label=f"estimate, coherence < {thr:g}")
        ax_m.loglog(f, np.abs(m), "k--", lw=1.2, label="fitted model (second order)")
        ax_p.fill_between(f, phase - np.degrees(rel), phase + np.degrees(rel),
                          color="tab:blue", alpha=0.25, lw=0)
        ax_p.semilogx(f, phase, color="tab:blue", lw=1.0)
        ax_p.semilogx(f, model_phase, "k--", lw=1.2)
        if n == 1:
            _draw_reflex(ax_m, ax_p, f, result.reflex or [], model_phase)
        ax_c.semilogx(f, c, color="tab:green", lw=1.0)
        ax_c.semilogx(f, np.where(coherent, np.nan, c), color="tab:red", lw=0, marker=".",
                      ms=3)
        ax_c.axhline(thr, color="0.3", lw=0.7, ls=":")
        ax_c.text(1.0, thr, f" {thr:g}", transform=ax_c.get_yaxis_transform(),
                  fontsize=7, va="center", ha="left", color="0.3")
        ax_c.set_ylim(0, 1.05)
        if n > 1:
            ax_m.set_title(e, fontsize=10, loc="right")
        ax_m.set_ylabel(f"|{e}| [N m/rad]")
        ax_p.set_ylabel("phase [deg]")
        ax_c.set_ylabel("coherence [-]")
        spans = low_coherence_spans(f, c, thr)
        for j, ax in enumerate((ax_m, ax_p, ax_c)):
            ax.axvspan(*band, color="0.88", zorder=0, lw=0,
                       label="fit band" if j == 0 else None)
            for s, (a, b) in enumerate(spans):
                ax.axvspan(a, b, facecolor="white", edgecolor="0.6", hatch="////", lw=0,
                           zorder=0.5, label=(f"coherence < {thr:g}" if j == s == 0
                                              else None))
            ax.grid(True, which="both", alpha=0.3)
            ax.set_xlim(f[0], f[-1])
        if flags and (i == k or n == 1):
            ax_m.text(0.0, 1.03, "FLAGGED: " + ", ".join(flags), transform=ax_m.transAxes,
                      color="tab:red", fontsize=8, va="bottom", ha="left",
                      bbox={"facecolor": "white", "edgecolor": "tab:red", "pad": 2})
        if n <= 2 or i == n - 1:
            ax_c.set_xlabel("frequency [Hz]")
    handles, labels = axes[(0, 0)][0].get_legend_handles_labels()
    legend = fig.legend(handles, labels, fontsize=7, loc="lower center",
                        ncol=3 if n == 1 else 4, frameon=False)
    fig.suptitle(_title(result), fontsize=10)
    texts = [legend]
    texts += [fig.text(0.5, 0.0, "\n".join(box), ha="center", va="bottom", fontsize=7.5,
                       multialignment="left",
                       family="monospace")] if box else []
    texts.append(fig.text(0.5, 0.0, _method_caption(result, nd), ha="center", va="bottom",
                          fontsize=7, color="0.3", wrap=True))
    _fit_layout(fig, texts, width, axes_h)
    return fig


def _fit_layout(fig, texts, width, axes_h) -> None:
    """Stack ``texts`` (a figure legend and figure texts, top to bottom) under the axes and
    size the figure so that axes, title and texts fill it without gaps."""
    renderer = fig.canvas.get_renderer()
    dpi = fig.dpi
    pad = 0.08
    _wrap_title(fig._suptitle, renderer, width * dpi * 0.96)
    heights = [t.get_window_extent(renderer).height / dpi for t in texts]
    title_h = fig._suptitle.get_window_extent(renderer).height / dpi + pad
    bottom = sum(heights) + pad * (len(texts) + 1)
    height = axes_h + title_h + bottom
    fig.set_size_inches(width, height)
    y = pad
    for t, h in reversed(list(zip(texts, heights))):
        if hasattr(t, "set_bbox_to_anchor"):  # a figure legend
            t.set_bbox_to_anchor((0.5, y / height), transform=fig.transFigure)
        else:
            t.set_position((0.5, y / height))
        y += h + pad
    fig._suptitle.set_position((0.5, 1 - pad / height))
    fig._suptitle.set_va("top")
    fig.tight_layout(rect=(0, bottom / height, 1, 1 - title_h / height), pad=0.3,
                     h_pad=0.6)


def _wrap_title(text, renderer, max_px) -> None:
    """Break ``text`` (a title) after its ", " so that no line is wider than ``max_px``
    pixels: a long label or parameters with many digits (``I = 0.01499999 ± 0.0000008``)
    were clipped on both sides of the figure. A single piece still too wide shrinks the
    font (down to 6 pt)."""
    if text.get_window_extent(renderer).width <= max_px:
        return
    pieces = re.split(r"(?<=, )|(?<=: )", text.get_text())
    lines = [""]
    for piece in pieces:
        text.set_text((lines[-1] + piece).rstrip())
        if lines[-1] and text.get_window_extent(renderer).width > max_px:
            lines.append(piece)
        else:
            lines[-1] += piece
    text.set_text("\n".join(line.rstrip() for line in lines))
    text.set_multialignment("center")
    while text.get_window_extent(renderer).width > max_px and text.get_fontsize() > 6:
        text.set_fontsize(text.get_fontsize() - 0.5)


def _title(result) -> str:
    """``label: K = 79.5 ± 1.6 N m/rad, B = ..., I = ...`` (one joint), else the label."""
    if result.n_dof > 1:
        return f"{result.label} ({result.n_dof} joints): fitted K, B, M below"
    parts = [f"{symbol(p, 1)} = " + plus_minus(getattr(result.fit, p)[0, 0],
                                                getattr(result.fit, f"{p}_ci")[0, 0],
                                                UNITS_PRETTY[p]) for p in "KBM"]
    head = f"{result.label}, second-order fit" if result.reflex else result.label
    return f"{head}: " + ", ".join(parts)


#: Units as printed on figures.
UNITS_PRETTY = {"K": "N m/rad", "B": "N m s/rad", "M": "kg m²"}


def _method_caption(result, nd) -> str:
    conf = int(round(100 * result.fit.confidence))
    return (f"Estimate: {METHOD_TEXT.get(result.method, result.method)}, "
            f"{', '.join(result.trials)}. Fit band {result.band_hz[0]:.3g}-"
            f"{result.band_hz[1]:.3g} Hz (grey). Blue band: {conf} % confidence from the "
            f"coherence ({nd:.0f} equivalent averages). Hatched: coherence < "
            f"{PHASE_MIN_COHERENCE:g} (estimate grey, phase not drawn). Details: "
            f"parameters.md.")


#: line styles of the parallel-cascade model: intrinsic, reflex, total
REFLEX_STYLES = {"intrinsic": ("tab:orange", "-."), "reflex": ("tab:purple", ":"),
                 "total": ("tab:red", "-")}


def _draw_reflex(ax_m, ax_p, f, fits, reference_deg) -> None:
    """The intrinsic, reflex and total frequency responses of each parallel-cascade fit
    (:meth:`estimation.reflex.ReflexResult.frequency_response`): magnitude, and phase.
    The intrinsic and total phases are drawn on the branch (multiple of 360 deg) nearest
    ``reference_deg``, the second-order fit's phase that the estimate's coherent
    stretches are aligned to, so that model and estimate are compared on the same branch
    (the line is broken where the branch changes); the reflex pathway's phase, which its
    delay turns by several turns, as its principal value, broken at each wrap."""
    for r in fits:
        resp = r.frequency_response(f)
        suffix = f" ({r.trial})" if len(fits) > 1 else ""
        for part, (color, ls) in REFLEX_STYLES.items():
            z = resp[part]
            ax_m.loglog(f, np.abs(z), color=color, ls=ls, lw=1.3,
                        label=f"{part} (parallel cascade){suffix}")
            ph = np.degrees(np.angle(z))
            if part != "reflex":
                ph = ph + 360.0 * np.round((reference_deg - ph) / 360.0)
            ph[1:][np.abs(np.diff(ph)) > 180] = np.nan
            ax_p.semilogx(f, ph, color=color, ls=ls, lw=1.3)


def _reflex_caption(result) -> list[str]:
    """The parallel-cascade fits, K, B, I first, each value rounded to its interval."""
    from .reflex import delay_text
    lines = []
    for r in result.reflex or []:
        v, c = r.values, r.ci
        lines += [f"intrinsic + reflex, parallel cascade ({r.trial}, rectify {r.rectify}):",
                  f"  K = {plus_minus(v['K'], c['K'], 'N m/rad')}, B = "
                  f"{plus_minus(v['B'], c['B'], 'N m s/rad')}, I = "
                  f"{plus_minus(v['I'], c['I'], 'kg m²')}",
                  f"  G = {plus_minus(v['G'], c['G'], 'N m s/rad')}, delay {delay_text(r)}, "
                  f"low-pass {plus_minus(v['cutoff_hz'], c['cutoff_hz'], 'Hz')}, damping "
                  f"{plus_minus(v['damping'], c['damping'])}",
                  f"  VAF intrinsic {r.vaf_pct['intrinsic']:.1f} %, reflex "
                  f"{r.vaf_pct['reflex']:.1f} %, total {r.vaf_pct['total']:.1f} % (K-B-I alone "
                  f"{r.vaf_pct['intrinsic_only']:.1f} %)",
                  f"  reflex drawn with its best linear gain {r.linear_gain:.3g} "
                  f"(the rectifier's Bussgang gain on the data)"]
        lines += [f"  FLAGGED: {w.split(':')[0][:90]}" for w in r.warnings]
    for s in result.reflex_not_fitted:
        why = {"short": "too short", "rate": "sampled too slowly"}.get(s["kind"], "several joints")
        lines.append(f"reflex not fitted for {s['trial']} ({why}: see the warnings)")
    return lines


def _parameter_caption(result) -> list[str]:
    """The box under a Bode plot, K, B, I (M) in that order. One joint: the range of K,
    B, I over bands and weightings (the values themselves are in the title); n joints:
    ``K = [a ± da, ...; ...] N m/rad`` per parameter, with its range. Then the
    parallel-cascade fits (:func:`_reflex_caption`)."""
    n = result.n_dof
    lines = []
    rng = result.sensitivity["range"] if result.sensitivity else None
    if n == 1:
        if rng:
            nv = len(result.sensitivity["variants"])
            parts = []
            for p in "KBM":
                ci = float(getattr(result.fit, f"{p}_ci")[0, 0])
                lo, hi = (float(np.asarray(x).ravel()[0]) for x in rng[p])
                parts.append(f"{symbol(p, 1)} {_same_place(lo, ci)} ... "
                             f"{_same_place(hi, ci)}")
            lines.append(f"over {nv} band/weighting choices: " + ", ".join(parts))
    else:  # one line per matrix row, the cells aligned
        nv = len(result.sensitivity["variants"]) if rng else 0
        for p in "KBM":
            value, ci = getattr(result.fit, p), getattr(result.fit, f"{p}_ci")
            cells = [[plus_minus(value[i, k], ci[i, k]) for k in range(n)] for i in range(n)]
            w = max(len(c) for row in cells for c in row)
            lines.append(f"{p} [{UNITS_PRETTY[p]}]:")
            lines += ["  [ " + "   ".join(c.rjust(w) for c in row) + " ]" for row in cells]
            if rng:
                lo, hi = (np.asarray(x) for x in rng[p])
                lines.append(f"  over {nv} band/weighting choices: {_matrix_text(lo)} ... "
                             f"{_matrix_text(hi)}")
    if result.reflex and lines:
        lines.insert(0, "second-order fit:")
    return lines + _reflex_caption(result)


def _same_place(x: float, ci: float) -> str:
    """``x`` rounded to the decimal place of ``ci`` at 2 significant digits (4
    significant digits when ``ci`` is not a positive number)."""
    try:
        return at_decimals(x, decimals_of(ci))
    except ValueError:
        return f"{x:.4g}"


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
