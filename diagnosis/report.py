"""The diagnosis report: ``report.md``, ``report.json`` and PNG plots in one folder."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import signal as sps  # noqa: E402

from .features import SIGNALS  # noqa: E402

@dataclass
class DiagnosisReport:
    """Result of :func:`diagnose`; ``to_dict()`` is the report's JSON (docs/diagnosis.md)."""

    verdict: str
    named: list
    summary: str
    amplitude: dict
    conventions: list
    numerics: list
    timing: dict
    fitted: dict
    ranking: list
    pairs: list
    gap: dict
    where: dict
    arm: dict
    split: dict
    config: dict
    n_simulations: int
    elapsed_s: float
    trials: list
    experiment: dict = field(default_factory=dict)
    gap_in_time: dict = field(default_factory=dict)  # pipeline.when
    intervals: dict = field(default_factory=dict)
    out_dir: object = None
    extras: dict = field(default_factory=dict, repr=False)
    #: effects (or pairs) that explain the held-out gap as well as the named one, on its
    #: held-out split (diagnosis.ties; [] when none)
    indistinguishable: list = field(default_factory=list)
    #: every alternative to the named fit, judged on its split (diagnosis.ties rows)
    alternatives: list = field(default_factory=list)
    #: how the trials were grouped, in one line (estimation.grouping.describe)
    grouping: str = ""
    #: the scheduling variable of each trial (trialformat.scheduling.usage: name, units,
    #: source, range, whether the state-varying effects used it, the refusal)
    scheduling: list = field(default_factory=list)
    #: the named model in full: K, B, I and the effect's parameters, each [value, low,
    #: high] (pipeline.report.named_model); None when nothing is named
    named_model: dict | None = None

    def to_dict(self) -> dict:
        return {"format": "arm-impedance-diagnosis/1", "verdict": self.verdict,
                "summary": self.summary, "named_effects": self.named,
                "indistinguishable": self.indistinguishable,
                "alternatives": self.alternatives,
                "named_model": self.named_model,
                "fitted_parameters": self.fitted, "fitted_intervals_95": self.intervals,
                "amplitude_dependence": self.amplitude,
                "conventions": self.conventions, "numerical_retries": self.numerics,
                "timing": self.timing,
                "ranking": self.ranking, "pairs": self.pairs, "gap": self.gap,
                "where": self.where, "gap_in_time": self.gap_in_time, "arm": self.arm, "split": self.split,
                "trials": self.trials, "experiment": self.experiment,
                "n_simulations": self.n_simulations,
                "elapsed_s": self.elapsed_s, "config": self.config,
                "grouping": self.grouping,
                "scheduling": list(self.scheduling)}


FIGURES = {"where": "gap_where.png", "ranking": "gap_ranking.png",
           "frf": "frf_compare.png", "noise": "noise_spectra.png",
           "varying": "k_of_rho.png"}
UNITS = {"theta": "rad", "tau_h": "N m", "tau_m": "N m"}


def write_report(report, out_dir) -> Path:
    """Write the report folder; returns the path of ``report.md``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    _plot_where(report, out / FIGURES["where"])
    _plot_ranking(report, out / FIGURES["ranking"])
    _plot_signals(report, out / FIGURES["frf"], out / FIGURES["noise"])
    if report.gap_in_time:
        from .pipeline.when import plot
        plot(report.gap_in_time, out / "gap_time.png")
    pv = (report.named_model or {}).get("parameter_varying")
    if pv:
        _plot_varying(pv, out / FIGURES["varying"])
    _atomic_text(out / "report.json", json.dumps(_clean(report.to_dict()), indent=2))
    _atomic_text(out / "report.md", markdown(report))
    return out / "report.md"


def _atomic_text(path: Path, text: str) -> None:
    """Write through a temporary file and rename; the file gets the user's umask."""
    from trialformat.logs import atomic_write
    atomic_write(path, lambda fh: fh.write(text.encode("utf-8")))


