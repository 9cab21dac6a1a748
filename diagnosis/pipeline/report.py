"""Stage 9, report: the :class:`DiagnosisReport` and, with an out folder, the report
folder (report.md, report.json, PNG plots) written whole or not at all."""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from trialformat import logs as tf

from .. import catalogue as cat
from ..errors import DiagnosisInputError
from ..report import DiagnosisReport, write_report
from .resume import CACHE_DIR


def build(r) -> DiagnosisReport:
    """The report of the run ``r`` (every earlier stage done)."""
    chosen = r.chosen
    n_parent_sims = len(r.trials) * (2 if chosen is not None else 1)
    model = r.model.to_dict()
    behind = None if chosen is None else r.experiment.model_with(
        r.model, chosen.simulation_effects(r.n_dof))
    model["behind_named_compliance"] = None if behind is None else behind.to_dict()
    if chosen is not None and chosen.model is not None:
        model["with_named_effect"] = chosen.model.to_dict()
    from .how_far import reduction
    fitted = {} if chosen is None else chosen.params
    intervals = {} if chosen is None or not chosen.intervals else chosen.intervals
    ranking, pair_rows = r.ranking, r.pair_rows
    alternatives = list(getattr(r, "alternative_rows", []) or [])
    if r.units:
        # the trials were rescaled (conventions.normalise_units): values back in the
        # file's units (impedances, gains and masses scale with tau_h / theta)
        rho = r.units["tau_h"] / r.units["theta"]
        model = _impedance_dict(model, rho)
        fitted = _effects_in_units(fitted, rho)
        intervals = _effects_in_units(intervals, rho)
        ranking = [_row_in_units(row, rho) for row in ranking]
        pair_rows = [_row_in_units(row, rho) for row in pair_rows]
        alternatives = [{**a, "params": _effects_in_units(a.get("params") or {}, rho)}
                        for a in alternatives]
    profile = None if chosen is None else getattr(chosen, "form_profile", None)
    if r.units and profile:
        profile = _profile_in_units(profile, r.units["tau_h"] / r.units["theta"])
    named = None if chosen is None else named_model(model, fitted, intervals, profile)
    scheduling = [u for u in r.scheduling if u["trial"] in {t.name for t in r.trials}]
    if named is not None and r.experiment.kind == "position":
        from .state_profile import profile as state_profile
        # K(rho) beside estimate's; its band from the fit's jackknife replicates (in the
        # fit's units: none when the trials were rescaled)
        reps = None if r.units else getattr(chosen, "replicates", None)
        pv = state_profile(r.trials, named, scheduling, reps)
        if pv is not None:
            named["parameter_varying"] = pv
    return DiagnosisReport(
        named_model=named,
        verdict=r.verdict, named=r.named, summary=r.summary, amplitude=r.amplitude,
        indistinguishable=list(getattr(r, "indistinguishable", [])),
        alternatives=alternatives,
        conventions=[f.to_dict() for f in r.findings], numerics=r.numerics,
        timing={"workers": r.workers,
                "scheduler": None if r.scheduler is None else str(r.scheduler),
                "phases": r.timings,
                "resumed_tasks": 0 if r.resume is None else r.resume.n_reused,
                # cache entries found unreadable (a truncated .npz) and recomputed
                "recomputed_unreadable_cache_entries":
                    0 if r.resume is None else getattr(r.resume, "n_corrupt", 0)},
        fitted=fitted, intervals=intervals, ranking=ranking, pairs=pair_rows,
        gap=gap_block(r, chosen, reduction),
        where=r.where, arm=model, gap_in_time=r.when,
        split={"rule": r.rule,
               "calibration": [{"trial": u.trial.name, "start": u.start, "stop": u.stop}
                               for u in r.cal],
               "held_out": [{"trial": u.trial.name, "start": u.start, "stop": u.stop}
                            for u in r.held]},
        config=r.config.to_dict(), grouping=r.grouping,
        scheduling=scheduling,
        n_simulations=n_parent_sims + r.n_worker_sims,
        elapsed_s=time.perf_counter() - r.t0, trials=[t.name for t in r.trials],
        experiment={**r.experiment.describe(), "simulated_by": simulated_by(r),
                    "effects_tried": list(r.effects),
                    "effects_not_applicable": list(r.skipped_effects)},
        extras={"nominal_all": r.nominal_all, "after_all": r.after, "ev_all": r.ev_all,
                "ev_named": r.ev_named,
                "chosen": chosen, "trials": r.trials, "experiment": r.experiment})


