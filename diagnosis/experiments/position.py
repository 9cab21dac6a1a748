"""A position-controlled apparatus (``perturbation.kind = "position"``, log-format.md).

An actuator servo imposes the perturbation on the joint(s); a torque sensor between
actuator and limb measures ``tau_h``. The diagnosis re-simulates the limb model
(``diagnosis.limb``: intrinsic K, B, I per joint plus the catalogue's limb and apparatus
effects):

- with a recorded reference ``theta_ref[j]``: the servo tracks it,
  ``theta, tau_h = limb.servo_response(theta_ref, fs, limb, effects)``; the features are
  the FRFs ``theta_ref -> theta`` and ``theta_ref -> tau_h``;
- without one (archived data such as the reklab ankle recordings): the measured angle
  drives the limb, ``tau_h = limb.limb_torque(theta, fs, limb, effects)``; the feature is
  the FRF ``theta -> tau_h`` (the joint's impedance).

Only the coherent (FRF) features are compared: the limb's own torque not coherent with
the perturbation (voluntary activity, sensor noise) is not modelled, so its spectrum is
no evidence for or against a model. The limb is estimated as ``armimp estimate`` does
(``direct`` method from theta to tau_h without a reference, ``full`` with one), with the
sampling the trials declare (real recordings: instantaneous).
"""

from __future__ import annotations

import numpy as np

import trialformat as tf

from ..arm import estimate_arm
from ..errors import DiagnosisInputError
from .base import Experiment