def _clean(obj):
    """JSON-safe copy: numpy scalars to float, inf/nan to strings."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if np.isfinite(v) else ("inf" if v > 0 else "-inf" if v < 0 else "nan")
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def _fmt(v, digits=3) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        if not np.isfinite(v):
            return "diverges" if v > 0 else "-inf"
        return f"{v:.{digits}g}"
    return str(v)


def _params(p: dict) -> str:
    return "; ".join(f"{e}: " + ", ".join(f"{k}={_fmt(v, 4)}" for k, v in d.items())
                     for e, d in p.items())


def alternatives_lines(report, top: int = 6) -> list:
    """report.md's table of the named fit's alternatives (diagnosis.ties rows), each on
    the named fit's held-out split; [] when there are none."""
    rows = report.alternatives or []
    if not rows:
        return []
    named = " + ".join(report.named)
    out = [f"Alternatives to {named}, each judged on the held-out split of {named} "
           f"({rows[0]['split']}), where {named} closes "
           f"{_pct(rows[0]['named_held_out_reduction'])} % of the gap; an alternative "
           f"within 5 points of it, or above, is indistinguishable here:", "",
           "| alternative | held-out reduction, same split | on its own split | "
           "indistinguishable | what would separate them |", "|---|---|---|---|---|"]
    for r in rows[:top]:
        own = ("same split" if not r.get("own_split") else
               f"{_pct(r.get('own_held_out_reduction'))} % ({r['own_split']}"
               + (f"; {named} there: {_pct(r['named_on_own_split'])} %"
                  if r.get("named_on_own_split") is not None else "") + ")")
        tie = ("**yes**" + (" (closes more)" if r.get("closes_more") else "")
               if r.get("indistinguishable") else
               "no" if r.get("nameable", True) else "no (flagged fit)")
        out.append(f"| {r['name']} | {_pct(r['held_out_reduction'])} % | {own} | {tie} | "
                   f"{r.get('separate') or '-'} |")
    if len(rows) > top:
        out.append(f"| ({len(rows) - top} more in report.json) | | | | |")
    return out + [""]


def _pct(share) -> str:
    from .ties import _pct as pct
    return pct(share)


def scheduling_line(u) -> str:
    """One line on a trial's scheduling variable (a trialformat.scheduling.usage entry):
    name, units, source and range, and whether the state-varying effects used it."""
    units = f" {u['units']}" if u.get("units") else ""
    shown = f" [{u['units']}]" if u.get("units") else " (units not stated)"
    lo, hi = u["range"]
    head = (f"Scheduling variable of {u['trial']}: {u['name']}{shown} ({u['source']}, "
            f"{u['how']}): {lo:.4g}..{hi:.4g}{units}")
    return head + ("; used by the state-varying effects" if u.get("used") else
                   f"; not used: {u.get('refusal')}")