def simulated_by(r) -> str:
    """What re-simulated the trials: the plant FMU given, the built-in plant, or the
    experiment's own model (a position or rendered-impedance experiment)."""
    if not r.experiment.uses_plant:
        return {"position": "diagnosis.limb (the limb model driven by the measured angle)",
                "rendered": "the rendered impedance M_rd, B_rd, K_rd"}.get(
            r.experiment.kind, type(r.experiment).__name__)
    from orchestrator.trial import env_plant_parameters, plant_kind
    values = env_plant_parameters()
    shown = "" if not values else " with " + ", ".join(f"{k} = {v:g}" for k, v in values.items())
    if r.plant is not None:
        return f"plant FMU {getattr(r.plant, 'path', r.plant)}{shown}"
    return f"built-in plant: {plant_kind()}{shown}"


FEATURE_MEASURE = ("features: mean squared normalised difference of the FRF, noise, static "
                   "and grid features above what noise gives (diagnosis.gap)")


def gap_block(r, chosen, reduction) -> dict:
    """The report's ``gap``: every top-level number in ONE measure, the one the which /
    how-far / verdict stages rank and name by (``measure``); for an experiment with its
    own fit measure (the position servo's limbfit), the where stage's feature gap is
    given apart under ``features``, never mixed with it."""
    features = {"measure": FEATURE_MEASURE, "nominal_all": r.nominal_all.value,
                "significance_threshold": r.config.significance_gap,
                "significant": bool(r.nominal_all.value > r.config.significance_gap),
                "named_all": None if r.after is None else r.after.value}
    fm = r.fit_measure
    top = {"measure": FEATURE_MEASURE if not fm else fm["measure"],
           "nominal_all": r.nominal_all.value if not fm else fm["g0_all"],
           "nominal_calibration": r.g0_cal, "nominal_held_out": r.g0_held,
           "significance_threshold": r.config.significance_gap if not fm else fm["threshold"],
           "significant": bool(r.significant),
           "named_calibration": None if chosen is None else chosen.calibration_gap,
           "named_held_out": None if chosen is None else chosen.held_out_gap,
           "named_held_out_reduction": None if chosen is None else
           reduction(r.g0_held, chosen.held_out_gap),
           # the named fit's held-out residual with the floor in it, on its split: the
           # gap is clipped at the floor, so "100 %" alone may be a bound (issue 21)
           "named_held_out_residual": None if chosen is None else
           getattr(chosen, "held_out_residual", None),
           # the named model on all data: in the feature measure only (limbfit gives the
           # calibration and held-out parts)
           "named_all": (None if r.after is None else r.after.value) if not fm else None}
    if fm:
        # which evidence the floor came from (issue 21 item 1; limbfit.FLOOR_*)
        top["noise_floor"] = fm.get("noise_floor")
        top["noise_floor_source"] = fm.get("noise_floor_source")
        # the records the shared time-variation test made significant (limbfit.time_gate)
        top["changing_in_time"] = fm.get("changing_in_time", [])
        # the model tolerance the threshold adds, and per record (limbfit: measured)
        for k in ("model_tolerance", "model_tolerance_source", "model_tolerance_per_record"):
            if k in fm:
                top[k] = fm[k]
        top["features"] = features
        top["fit_measure"] = fm
    return top