class PositionServo(Experiment):
    """Position servo with a torque sensor between actuator and limb (any n >= 1)."""

    kind = "position"
    title = "position servo imposes the angle, torque sensor between actuator and limb"
    declared_keys = ("fs", "n_dof")
    feature_kinds = ("frf",)
    #: only the best fit can be named (pipeline.verdict.choose; as limbfit's verdict)
    name_best_fit_only = True
    scale_free = True

    @classmethod
    def accepts(cls, trials) -> bool:
        return all(t.perturbation_kind == "position" for t in trials)

    def check_metadata(self, trials) -> None:
        with_ref = {t.name: t.theta_ref is not None for t in trials}
        if len(set(with_ref.values())) > 1:
            raise DiagnosisInputError(
                f"position trials with and without a recorded theta_ref in one diagnosis "
                f"({with_ref}): one experiment either tracks a reference or not")

    def __init__(self, trials):
        super().__init__(trials)
        self.with_reference = all(t.theta_ref is not None for t in trials)

    def not_applicable(self, name: str) -> str | None:
        """Also: ``servo_bandwidth`` needs a recorded reference (the servo tracks it)."""
        why = super().not_applicable(name)
        if why is None and name == "servo_bandwidth" and not self.with_reference:
            return ("needs a recorded theta_ref (the servo's reference); these position "
                    "trials have none, the measured angle drives the limb")
        return why

    def perturbation_signal(self, trial) -> str:
        return "theta_ref" if trial.theta_ref is not None else "theta"

    def output_signals(self, trial) -> tuple:
        return ("theta", "tau_h") if trial.theta_ref is not None else ("tau_h",)

    def estimate(self, trials):
        return estimate_arm(trials)

    def simulator(self, model, *, plant=None, rk4_step=None):
        from .. import limb as lm
        limb = limb_of(model)

        def simulate(trial, effects, n_samples):
            n = int(n_samples)
            fs = trial.fs
            # a varying stiffness as reported (K0 and its relative change, rebuilt from
            # the trial's schedule or time: varying_effects.factor); the switching's and
            # the modulation's are not reported in full, their limb runs time-invariant
            from .. import varying_effects as vary
            factor = None
            for k, v in (effects or {}).items():
                f = vary.factor(trial, k, v, n) if k in vary.EFFECTS else None
                if f is not None:
                    factor = f if factor is None else factor * f
            effects = {k: v for k, v in (effects or {}).items() if k not in vary.EFFECTS}
            try:
                if trial.theta_ref is not None:
                    theta, tau = lm.servo_response(trial.theta_ref[:n], fs, limb, effects or {},
                                                   factor)
                else:
                    theta = np.array(trial.theta[:n], dtype=float)
                    tau = lm.limb_torque(theta, fs, limb, effects or {}, factor)
            except (FloatingPointError, OverflowError, np.linalg.LinAlgError):
                return None
            theta, tau = np.asarray(theta, float), np.asarray(tau, float)
            if not (np.isfinite(theta).all() and np.isfinite(tau).all()):
                return None
            return tf.Trial(meta=trial.meta, t=trial.t[:n], theta=theta.reshape(n, -1),
                            tau_h=tau.reshape(n, -1),
                            theta_ref=None if trial.theta_ref is None else trial.theta_ref[:n],
                            name=f"{trial.name}-sim")
        return simulate

    # ------------------------------------------------------------------ fits
    def fit_effects(self, trials, effects, config, store=None, runner=None):
        """Which / how far for a position experiment: every applicable effect fitted by
        variable projection (diagnosis.limbfit: K, B, I and the effect's gain-like
        parameters linear, the others searched), calibrated on the first
        ``config.time_split_fraction`` of every trial, its gap on the rest (held out);
        95 % jackknife intervals for the best fit; pairs built on the best fit
        (diagnosis.limbpairs) when it leaves a significant calibration gap.

        ``store`` (pipeline.resume.ResumeStore, optional): every finished fit, and the
        best fit's intervals, are written to it atomically as they finish and read back
        by a re-run with the same inputs and options (the store's key), which then fits
        only what is missing and gives the same report.

        ``runner`` (diagnosis.parallel.Runner, optional; the diagnosis's, whose state
        holds these ``trials``): with more than one worker the effects are fitted on the
        workers (diagnosis.tasks.task_limbfit), the costliest first, each returned as the
        record a resume store keeps (limbfit.fit_record) and rebuilt here bit for bit;
        without one, or with one worker, in this process. The result is the same.

        Returns
        -------
        dict
            ``fits`` (fitting.EffectFit, best first, each with ``intervals`` and the
            re-estimated limb as ``model``), ``pairs`` (fitting.EffectFit of two effects,
            best first, each with its second effect's held-out test ``second_test``), ``g0_cal``, ``g0_held``, ``g0_all``,
            ``significant``, ``threshold``, ``noise_floor``, ``noise_floor_source``,
            ``model_tolerance`` (with ``model_tolerance_source`` and
            ``model_tolerance_per_record``), ``changing_in_time``, ``measure``, and
            ``alternatives``: a function of the named fit giving its alternatives, each
            judged on the named fit's held-out split (diagnosis.limbties.alternatives;
            computed once per named fit, kept in the resume store).
        """
        from .. import limbfit as lf
        from ..catalogue import at_search_bound
        from ..fitting import EffectFit
        cfg = lf.FitConfig(held_out_fraction=1.0 - config.time_split_fraction,
                           effects=tuple(effects))
        records = [lf.PositionRecord.from_trial(t) for t in trials]
        preps = lf.prepare(records, cfg)
        nominal = lf.fit_nominal(preps, cfg)
        g = nominal["gaps"]
        # the shared time-variation test gates the fits too: a change found in time makes
        # the gap significant (limbfit.gap_is_significant), as in limbfit.diagnose_position
        significant, changing = lf.gap_is_significant(records, g["all"], cfg)
        # effects are fitted only when there is a gap to explain (as limbfit does)
        names = lf.candidates(preps, effects) if effects and significant else []
        if _parallel(runner, trials, names):
            fits = _fit_on_workers(runner, names, preps, nominal, cfg, store)
        else:
            fits = [_resumable(store, ("limbfit", nm, repr(cfg)),
                               lambda nm=nm: lf.fit_effect(preps, nm, nominal, cfg,
                                                           intervals=False),
                               lf.fit_record,
                               lambda d: lf.fit_from_record(preps, d, nominal, cfg))
                    for nm in names]
        fits.sort(key=lambda f: f.calibration_objective)
        from .. import varying_effects as vary
        fits = vary.prefer_simpler(fits, cfg.name_reduction)  # nesting: the simpler first
        if fits and cfg.n_jackknife >= 2:
            best = fits[0]

            def jackknife():
                lf.add_intervals(best, cfg)   # with the form profile (diagnosis.formprofile)
                return {"intervals": best.intervals, "n": best.n_evaluations,
                        "limb_ci": best.limb_ci, "form_profile": best.form_profile}
            ci = _resumable(store, ("limbfit-jackknife", best.effect, repr(cfg)), jackknife,
                            lambda d: d,
                            lambda d: {"intervals": dict(d["intervals"]), "n": int(d["n"]),
                                       "limb_ci": d.get("limb_ci"),
                                       "form_profile": d.get("form_profile")})
            if ci.get("form_profile") and best.form_profile is None:  # read back: apply it
                from .. import formprofile
                formprofile.apply(lf, best, {**ci["form_profile"], "n_evaluations": 0}, cfg)
            best.intervals, best.n_evaluations = ci["intervals"], int(ci["n"])
            best.limb_ci = ci["limb_ci"]
        # the independent steps after the single fits (the pairs' forward choices and
        # refits, the ties' scores) on the workers too (tasks.task_limbfit_call)
        run = _runner_run(runner, trials, cfg)
        pairs = []
        if fits and significant and cfg.pairs:
            from .. import limbpairs as lp
            import sys as _sys
            pairs = _resumable(
                store, ("limbfit-pairs", fits[0].effect, repr(cfg)),
                lambda: lp.search_pairs(_sys.modules[lf.__name__], preps, fits, nominal, cfg,
                                        run=run),
                lambda ps: [p.as_dict() for p in ps],
                lambda d: [lp.PairFit.from_dict(x) for x in d])
        out = []
        for f in fits:
            fit = EffectFit((f.effect,), {f.effect: dict(f.params)}, f.calibration_gap,
                            f.n_evaluations, held_out_gap=f.held_out_gap,
                            objective=f.calibration_objective)
            fit.intervals = None if f.intervals is None else {f.effect: f.intervals}
            # the intervals' form profile (the choices profiled, each refit; formprofile)
            fit.form_profile = {f.effect: f.form_profile} if f.form_profile else None
            # the limb re-estimated with the effect, with its K, B, I intervals (the
            # jackknife of the best fit)
            fit.model = model_of(f.limb, trials[0].fs, "limbfit with " + f.effect,
                                 ci=f.limb_ci)
            # a varying effect's own held-out split, and the nesting rule (report)
            fit.split = getattr(f, "split", None)
            # the held-out residual with the floor in it (a gap clipped at 0 says little)
            fit.held_out_residual = getattr(f, "held_out_residual", None)
            fit.preferred_over = getattr(f, "preferred_over", None)
            # limbfit's flags as notes (a negative linear gain: unphysical), formatted
            # with the parameters in the units they are shown in (fitting.format_flags)
            fit.value_flags = [(f.effect, k, "< 0 (unphysical)")
                               for k in lf.LINEAR.get(f.effect, ()) if f.params[k] < 0]
            shown = at_search_bound(f.effect, f.params)  # those EffectFit derives itself
            fit.bound_flags = [x for x in f.at_search_bound if x not in shown
                               and not x.endswith("< 0 (unphysical)")]
            out.append(fit)

        def alternatives(chosen):
            """The alternatives to the named fit ``chosen`` (a fitting.EffectFit of
            ``out`` or of the pairs), each judged on the held-out split of ``chosen``
            (diagnosis.limbties);
            None when it is not one of these fits."""
            from .. import limbties as lt
            eff = tuple(chosen.effects)
            named = (next((f for f in fits if (f.effect,) == eff), None) if len(eff) == 1
                     else next((p for p in pairs if tuple(p.effects) == eff), None))
            if named is None:
                return None
            return _resumable(store, ("limbties", 3, list(eff), repr(cfg)),
                              lambda: lt.alternatives(lf, preps, nominal, cfg, named, fits,
                                                      pairs, run=run),
                              lambda d: d, lambda d: d)

        return {"fits": out, "pairs": [_pair_fit(p, trials[0].fs) for p in pairs],
                "alternatives": alternatives,
                "g0_cal": g["cal"].value, "g0_held": g["held"].value,
                "g0_all": g["all"].value, "significant": significant,
                "threshold": float(g["all"].threshold(cfg)),
                "noise_floor": float(g["all"].floor),
                "noise_floor_source": g["all"].source,
                "changing_in_time": changing,
                # the model tolerance the threshold adds, per record (limbfit)
                **g["all"].tolerance_report(preps, cfg),
                "measure": "limbfit: band energy of the torque residual above the noise "
                           "floor (noise_floor_source), relative to the torque energy "
                           "(diagnosis.limbfit)",
                "nominal_limb": model_of(nominal["limb"], trials[0].fs, "limbfit nominal")}


