"""The lab estimator's parameter-varying hook: when a trial has a scheduling variable
(trialformat.scheduling) that spreads beyond the perturbation, or one the user named,
:func:`varying_of_trials` fits K, B, I (and the reflex gain with ``--reflex``) over it
(estimation.varying) and says what it found; a variable that cannot be used keeps the
time-invariant answer, with a warning naming it and what would work.

It also gives the torque-sign finding of a moving joint (:func:`sign_warnings`): the
inertia I(rho), which dominates the torque at the top of the band and is the best
determined parameter there, is negative over the whole visited range exactly when the
torque's sign is reversed; a stiffness that changes with the angle is not evidence of
a sign either way.
"""

from __future__ import annotations

import numpy as np

from .errors import EstimationError


def _sched(trial):
    from trialformat.scheduling import scheduling_of
    try:
        return scheduling_of(trial), None
    except Exception as exc:  # SchedulingError: refused at reading when named
        return None, str(exc)


def varying_of_trials(trials, options) -> tuple[list, list]:
    """``(fits, warnings)``: a :class:`estimation.varying.VaryingResult` for each one-joint
    trial of ``trials`` whose scheduling variable is named (requested or declared) or
    moves beyond its perturbation (not :func:`trialformat.scheduling.narrow_range`), and
    one warning per trial whose named variable could not be used (the time-invariant
    estimate is kept). ``options``: AnalysisOptions (its ``reflex``)."""
    from trialformat.scheduling import varying_refusal
    from .reflex import ReflexOptions
    from .varying import VaryingError, fit_varying
    fits, notes = [], []
    ropt = None
    if getattr(options, "reflex", None):
        ropt = options.reflex if isinstance(options.reflex, ReflexOptions) else ReflexOptions()
    for t in trials:
        s, err = _sched(t)
        if s is None:
            if err:
                notes.append(f"parameter-varying fit not done for {t.name}: {err}")
            continue
        named = s.note is None  # requested or declared (a default carries its note)
        if t.n_dof != 1:
            if named:
                notes.append(f"parameter-varying fit not done for {t.name}: it is for one "
                             f"joint; {t.name!r} has {t.n_dof}")
            continue
        refusal = varying_refusal(s, t.name)  # the same refusal as diagnose's
        if refusal:
            if named:
                notes.append(refusal)
            continue
        try:
            fit = fit_varying(t.theta[:, 0], t.tau_h[:, 0], s.values, t.fs, name=s.name,
                              units=s.units, source=s.source, reflex=ropt,
                              is_time=s.name == "time")
        except (VaryingError, EstimationError, np.linalg.LinAlgError) as exc:
            notes.append(f"parameter-varying fit not done for {t.name}: {exc}; the "
                         f"time-invariant estimate is kept")
            continue
        fit.trial = t.name
        fits.append(fit)
    return fits, notes


def sign_warnings(fits, trials) -> list:
    """A ``torque sign reversed?`` warning for each fit whose I(rho) interval lies below 0
    over the whole range (module docstring), naming the key to declare."""
    out = []
    by_name = {t.name: t for t in trials}
    for f in fits:
        if not np.all(f.hi["I"] < 0):
            continue
        t = by_name.get(getattr(f, "trial", None))
        now = int(((t.meta.get("sensors") or {}).get("torque_sign", 1)) if t else 1)
        out.append(f"torque sign reversed? Z: I({f.scheduling}) negative over the whole "
                   f"range ({np.min(f.values['I']):.4g}..{np.max(f.values['I']):.4g} kg m^2; "
                   f"the inertia dominates the torque at the top of the band). If the "
                   f"torque sensor's sign is opposite to the angle's, declare "
                   f"\"sensors\": {{\"torque_sign\": {-now}}} in the metadata or the .mat's "
                   f"sidecar NAME.json (now {now}), or give --torque-sign {-now}; the reader "
                   f"then negates tau_h")
    return out


def varying_json(fits) -> dict | None:
    """The ``parameter_varying`` entry of results.json: the first fit's document (with its
    ``trial``), the others under ``"others"``; None without a fit."""
    if not fits:
        return None
    docs = [{**f.to_json(), "trial": getattr(f, "trial", "")} for f in fits]
    out = docs[0]
    if len(docs) > 1:
        out["others"] = docs[1:]
    return out


def describe_varying(fits) -> list:
    return [f.describe(getattr(f, "trial", "")) for f in fits]


def plot_varying(fit, path) -> None:
    """K(rho), B(rho), I(rho) (and G(rho)) with their interval bands and the time-invariant
    value (dashed, its interval shaded lighter): one panel each, saved to ``path``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from .varying import NAMES, UNITS
    params = fit.params
    fig, axes = plt.subplots(len(params), 1, figsize=(6.4, 2.1 * len(params) + 0.6),
                             sharex=True)
    for ax, p in zip(np.atleast_1d(axes), params):
        ax.fill_between(fit.rho, fit.lo[p], fit.hi[p], color="tab:blue", alpha=0.25,
                        label=f"{int(round(100 * fit.confidence))} % interval")
        ax.plot(fit.rho, fit.values[p], color="tab:blue", label="parameter-varying")
        v, lo, hi = fit.invariant[p]
        ax.axhspan(lo, hi, color="0.5", alpha=0.15)
        ax.axhline(v, color="0.3", ls="--", lw=1, label="time-invariant")
        ax.set_ylabel(f"{p} [{UNITS[p]}]")
        ax.set_title(NAMES[p], fontsize=9, loc="left")
    units = f" [{fit.units}]" if fit.units else ""
    np.atleast_1d(axes)[-1].set_xlabel(f"{fit.scheduling}{units}")
    np.atleast_1d(axes)[0].legend(fontsize=7, loc="best")
    h = fit.heldout_vaf_pct
    fig.suptitle(f"{getattr(fit, 'trial', '')}: impedance over {fit.scheduling} "
                 f"(order {fit.order}; held-out VAF {h['varying']:.1f} % vs "
                 f"time-invariant {h['invariant']:.1f} %)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_varying_files(result, folder, stem) -> list:
    """``pv_STEM.png`` (:func:`plot_varying`) and ``pv_STEM.csv`` (rho, then each
    parameter's value, lo, hi) for each parameter-varying fit of ``result`` (LabResult);
    a second trial's files get ``_TRIAL`` appended. Returns the paths written."""
    import csv
    from pathlib import Path
    paths = []
    for k, fit in enumerate(getattr(result, "varying", None) or []):
        name = f"pv_{stem}" + (f"_{fit.trial}" if k else "")
        png = Path(folder) / f"{name}.png"
        plot_varying(fit, png)
        table = Path(folder) / f"{name}.csv"
        with open(table, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            units = f" [{fit.units}]" if fit.units else ""
            w.writerow([f"{fit.scheduling}{units}"] + [f"{p}{s}" for p in fit.params
                                                       for s in ("", "_lo", "_hi")])
            for i, r in enumerate(fit.rho):
                w.writerow([repr(float(r))] + [repr(float(getattr(fit, a)[p][i]))
                                               for p in fit.params
                                               for a in ("values", "lo", "hi")])
        paths += [png, table]
    return paths