def markdown(report) -> str:
    """The report page (Markdown)."""
    g = report.gap
    m = measure_name(g)
    exp = report.experiment or {}
    lines = [f"# Sim-to-real gap diagnosis", "",
             f"Trials: {', '.join(report.trials)}", "",
             *([report.grouping, ""] if report.grouping else []),
             *[x for u in (report.scheduling or []) for x in (scheduling_line(u), "")],
             f"Experiment: {exp.get('class', '-')} ({exp.get('title', '-')})"
             + (f"; effects not applicable to it: {', '.join(exp['effects_not_applicable'])}"
                if exp.get("effects_not_applicable") else "") + ".", "",
             f"## Verdict: **{report.verdict}**"
             + (f" — {' + '.join(report.named)}" if report.named else ""), "",
             report.summary, ""]
    if report.named:
        lines += [f"Fitted: {_params(report.fitted)}", ""]
        if report.intervals:
            lines += ["95 % intervals: " + "; ".join(
                f"{e}: " + ", ".join(f"{k} [{_fmt(v[0], 4)}, {_fmt(v[1], 4)}]"
                                     for k, v in d.items())
                for e, d in report.intervals.items() if d), ""]
        if report.named_model:
            lines += named_model_lines(report.named_model)
        lines += alternatives_lines(report)
        lines += [
                  f"Held-out gap ({m}) {_fmt(g['nominal_held_out'])} -> "
                  f"{_fmt(g['named_held_out'])} (reduction "
                  f"{_fmt(100 * g['named_held_out_reduction'], 3)} %)"
                  + (f"; all data {_fmt(g['nominal_all'])} -> {_fmt(g['named_all'])}"
                     if g.get("named_all") is not None else "") + "."
                  + residual_sentence(g.get("named_held_out_residual")), ""]
    lines += [f"Nominal gap ({m}), all data: {_fmt(g['nominal_all'])} (significant above "
              f"{_fmt(g['significance_threshold'])}); calibration {_fmt(g['nominal_calibration'])}, "
              f"held out {_fmt(g['nominal_held_out'])}. The {m} gap is "
              f"{g.get('measure', '').split(':', 1)[-1].strip() or 'the feature gap'}.", ""]
    if g.get("noise_floor_source"):
        lines += [f"Noise floor ({_fmt(g.get('noise_floor'))} of the torque energy): "
                  f"{g['noise_floor_source']}.", ""]
    if g.get("model_tolerance_source"):
        per = g.get("model_tolerance_per_record") or []
        lines += [f"Model tolerance ({_fmt(g.get('model_tolerance'))} of the torque energy, "
                  f"in the threshold): {g['model_tolerance_source']}"
                  + (": " + ", ".join(f"{x['record']} {_fmt(x['tolerance'])}" for x in per)
                     if per else "") + ".", ""]
    feat = g.get("features")
    if feat:
        lines += [f"Feature gap (another measure: the where stage's, from the FRF features "
                  f"below; not comparable with the {m} gap the verdict uses): all data "
                  f"{_fmt(feat['nominal_all'])} (significant above "
                  f"{_fmt(feat['significance_threshold'])})"
                  + (f", {_fmt(feat['named_all'])} with the named model"
                     if feat.get("named_all") is not None else "") + ".", ""]
    lines += ["## Where (nominal model; feature gap)", ""]
    if report.conventions:
        lines += ["Conventions and set-up mismatches (found in the files, corrected before "
                  "the diagnosis):", ""] + [f"- {c}" for c in report.where["conventions"]] + [""]
    lines += ["Storage of the numbers: " + "; ".join(
                  f"{name}: " + ", ".join(f"{s} {'/'.join(v)}" for s, v in cols.items())
                  for name, cols in list(report.where["storage"].items())[:2])
              + (" ..." if len(report.where["storage"]) > 2 else ""), "",
              f"![where]({FIGURES['where']})", ""]
    w = report.where["nominal"]
    lines += [f"Coherent (FRF) share of the squared normalised differences: "
              f"{_fmt(100 * w['coherent_share'])} %.", "",
              "| group | feature gap |", "|---|---|"]
    for key in ("by_signal", "by_joint", "by_kind", "by_level"):
        for row in w[key]:
            label = ", ".join(f"{k}={v}" for k, v in row.items() if k != "gap")
            lines.append(f"| {label} | {_fmt(row['gap'])} |")
    lines += ["", "Bands where it concentrates:", "",
              "| kind | signal | joint | band | feature gap |",
              "|---|---|---|---|---|"]
    for row in w["top_bands"]:
        lines.append(f"| {row['kind']} | {row['signal']} | {row['joint']} | {row['band']} | "
                     f"{_fmt(row['gap'])} |")
    lines += ["", "## Which effect (each alone, fitted on the calibration data)", "",
              f"![ranking]({FIGURES['ranking']})", "",
              f"Gaps in this table and in the figure: the {m} gap.", "",
              f"| rank | effect | fitted | calibration gap ({m}) | held-out gap ({m}) | "
              f"held-out reduction | runs |",
              "|---|---|---|---|---|---|---|"]
    for i, r in enumerate(report.ranking, 1):
        lines.append(f"| {i} | {' + '.join(r['effects'])} | {_params(r['params'])}{_bound(r)} | "
                     f"{_fmt(r['calibration_gap'])} | {_fmt(r['held_out_gap'])} | "
                     f"{_fmt(100 * r['held_out_reduction'])} % | {r['n_simulations']} |")
    splits = [r for r in report.ranking if r.get("split")]
    if splits:
        lines += ["", "Held-out splits of the time- and state-varying effects (the other "
                  "rows: the default split below):", ""]
        lines += [f"- {' + '.join(r['effects'])}: {r['split']['rule']} ({r['split']['why']})"
                  for r in splits]
    widened = [w for r in report.ranking + report.pairs for w in r.get("widened", [])]
    if widened:
        lines += ["", "Search ranges widened (a best fit on a bound of its range, inside "
                  "the parameter's physical limits):", ""] + \
            [f"- {w}" for w in dict.fromkeys(widened)]
    lines += [f"- {' + '.join(r['effects'])} ranked above {'; '.join(r['preferred_over'])}: "
              f"the simpler (nested) effect is preferred" for r in report.ranking
              if r.get("preferred_over")]
    if report.pairs:
        lines += ["", "Pairs of the top-ranked effects:", "",
                  f"| effects | fitted | calibration gap ({m}) | held-out gap ({m}) | "
                  f"held-out reduction |",
                  "|---|---|---|---|---|"]
        for r in report.pairs:
            lines.append(f"| {' + '.join(r['effects'])} | {_params(r['params'])}{_bound(r)} | "
                         f"{_fmt(r['calibration_gap'])} | {_fmt(r['held_out_gap'])} | "
                         f"{_fmt(100 * r['held_out_reduction'])} % |")
    lines += ["", "## Signals", "", f"![frf]({FIGURES['frf']})", "",
              f"![noise]({FIGURES['noise']})", "",
              "## Nominal model", "",
              f"Arm estimated from the trials ({report.arm['method']} estimator, second-order "
              f"fit, weighted R^2 {np.round(report.arm['r2'], 3).tolist()}): "
              f"M_h={np.round(report.arm['M_h'], 4).tolist()}, "
              f"B_h={np.round(report.arm['B_h'], 4).tolist()}, "
              f"K_h={np.round(report.arm['K_h'], 3).tolist()}"
              + (f" (95 % intervals +- M {np.round(report.arm['ci95']['M_h'], 4).tolist()}, "
                 f"B {np.round(report.arm['ci95']['B_h'], 4).tolist()}, "
                 f"K {np.round(report.arm['ci95']['K_h'], 3).tolist()})"
                 if report.arm.get("ci95") else "")
              + "; sampling and leakage: "
              + (", ".join(f"{k}={v}" for k, v in report.arm.get("corrections", {}).items())
                 or "-") + ".", "",
              f"Split rule: {report.split['rule']}; calibration "
              + ", ".join(f"{u['trial']}[{u['start']}:{u['stop']}]"
                          for u in report.split["calibration"])
              + "; held out " + ", ".join(f"{u['trial']}[{u['start']}:{u['stop']}]"
                                         for u in report.split["held_out"]) + ".", "",
              f"{report.n_simulations} simulations, {report.elapsed_s:.1f} s.", ""]
    if report.gap_in_time:
        from .pipeline.when import markdown as when_lines
        lines += when_lines(report.gap_in_time)
    return "\n".join(lines)