def _parallel(runner, trials, names) -> bool:
    """Fit on the runner's workers: more than one worker (or a cluster), more than one
    effect, and the runner's state holds these very trials (the tasks read them there)."""
    if len(names) < 2:
        return False
    return _on_workers(runner, trials)


def _runner_run(runner, trials, cfg):
    """``run(fn, arg_tuples, desc)`` mapping ``fn(limbfit, preps, nominal, cfg, *a)`` on
    the runner's workers (tasks.task_limbfit_call: each worker's own prepared records and
    nominal fit of the same trials, the same numbers), or None (in this process) when
    :func:`_on_workers` says no."""
    if not _on_workers(runner, trials):
        return None
    from ..tasks import task_limbfit_call

    def run(fn, arg_tuples, desc=""):
        return runner.map(task_limbfit_call, [(cfg, fn, tuple(a)) for a in arg_tuples],
                          desc=desc)
    return run


def _on_workers(runner, trials) -> bool:
    """More than one worker (or a cluster), and the runner's state holds these very
    trials (the tasks read them there)."""
    if runner is None:
        return False
    if getattr(runner, "workers", 1) < 2 and getattr(runner, "_client", None) is None:
        return False
    held = getattr(getattr(runner, "state", None), "trials", None)
    return held is not None and len(held) == len(trials) and all(
        a is b for a, b in zip(held, trials))