def _triples(values, half=None):
    """[value, low, high] per joint (the diagonal of an (n, n) matrix) from ``half``
    (95 % half-widths, same shape, or None: no interval); one triple for one joint."""
    v = np.atleast_2d(np.asarray(values, float))
    h = None if half is None else np.atleast_2d(np.asarray(half, float))
    rows = [[float(v[i, i])] + ([None, None] if h is None else
                                [float(v[i, i] - h[i, i]), float(v[i, i] + h[i, i])])
            for i in range(v.shape[0])]
    return rows[0] if len(rows) == 1 else rows


def named_model(model: dict, fitted: dict, intervals: dict, form_profile=None) -> dict:
    """The named model in full (issue 21, item 6): the limb's K, B, I as the named model
    simulates it, each ``[value, low, high]`` (95 %; per joint for several joints; low
    and high None where no interval is known), and every named effect's parameters
    likewise, ``{effect: {param: [value, low, high]}}``; a discrete choice (a reflex
    rectified or not) as its value. ``limb_refitted``: True when the fit re-estimated
    the limb with the effect (the position servo's limbfit), False when the named model
    keeps the limb estimated from the trials (the exoskeleton's fits).

    ``model``, ``fitted``, ``intervals``: the report's arm dict and the named fit's
    parameters and intervals, in the file's units. ``form_profile`` ({effect: record of
    diagnosis.formprofile.profile}, or None): the intervals are envelopes over refits at
    the tied choices' alternatives; given as ``form_profile`` {effect: {"profiled",
    "best_fitting", "point_estimate_changed", "jackknife_intervals", "alternatives",
    "rule"}}, and a tied choice (a damping) is shown as a value."""
    from ..formprofile import FORM_GRID
    limb = model.get("with_named_effect")
    refitted = isinstance(limb, dict)
    limb = limb if refitted else model
    ci = limb.get("ci95") or {}
    out = {"limb_refitted": refitted, "method": limb.get("method"),
           "K": _triples(limb["K_h"], ci.get("K_h")), "B": _triples(limb["B_h"], ci.get("B_h")),
           "I": _triples(limb["M_h"], ci.get("M_h")), "effects": {}}
    for effect, params in (fitted or {}).items():
        cis = (intervals or {}).get(effect) or {}
        choices = dict(cat.get_effect(effect).choices) if effect in cat.CATALOGUE else {}
        choices.update(FORM_GRID.get(effect, {}))
        out["effects"][effect] = {
            k: v if isinstance(v, (bool, str)) or k in choices else
            [float(v)] + ([float(c) for c in cis[k]] if k in cis else [None, None])
            for k, v in params.items()}
    notes = _reflex_notes(out["effects"].get("stretch_reflex"))
    if len(out["effects"]) > 1 and intervals and not form_profile:
        notes.append("a pair's intervals are its one-step delete-one-block jackknife at the "
                     "form the fit ties (limbpairs.add_intervals): the form's own "
                     "uncertainty (a reflex's activation damping) is not in them, so they are "
                     "narrower than the single effects' form-profiled ones (the form is "
                     "profiled, limbpairs.profile_pair, with at most search_trials records)")
    if notes:
        out["notes"] = notes
    if form_profile:
        out["form_profile"] = {
            e: {k: rec.get(k) for k in ("profiled", "best_fitting", "point_estimate_changed",
                                       "jackknife_intervals", "alternatives", "rule",
                                       "delay_resolution_s", "jackknife_limb_ci",
                                       "derivative_allowance")}
            for e, rec in form_profile.items() if rec}
    return out


def reflex_latency(p: dict | None) -> dict | None:
    """``{"delay_ms", "frequency_hz", "damping", "effective_ms"}`` of a named stretch
    reflex (``named_model`` effect entry, values as ``[value, lo, hi]`` or plain): the pure
    delay and the delay plus its activation's low-frequency group delay 2 zeta / omega_n
    (the tied damping, diagnosis.limb, unless the form profile chose another)."""
    if not p:
        return None
    from estimation.reflex import activation_lag_ms
    from ..limb import DEFAULTS
    v = {k: (x[0] if isinstance(x, list) else x) for k, x in p.items()}
    zeta = float(v.get("damping", DEFAULTS["stretch_reflex"]["damping"]))
    d, f = 1e3 * float(v["delay_s"]), float(v["frequency_hz"])
    return {"delay_ms": d, "frequency_hz": f, "damping": zeta,
            "effective_ms": d + activation_lag_ms(f, zeta)}