LIMB_UNITS = {"K": "N m/rad", "B": "N m s/rad", "I": "kg m^2"}


def _triple(t) -> str:
    """``"60.1 [59.8, 60.4]"`` (or the value alone without an interval)."""
    v, lo, hi = t
    return _fmt(v, 4) + ("" if lo is None else f" [{_fmt(lo, 4)}, {_fmt(hi, 4)}]")


def residual_sentence(res) -> str:
    """`` The held-out residual, noise floor included: 0.34 -> 0.13 of the torque energy
    (61 % less; floor 0.19) ...`` from ``gap.named_held_out_residual``; "" without one."""
    if not res or res.get("residual_reduction") is None:
        return ""
    text = (f" The held-out residual, noise floor included: {_fmt(res['nominal_residual'])}"
            f" -> {_fmt(res['residual'])} of the torque energy "
            f"({_fmt(100 * res['residual_reduction'], 3)} % less; floor {_fmt(res['floor'])})")
    if res.get("clipped"):
        text += (": it lies below the floor, so the gap reads 0 and its reduction 100 % "
                 "is a bound, not a measurement (the floor holds part of what the model "
                 "explains)")
    return text + "."


def named_model_lines(nm: dict) -> list:
    """The named model in full (report.md): K, B, I and the effect, with intervals."""
    def limb(key):
        t = nm[key]
        joints = [t] if t and not isinstance(t[0], list) else t
        text = ", ".join(_triple(j) for j in joints)
        return f"{key} = {text if len(joints) == 1 else '(' + text + ')'} {LIMB_UNITS[key]}"
    which = ("the limb re-fitted with the effect" if nm["limb_refitted"] else
             "the limb as estimated from the trials (the fit keeps it, not re-fitted)")
    effects = "; ".join(f"{e}: " + ", ".join(
        f"{k} = {_triple(v) if isinstance(v, list) else v}" for k, v in ps.items())
        for e, ps in nm["effects"].items())
    pv = nm.get("parameter_varying")
    at = ("" if not pv else f"; K, B at {pv['scheduling']} = rho_mid = "
          f"{_fmt(nm['effects'][pv['effect']]['rho_mid'][0], 4)} {pv['units']}, "
          f"varying with it: table below")
    lines = [f"Named model ({which}; 95 % intervals in brackets where known{at}): "
             + ", ".join(limb(k) for k in ("K", "B", "I")) + f"; {effects}."]
    for e, fp in (nm.get("form_profile") or {}).items():
        grid = "; ".join(f"{k} in {{{', '.join(str(v) for v in vs)}}}"
                         for k, vs in (fp.get("profiled") or {}).items())
        kept = [a["choice"] for a in fp.get("alternatives") or [] if a.get("kept")]
        lines.append(f"{e}'s intervals include its form: refitted at {grid}; the envelope "
                     f"of the jackknife intervals of {', '.join(kept)} (the choices the data "
                     f"do not reject); point estimate: {fp.get('best_fitting')}"
                     + (" (not the catalogue's tied choice)" if fp.get("point_estimate_changed")
                        else "") + ".")
    lines += [f"Note: {n}." for n in nm.get("notes") or []]
    return lines + [""] + (varying_lines(pv) if pv else [])