def _fit_cost(name, cfg) -> float:
    """A rough cost of fitting ``name`` (grid points times discrete choices): the
    workers take the costliest first so that none is left with a long fit at the end."""
    from .. import catalogue as cat
    from .. import limbfit as lf
    from .. import varying_effects as vary
    nl = len(lf._nonlinear(name))
    if name == "stiffness_modulated":
        return float(vary.PERIOD_GRID)
    grid = cfg.grid if nl == 1 else max(6, int(cfg.grid * 1.3))
    choices = 1
    for values in (cat.get_effect(name).choices or {}).values():
        choices *= len(values)
    return float(grid ** nl * choices)


def _fit_on_workers(runner, names, preps, nominal, cfg, store):
    """The fits of ``names`` (in that order) made on the runner's workers; those a
    resume store holds are read back, each new one stored as it finishes."""
    from .. import limbfit as lf
    from ..tasks import task_limbfit
    keys = {nm: ("limbfit", nm, repr(cfg)) for nm in names}
    records = {}
    if store is not None:
        for nm in names:
            found = store.get_json(keys[nm])
            if found is not None:
                records[nm] = found
    todo = sorted((nm for nm in names if nm not in records),
                  key=lambda nm: -_fit_cost(nm, cfg))

    def done(i, record):
        if store is not None:
            store.put_json(keys[todo[i]], record)

    results = runner.map(task_limbfit, [(nm, cfg) for nm in todo], desc="limbfit effects",
                         done=done)
    fits = []
    for nm in names:
        if nm in records:
            try:
                fits.append(lf.fit_from_record(preps, records[nm], nominal, cfg))
                store.n_reused += 1
                continue
            except (KeyError, ValueError, TypeError):
                pass  # another layout: fit again, here
            fit = lf.fit_effect(preps, nm, nominal, cfg, intervals=False)
            store.put_json(keys[nm], lf.fit_record(fit))
            fits.append(fit)
        else:
            fits.append(lf.fit_from_record(preps, results[todo.index(nm)], nominal, cfg))
    return fits


def _pair_fit(p, fs):
    """A fitting.EffectFit of a limbpairs.PairFit (its second effect's held-out test as
    ``second_test``, which pipeline.verdict.pair_earns_second reads)."""
    from .. import limbfit as lf
    from ..fitting import EffectFit
    fit = EffectFit(tuple(p.effects), {k: dict(v) for k, v in p.params.items()},
                    p.calibration_gap, p.n_evaluations, held_out_gap=p.held_out_gap,
                    objective=p.calibration_objective)
    fit.model = model_of(p.limb, fs, "limbfit with " + " + ".join(p.effects),
                         ci=p.limb_ci)
    # the one-step jackknife of the best pair (limbpairs.add_intervals), its envelope
    # over the members' form alternatives (limbpairs.profile_pair)
    fit.intervals = p.intervals
    fit.form_profile = p.form_profile
    fit.replicates = p.replicates
    fit.value_flags = [(k, g, "< 0 (unphysical)") for k in p.effects
                       for g in lf.LINEAR.get(k, ()) if p.params[k][g] < 0]
    fit.second_test = dict(p.test)
    fit.held_out_residual = p.test.get("held_out_residual")
    fit.split = p.split
    return fit


def _resumable(store, key, compute, to_json, from_json):
    """``compute()``, or its result read back from ``store`` under ``key`` (a re-run of
    the same diagnosis); a result computed is stored at once (atomically)."""
    if store is None:
        return compute()
    found = store.get_json(key)
    if found is not None:
        try:
            value = from_json(found)
            store.n_reused += 1
            return value
        except (KeyError, ValueError, TypeError):
            pass  # another layout: fit again
    value = compute()
    store.put_json(key, to_json(value))
    return value


def limb_of(model):
    """The diagnosis.limb.LimbModel of an ArmModel (I = the fitted inertia M)."""
    from .. import limb as lm
    return lm.LimbModel(K=np.atleast_2d(np.asarray(model.K, float)),
                        B=np.atleast_2d(np.asarray(model.B, float)),
                        I=np.atleast_2d(np.asarray(model.M, float)))


def model_of(limb, fs, method, ci=None):
    """An ArmModel holding a limbfit LimbModel (for the simulator and the report);
    ``ci``: its 95 % half-widths ({"K_h", "B_h", "M_h"}, limbfit.EffectFit.limb_ci)."""
    from ..arm import ArmModel
    n = limb.K.shape[0]
    return ArmModel(M=np.asarray(limb.I, float), B=np.asarray(limb.B, float),
                    K=np.asarray(limb.K, float), r2=np.full((n, n), np.nan), method=method,
                    fs=fs, inertia_delay_s=0.0,
                    ci=None if ci is None else {k: np.asarray(v, float)
                                                for k, v in ci.items()})