def _reflex_notes(p: dict | None) -> list:
    """The named reflex's delay against the reported latencies (estimation.reflex)."""
    lat = reflex_latency(p)
    if lat is None:
        return []
    from estimation.reflex import latency_warning
    w = latency_warning(lat["delay_ms"], lat["frequency_hz"], lat["damping"])
    return [w] if w else []


def _profile_in_units(profile: dict, rho: float) -> dict:
    """{effect: form-profile record} with its parameters and intervals in the file's
    units (impedance-like ones times rho)."""
    out = {}
    for e, rec in (profile or {}).items():
        if not rec:
            out[e] = rec
            continue
        rec = dict(rec)
        conv = lambda d: _effects_in_units({e: d}, rho)[e] if d else d  # noqa: E731
        rec["intervals"] = conv(rec.get("intervals"))
        rec["jackknife_intervals"] = conv(rec.get("jackknife_intervals"))
        for key in ("jackknife_limb_ci", "derivative_allowance"):  # a pair's (profile_pair)
            if rec.get(key):
                rec[key] = {k: (np.asarray(v, float) * rho).tolist()
                            for k, v in rec[key].items()}
        rec["alternatives"] = [{**a, "params": conv(a.get("params")),
                                "intervals": conv(a.get("intervals"))}
                               for a in rec.get("alternatives") or []]
        out[e] = rec
    return out


#: units of the values that scale with tau_h / theta when the trials were rescaled
IMPEDANCE_UNITS = ("N m/rad", "N m s/rad", "kg m^2", "N m s^2/rad")


def _impedance_dict(model: dict, rho: float) -> dict:
    out = dict(model)
    for k in ("K_h", "B_h", "M_h"):
        if k in out:
            out[k] = (np.asarray(out[k], float) * rho).tolist()
    if out.get("ci95"):
        out["ci95"] = {k: (np.asarray(v, float) * rho).tolist() for k, v in out["ci95"].items()}
    for k in ("with_named_effect", "behind_named_compliance"):
        if isinstance(out.get(k), dict):
            out[k] = _impedance_dict(out[k], rho)
    return out


def _effects_in_units(effects: dict, rho: float) -> dict:
    """{effect: {param: value or [low, high]}} with impedance-like parameters (catalogue
    units in IMPEDANCE_UNITS) times rho."""
    out = {}
    for name, params in (effects or {}).items():
        units = {p.name: p.unit for p in cat.get_effect(name).parameters} \
            if name in cat.CATALOGUE else {}
        out[name] = {k: ((np.asarray(v, float) * rho).tolist() if isinstance(v, (list, tuple))
                         else v * rho) if units.get(k) in IMPEDANCE_UNITS else v
                     for k, v in (params or {}).items()}
    return out


def _row_in_units(row: dict, rho: float) -> dict:
    row = dict(row)
    row["params"] = _effects_in_units(row.get("params") or {}, rho)
    if row.get("intervals"):
        row["intervals"] = _effects_in_units(row["intervals"], rho)
    if row.get("form_profile"):
        row["form_profile"] = _profile_in_units(row["form_profile"], rho)
    if row.get("flag_notes") is not None:  # the flags with the values shown beside them
        from ..fitting import format_flags
        row["at_search_bound"] = format_flags(row["flag_notes"], row["params"])
    if row.get("widenings"):  # the ranges searched, in the file's units too
        from ..fitting import widening_note
        row["widened"] = [widening_note(*w, scale=_param_scale(w[0], w[1], rho))
                          for w in row["widenings"]]
        row["searched"] = _effects_in_units(row.get("searched") or {}, rho)
    return row