def varying_lines(pv: dict) -> list:
    """report.md: K(rho) of the named state-varying model beside ``armimp estimate``'s
    parameter-varying K(rho) (diagnosis.pipeline.state_profile)."""
    u = f" [{pv['units']}]" if pv.get("units") else ""
    est = pv.get("estimate")
    lines = [f"K over {pv['scheduling']}{u} of the named model ({pv['effect']}: "
             f"{pv['form']})" + (f", beside {est['method']}, held-out VAF "
                                 f"{_fmt(est['heldout_vaf_pct']['varying'], 3)} % vs "
                                 f"time-invariant {_fmt(est['heldout_vaf_pct']['invariant'], 3)}"
                                 f" %" if est else
                                 f" (no estimate to compare: {pv.get('estimate_missing')})")
             + ":", "", f"| {pv['scheduling']}{u} | K named model [N m/rad] (95 %) | "
             f"K estimate [N m/rad] (95 %) |", "|---|---|---|"]
    for pt in pv["points"]:
        e = pt.get("K_estimate")
        lines.append(f"| {_fmt(pt['rho'], 4)} | {_triple(pt['K'])} | "
                     + ("-" if e is None else f"{_fmt(e[0], 4)} [{_fmt(e[1], 4)}, "
                        f"{_fmt(e[2], 4)}]") + " |")
    lines += ["", f"![K over {pv['scheduling']}]({FIGURES['varying']})"]
    if pv.get("agreement") is not None:
        lines += ["", f"The named model's K lies inside the estimate's interval at "
                      f"{100 * pv['agreement']:.0f} % of the points (two forms fitted apart: "
                      f"the catalogue's quadratic in limbfit, the estimate's Chebyshev "
                      f"expansion)"
                  + ("" if pv.get("intervals_overlap") is None else
                     f"; the two intervals overlap at {100 * pv['intervals_overlap']:.0f} %")
                  + "."]
    rf = pv.get("reflex") or {}
    if rf.get("named") and rf.get("estimate"):
        a, b = rf["named"], rf["estimate"]
        lines += ["", f"Reflex delay: {_fmt(a['delay_ms'], 3)} ms in the named model "
                      f"(activation {_fmt(a['frequency_hz'], 3)} Hz, damping "
                      f"{_fmt(a['damping'], 2)}: {_fmt(a['effective_ms'], 3)} ms with its "
                      f"low-frequency lag), {_fmt(b['delay_ms'], 3)} ms in the estimate "
                      f"({_fmt(b['frequency_hz'], 3)} Hz, damping {_fmt(b['damping'], 2)}: "
                      f"{_fmt(b['effective_ms'], 3)} ms): the two forms split the lag "
                      f"between the pure delay and the activation differently; neither "
                      f"delay alone is the reflex latency."]
    return lines + [""]


def _plot_where(report, path: Path) -> None:
    result = report.extras["nominal_all"]
    after = report.extras.get("after_all")
    panels = [("nominal model", result)] + ([("with " + " + ".join(report.named), after)]
                                            if after is not None else [])
    cols = []
    for lab in result.labels:
        c = (lab[2], lab[5])
        if c not in cols:
            cols.append(c)
    rows = sorted({(lab[3], lab[4]) for lab in result.labels},
                  key=lambda r: (SIGNALS.index(r[0]) if r[0] in SIGNALS else 9, r[1]))
    fig, axes = plt.subplots(1, len(panels), figsize=(1.0 + 0.75 * len(cols) * len(panels), 4.2),
                             squeeze=False)
    vmax = None
    for ax, (title, res) in zip(axes[0], panels):
        table = res.breakdown("signal", "joint", "kind", "band")
        grid = np.full((len(rows), len(cols)), np.nan)
        for (s, j, k, b), v in table.items():
            grid[rows.index((s, j)), cols.index((k, b))] = v
        shown = np.log10(1.0 + grid)
        vmax = vmax or max(1.0, np.nanmax(shown))
        im = ax.imshow(shown, cmap="magma_r", vmin=0, vmax=vmax, aspect="auto")
        ax.set_xticks(range(len(cols)), [f"{k}\n{b}" for k, b in cols], rotation=90,
                      fontsize=7)
        ax.set_yticks(range(len(rows)), [f"{s}[{j}]" for s, j in rows])
        ax.set_title(f"feature gap by band, {title}", fontsize=9)
        for (i, j), v in np.ndenumerate(grid):
            if np.isfinite(v) and v >= 1:
                ax.text(j, i, f"{v:.0f}", ha="center", va="center", fontsize=6, color="w")
    fig.colorbar(im, ax=axes[0].tolist(), label="log10(1 + feature gap)")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def _bound(row: dict) -> str:
    """Flag for a fit on a search bound (never named)."""
    flags = row.get("at_search_bound") or []
    return f" (at search bound: {'; '.join(flags)})" if flags else ""