def _param_scale(effect: str, param: str, rho: float) -> float:
    """rho for an impedance-like parameter (IMPEDANCE_UNITS), else 1."""
    units = {p.name: p.unit for p in cat.get_effect(effect).parameters}
    return rho if units.get(param) in IMPEDANCE_UNITS else 1.0


def run(r) -> None:
    """Fill ``r.report``; write it when ``r.out_dir`` is set (atomically, see
    :func:`write_atomically`)."""
    from .when import add_named
    add_named(r)  # the named model's gap per time block, beside the nominal's
    r.report = build(r)
    if r.out_dir is not None:
        r.report.out_dir = Path(r.out_dir)
        write_atomically(r.report, r.out_dir, r.resume)


def check_out_dir(out_dir, source) -> None:
    """Refuse an out folder that would overwrite what the user wrote: an existing file,
    a folder that is not an earlier diagnosis report (not empty, no ``report.json``), or
    the trials' own folder (or one of its parents).

    Raises
    ------
    DiagnosisInputError
        Naming the folder and why.
    """
    out = Path(out_dir)
    try:  # below a file: refused before anything runs (not an OS error at the end)
        from trialformat.logs import check_out_parent
        check_out_parent(out, "--out")
    except ValueError as exc:
        raise DiagnosisInputError(str(exc)) from None
    if out.exists() and not out.is_dir():
        raise DiagnosisInputError(f"--out {out}: exists and is a file, not a report folder; "
                                  f"choose another path")
    sources = [Path(source)] if isinstance(source, (str, os.PathLike)) else \
        [Path(p).parent for p in source]
    for s in sources:
        s_dir = s if s.is_dir() else s.parent
        try:
            if s_dir.resolve() == out.resolve() or out.resolve() in s_dir.resolve().parents:
                raise DiagnosisInputError(
                    f"--out {out}: is the trials' folder {s_dir} (or holds it); the report "
                    f"would replace the measured trials; choose another folder")
        except OSError:
            pass
    if out.is_dir() and not _diagnosis_folder(out, depth=1):
        names = {p.name for p in out.iterdir()}
        if names:
            raise DiagnosisInputError(
                f"--out {out}: the folder exists and holds files that are not a diagnosis "
                f"report ({', '.join(sorted(names)[:5])}{' ...' if len(names) > 5 else ''}); "
                f"it would be replaced: choose a new or an earlier report folder")


def _diagnosis_folder(folder: Path, depth: int) -> bool:
    """An earlier diagnosis report (``report.json``), a killed run's resume store, or
    (``depth`` 1) a folder of such per-condition reports, as a killed diagnosis of several
    conditions leaves it: one that a re-run may replace."""
    names = {p.name for p in folder.iterdir()}
    if not names or "report.json" in names or names == {CACHE_DIR}:
        return True
    if depth <= 0:
        return False
    return all(p.is_dir() and (p.name.startswith(".") or _diagnosis_folder(p, depth - 1))
               for p in folder.iterdir())


def write_atomically(report, out_dir, resume=None) -> Path:
    """Write the report into a temporary sibling folder, then swap it in place of
    ``out_dir`` (trialformat.replace_dir): a crash or a full disk leaves the previous
    report whole. The resume store moves into the new folder; the folder and its files
    get the user's umask."""
    out = Path(out_dir)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))
    try:
        os.chmod(tmp, 0o777 & ~tf.current_umask())
        write_report(report, tmp)
        if resume is not None:
            resume.keep_only_current()
            if resume.root.is_dir():
                os.replace(resume.root, tmp / CACHE_DIR)
        tf.replace_dir(tmp, out, kind="diagnosis")
    except BaseException:
        import shutil
        if (tmp / CACHE_DIR).is_dir() and resume is not None and not resume.root.exists():
            os.replace(tmp / CACHE_DIR, resume.root)  # keep what was computed
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out / "report.md"