def measure_name(gap: dict) -> str:
    """The short name of the measure of a report's top-level gaps (``features`` or an
    experiment's own, e.g. ``limbfit``)."""
    return (gap.get("measure") or "features").split(":")[0].strip()


def ranking_lines(report) -> list:
    """The reference lines of gap_ranking.png, [(value, label)]: in the measure of its
    bars (the ranking's calibration and held-out gaps), never another one."""
    g = report.gap
    m = measure_name(g)
    return [(g["nominal_held_out"], f"nominal, held out ({m})"),
            (g["significance_threshold"], f"significance of the nominal gap ({m})")]


def _plot_varying(pv: dict, path: Path) -> None:
    """K over the scheduling variable: the named model's curve, the estimate's with its
    95 % band (diagnosis.pipeline.state_profile)."""
    rho = np.array([p["rho"] for p in pv["points"]])
    fig, ax = plt.subplots(figsize=(6, 3.8))
    est = [p.get("K_estimate") for p in pv["points"]]
    if all(e is not None for e in est):
        e = np.array(est, float)
        ax.fill_between(rho, e[:, 1], e[:, 2], alpha=0.25, label="estimate, 95 %")
        ax.plot(rho, e[:, 0], "o-", ms=3, label="armimp estimate (parameter-varying)")
    named = np.array([[np.nan if v is None else v for v in p["K"]] for p in pv["points"]],
                     float)
    if np.isfinite(named[:, 1:]).all():
        ax.fill_between(rho, named[:, 1], named[:, 2], color="k", alpha=0.1,
                        label="named model, 95 %")
    ax.plot(rho, named[:, 0], "k--", label=f"named model ({pv['effect']})")
    u = f" [{pv['units']}]" if pv.get("units") else ""
    ax.set_xlabel(f"{pv['scheduling']}{u}")
    ax.set_ylabel("K [N m/rad]")
    ax.set_title("Stiffness over the scheduling variable", fontsize=10)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def _plot_ranking(report, path: Path) -> None:
    rows = report.ranking + report.pairs
    names = [" + ".join(r["effects"]) for r in rows]
    held = np.array([r["held_out_gap"] for r in rows], float)
    cal = np.array([r["calibration_gap"] for r in rows], float)
    g = report.gap
    top = max(g["nominal_held_out"], g["nominal_calibration"], 1e-3) * 1.5
    fig, ax = plt.subplots(figsize=(7, 0.35 * len(rows) + 1.5))
    y = np.arange(len(rows))
    ax.barh(y - 0.2, np.minimum(np.nan_to_num(cal, posinf=top), top), 0.4,
            label="calibration (fit)")
    ax.barh(y + 0.2, np.minimum(np.nan_to_num(held, posinf=top), top), 0.4,
            label="held out")
    for (value, label), style in zip(ranking_lines(report), ({"color": "k", "ls": "--"},
                                                              {"color": "r", "ls": ":"})):
        ax.axvline(value, label=label, **style)
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel(f"{measure_name(g)} gap (0 = explained; bars clipped; diverging models "
                  f"at the edge)")
    ax.legend(fontsize=7, loc="lower right")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def _plot_signals(report, frf_path: Path, noise_path: Path) -> None:
    """Bode plot (|H| and phase) from the experiment's perturbation to each compared
    signal, measured / nominal / named model, and the signals' spectra."""
    trials = report.extras["trials"]
    ev = report.extras["ev_all"]
    chosen = report.extras.get("chosen")
    experiment = report.extras["experiment"]
    trial = trials[0]
    k = trial.perturbed_dof or 1
    from .evaluation import Unit
    unit = Unit(trial, 0, trial.n_samples, "all")
    source = experiment.perturbation_signal(trial)
    signals = [s for s in experiment.output_signals(trial) if s != source]
    runs = [("measured", trial), ("nominal", ev.simulation(unit, {}))]
    if chosen is not None:
        ev_named = report.extras.get("ev_named") or ev
        runs.append(("with " + " + ".join(chosen.effects),
                     ev_named.simulation(unit, chosen.simulation_effects(trial.n_dof))))
    nper = ev.cfg.features.nperseg
    cols = len(signals)
    fig, axes = plt.subplots(2, cols, figsize=(4 * cols + 1, 6), sharex=True, squeeze=False)
    fig2, axes2 = plt.subplots(1, cols, figsize=(4 * cols + 1, 3.5), squeeze=False)
    axes2 = axes2[0]
    for col, s in enumerate(signals):
        for label, run in runs:
            if run is None:
                continue
            x, y = run.signal(source)[:, k - 1], run.signal(s)[:, k - 1]
            f, pxy = sps.csd(x, y, fs=run.fs, nperseg=nper)
            _, pxx = sps.welch(x, fs=run.fs, nperseg=nper)
            _, pyy = sps.welch(y, fs=run.fs, nperseg=nper)
            band = (f > 0) & (f <= 40)
            h = pxy[band] / pxx[band]
            axes[0, col].loglog(f[band], np.abs(h), label=label)
            axes[1, col].semilogx(f[band], np.degrees(np.angle(h)), label=label)
            axes2[col].loglog(f[1:], pyy[1:], label=label, lw=0.8)
        axes[0, col].set_title(f"{source}[{k}] -> {s}[{k}]")
        axes[1, col].set_xlabel("frequency [Hz]")
        axes2[col].set_title(f"spectrum of {s}[{k}] [{UNITS[s]}^2/Hz]")
        axes2[col].set_xlabel("frequency [Hz]")
    axes[0, 0].set_ylabel("|H|")
    axes[1, 0].set_ylabel("phase [deg]")
    axes[0, 0].legend(fontsize=7)
    axes2[0].legend(fontsize=7)
    fig.suptitle(f"FRFs of trial {trial.name}")
    fig.savefig(frf_path, dpi=100, bbox_inches="tight")
    fig2.savefig(noise_path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    plt.close(fig2)


def write_set_index(result, out_dir) -> Path:
    """The index of a diagnosis over several conditions: ``report.md`` and
    ``report.json`` beside one report folder per condition."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lines = ["# Sim-to-real gap diagnosis, one report per condition", "",
             "| condition | verdict | named | fitted | held-out reduction | nominal gap |",
             "|---|---|---|---|---|---|"]
    for c, r in result.reports.items():
        red = r.gap.get("named_held_out_reduction")
        folder = r.out_dir.name if r.out_dir is not None else c
        lines.append(f"| [{c}]({folder}/report.md) | {r.verdict} | {' + '.join(r.named) or '-'} | "
                     f"{_params(r.fitted) or '-'} | "
                     f"{'-' if red is None else _fmt(100 * red) + ' %'} | "
                     f"{_fmt(r.gap['nominal_all'])} ({measure_name(r.gap)}) |")
    lines += [""] + [f"- **{c}**: {r.summary}" for c, r in result.reports.items()] + [""]
    lines += [f"Note: {n}." for n in getattr(result, "notes", [])]
    if getattr(result, "grouping", None):
        lines += ["", result.grouping, ""]
    _atomic_text(out / "report.json", json.dumps(_clean(
        {"format": "arm-impedance-diagnosis-set/1",
         "conditions": {c: {"report": f"{r.out_dir.name if r.out_dir else c}/report.json",
                            "verdict": r.verdict, "named_effects": r.named,
                            "indistinguishable": r.indistinguishable,
                            "fitted_parameters": r.fitted,
                            "named_model": r.named_model, "gap": r.gap}
                        for c, r in result.reports.items()}}), indent=2))
    _atomic_text(out / "report.md", "\n".join(lines))
    return out / "report.md"
