"""Position-servo catalogue effects of a stiffness (and damping) that varies in time or in
state (docs/diagnosis.md, section "Time- and state-varying effects").

Every effect here is a *basis expansion* of the limb's K and B, linear in its
coefficients: K(t) = K0 + sum_m cK_m phi_m(t), B(t) = B0 + sum_m cB_m phi_m(t), so the
design columns are theta_k phi_m and omega_k phi_m (low-passed like the base columns) and
the variable projection of diagnosis.limbfit solves them in one least-squares step; only
a time constant or a period is searched.

========================  ====================================================  ==========
effect                    phi_m                                                 searched
========================  ====================================================  ==========
stiffness_saturating      1 - exp(-t / T): a drift that settles (fatigue)       T
stiffness_switching       indicator of the "high" level; the change points are  -
                          read from the data (local K over 1 s windows split
                          in two levels by the largest between-class variance)
stiffness_modulated       sin, cos(2 pi t / P): a slow modulation               P
stiffness_angle           rho, rho^2 with rho the scheduling variable (the      -
                          slow angle, or a named one: the nldat ``sv``),
                          centred and scaled to [-1, 1]; plus quasi-static
                          columns rho, rho^2, rho^3 (the torque of the
                          movement itself)
stiffness_torque          as stiffness_angle with rho the slow part of the      -
                          measured torque (the background torque)
========================  ====================================================  ==========

Held-out split (per effect, :func:`split_masks`): a time-varying effect is judged on
interleaved blocks *inside* the time range its fit saw (every third block held out): the
default split (the last third held out) would ask it to extrapolate a drift that
saturates or a switching sequence into a future it never saw. A state-varying effect is
judged on blocks *stratified by the scheduling variable* (the blocks ordered by their mean
state, every third held out), held-out samples outside the states the calibration covered
(its 1-99 % range) dropped. The effect's nominal reference gap is measured on the same
split; its gaps are reported on the default split's scale (times the default nominal gap
over the split's nominal gap) so that every row of the ranking compares the same
reduction ``1 - gap(effect) / gap(nominal)``; the raw split gaps are in ``split``.

Nesting (:func:`prefer_simpler`): when a richer (or an alternative) effect ranks above a
simpler one it nests or that explains the same variation (linear drift inside the
saturating or modulated drift; a stiffness that varies with the angle on a periodic
movement looks modulated in time), the simpler one is named unless the richer one's
held-out reduction exceeds it by :data:`NEST_MARGIN`.

The switching effect reads its change points from the whole record (calibration and
held-out blocks): one bit per 1 s window, so it can follow any variation coarsely; the
nesting rule keeps it from being named for a drift or an angle dependence it only mimics.
"""

from __future__ import annotations

import math
from contextlib import contextmanager

import numpy as np

TIME_EFFECTS = ("stiffness_saturating", "stiffness_switching", "stiffness_modulated")
STATE_EFFECTS = ("stiffness_angle", "stiffness_torque")
EFFECTS = TIME_EFFECTS + STATE_EFFECTS

#: (preferred, other): ``other`` is named over ``preferred`` only when its held-out
#: reduction exceeds the preferred one's by NEST_MARGIN (module docstring)
PREFERRED = [(s, o) for s in ("stiffness_drift",) for o in TIME_EFFECTS] + \
    [(s, o) for s in STATE_EFFECTS for o in TIME_EFFECTS + ("stiffness_drift",)] + \
    [("stiffness_angle", "stiffness_torque")]
NEST_MARGIN = 0.1
#: interleaved / stratified blocks: about this many per trial, at least BLOCK_MIN_S long
N_BLOCKS = 18
BLOCK_MIN_S = 3.0
#: grid points of the modulation period's search
PERIOD_GRID = 40
#: the switching effect's window for the local stiffness [s]
SWITCH_WINDOW_S = 1.0
#: a trial's slow torque schedules the stiffness when its 1-99 % span exceeds this many
#: std of its fast part (trialformat.scheduling.MOVING_RATIO, as for the angle)
TORQUE_RATIO = 5.0


def is_varying(name) -> bool:
    return name in EFFECTS


# ----------------------------------------------------------------------------- schedules
def schedule(pr, name):
    """Scheduling variable (N,) at the full rate for a state effect on prepared record
    ``pr``, or None when the record has none (a stationary joint, a constant torque)."""
    cache = pr.__dict__.setdefault("_varying_schedules", {})
    if name in cache:
        return cache[name]
    from trialformat import scheduling as sch
    rho = None
    if name == "stiffness_angle":
        s = getattr(pr.rec, "scheduling", None)
        if s is not None and getattr(s, "name", "") != "time":
            v = np.asarray(s.values, float).reshape(-1)
            if v.shape[0] == pr.N and np.all(np.isfinite(v)):
                rho = v
    elif name == "stiffness_torque" and pr.N > 3 * pr.fs / sch.SLOW_CUTOFF_HZ:
        tau = pr.rec.tau[:, 0]
        span, noise = sch.spread(tau, pr.fs)
        if span > TORQUE_RATIO * noise:
            rho = sch.slow_part(tau, pr.fs)
    cache[name] = rho
    return rho


def applicable(preps, name) -> bool:
    """False for a state effect when some record has no scheduling variable."""
    if name not in STATE_EFFECTS:
        return True
    return all(schedule(pr, name) is not None for pr in preps)


def _scaled(rho):
    lo, hi = np.percentile(rho, [1, 99])
    mid, half = 0.5 * (lo + hi), max(0.5 * (hi - lo), 1e-12)
    return (rho - mid) / half, mid, half


# ----------------------------------------------------------------------------- basis
def _switch_indicator(pr, partner=None):
    """(N,) 0/1 indicator of the high stiffness level, from a local K per window.

    ``partner``: (key, (Nd, q) low-passed columns) of a pair's other effect (a reflex's
    torque), regressed in every window beside the limb's: a reflex otherwise scatters the
    local K by more than the switch (labsim switching+reflex, seed 102: local K from -73
    to 330 N m/rad where the truth switches between 30 and 69; with the reflex column
    27-33 and 62-74)."""
    if partner is not None:
        cache = pr.__dict__.setdefault("_switch_partnered", {})
        if partner[0] not in cache:
            cache[partner[0]] = _switch_indicator_of(pr, partner[1])
        pr._switch_partner_last = partner[0]  # the pair's reported change count
        return cache[partner[0]][0]
    if "_switch" not in pr.__dict__:
        pr._switch, pr._switch_changes = _switch_indicator_of(pr, None)
    return pr._switch


def _switch_indicator_of(pr, extra):
    """(indicator (N,), number of changes) from local K over windows, ``extra`` columns
    (Nd, q) regressed beside the limb's (None: none)."""
    w = max(8, int(round(SWITCH_WINDOW_S * pr.fs_d)))
    n = pr.n
    cols = pr.base.reshape(pr.Nd, -1)
    # the record's usable samples, whatever split is swapped in when it is first asked
    # for: a stratified split holds fewer (its out-of-range held-out samples dropped), and
    # the indicator then depended on which fit asked first (a switching alternative
    # re-scored on a state effect's split got 19 changes where its own fit had 22)
    keep = usable(pr)
    ks, starts = [], []
    for s in range(0, pr.Nd - w + 1, w):
        rows = slice(s, s + w)
        if keep[rows].mean() < 0.5:
            ks.append(np.nan)
            starts.append(s)
            continue
        parts = [cols[rows], np.ones((w, 1)), pr.t[rows, None] - pr.t[s]]
        if extra is not None:
            parts.insert(1, extra[rows])
        A = np.concatenate(parts, axis=1)
        coef, *_ = np.linalg.lstsq(A, pr.tau_lp[rows, 0], rcond=None)
        ks.append(coef[0] if n == 1 else coef[0])
        starts.append(s)
    ks = np.array(ks)
    ok = np.isfinite(ks)
    ind_w = np.zeros(ks.shape)
    if ok.sum() >= 4:
        srt = np.sort(ks[ok])
        best, thr = -1.0, srt[0]
        for i in range(1, srt.size):  # largest between-class variance (Otsu)
            a, b = srt[:i], srt[i:]
            v = a.size * b.size * (a.mean() - b.mean()) ** 2
            if v > best:
                best, thr = v, 0.5 * (srt[i - 1] + srt[i])
        ind_w = (ks > thr).astype(float)
        # a window left out of the fit (the record's filter-trimmed ends, a gap) holds
        # the level of the nearest window estimated: set to the low level, a record that
        # starts (or ends) high counted one switch too many and its basis was low there
        have = np.flatnonzero(ok)
        for i in np.flatnonzero(~ok):
            ind_w[i] = ind_w[have[np.argmin(np.abs(have - i))]]
    ind_d = np.zeros(pr.Nd)
    for s, v in zip(starts, ind_w):
        ind_d[s:s + w] = v
    if starts:
        ind_d[starts[-1] + w:] = ind_w[-1]
    full = np.repeat(ind_d, pr.D)[:pr.N]
    if full.size < pr.N:
        full = np.concatenate([full, np.full(pr.N - full.size, full[-1] if full.size else 0)])
    return full, int(np.sum(np.abs(np.diff(ind_w))))


def basis(pr, name, params, partner=None):
    """(Nd, m) basis of the varying K and B on the decimated samples of ``pr`` (every
    D-th sample of the full rate, as the low-passed columns), and (Nd, q) quasi-static
    columns (state effects) or None.

    Each basis function is evaluated on the decimated samples only (the same values as
    evaluating it at the full rate and keeping every D-th sample: the functions are
    pointwise); the scheduling variable's scaling (its 1-99 % range over the whole
    record) is computed once per record, and the last few bases are kept (a pair's search
    varies its second effect only: the first's basis is the same at every step). The
    arrays returned are shared: read them, never write."""
    key = (name, tuple(sorted((k, repr(v)) for k, v in (params or {}).items())),
           None if partner is None else partner[0])
    cache = pr.__dict__.setdefault("_varying_basis", {})
    if key in cache:
        return cache[key]
    out = _basis(pr, name, params, partner)
    if len(cache) >= 4:
        cache.pop(next(iter(cache)))  # the oldest
    cache[key] = out
    return out


def _basis(pr, name, params, partner=None):
    t = (np.arange(pr.N) / pr.fs)[::pr.D][:pr.Nd]
    if name == "stiffness_saturating":
        return (1.0 - np.exp(-t / float(params["time_constant_s"])))[:, None], None
    if name == "stiffness_modulated":
        a = 2 * math.pi * t / float(params["period_s"])
        return np.stack([np.sin(a), np.cos(a)], axis=1), None
    if name == "stiffness_switching":
        return _switch_indicator(pr, partner)[::pr.D][:pr.Nd, None], None
    x = _scaled_schedule(pr, name)[::pr.D][:pr.Nd]
    return np.stack([x, x * x], axis=1), np.stack([x, x * x, x ** 3], axis=1)


def _scaled_schedule(pr, name):
    """(N,) the scheduling variable of ``name`` scaled to [-1, 1] over its 1-99 % range
    (:func:`_scaled`), computed once per prepared record."""
    cache = pr.__dict__.setdefault("_varying_scaled", {})
    if name not in cache:
        cache[name] = _scaled(schedule(pr, name))[0]
    return cache[name]


def columns(pr, name, params):
    """Low-passed design columns (Nd, n, p): the base K, B, I columns, then per basis
    function the K and B columns times it, then the quasi-static columns.

    The basis varies below about 0.5 Hz, far below the analysis band (30 Hz): the
    low-pass commutes with a product by it (up to the steps of the switching indicator,
    a few samples each), so the already low-passed base columns are multiplied by the
    decimated basis instead of low-passing every product at the full rate (10-50 times
    faster on the 106 s pilot recording)."""
    phi_d, q = basis(pr, name, params)
    n, nn = pr.n, pr.n * pr.n
    extra = []
    for m in range(phi_d.shape[1]):
        extra.append(pr.base[:, :, :2 * nn] * phi_d[:, m, None, None])
    if q is not None:
        for m in range(q.shape[1]):
            c = np.zeros((pr.Nd, n, n))
            for j in range(n):
                c[:, j, j] = q[:, m]
            extra.append(c)
    return np.concatenate([pr.base] + extra, axis=2)


def summary(preps, name, params, coef) -> dict:
    """The effect's reported parameters from the solved coefficients (relative to K0 of
    joint 1: the change a lab reads)."""
    pr = preps[0]
    n = pr.n
    nn = n * n
    k0 = float(coef[0])
    k0 = k0 if abs(k0) > 1e-12 else 1e-12
    ext = coef[3 * nn:]
    cK = [float(ext[2 * nn * m]) for m in range(len(ext) // (2 * nn))]
    out = {}
    if name == "stiffness_saturating":
        out = {"change_rel": cK[0] / k0, "time_constant_s": float(params["time_constant_s"])}
    elif name == "stiffness_modulated":
        out = {"amplitude_rel": math.hypot(cK[0], cK[1]) / abs(k0),
               "period_s": float(params["period_s"])}
    elif name == "stiffness_switching":
        out = {"level_ratio": (k0 + cK[0]) / k0 if k0 > 0 else float("nan"),
               "n_changes": float(getattr(pr, "_switch_changes", 0))}
    else:
        _, mid, half = _scaled(schedule(pr, name))
        out = {"slope_rel": cK[0] / half / k0, "curvature_rel": cK[1] / half ** 2 / k0,
               "rho_mid": float(mid), "rho_half_range": float(half)}
    return out


#: the varying effects a re-simulation can run from their reported parameters (the
#: others need what the fit read from the data and does not report: the switching's
#: change points, the modulation's phase)
RESIMULATED = ("stiffness_angle", "stiffness_torque", "stiffness_saturating")


def factor(trial, name, params, n_samples):
    """(n_samples,) the factor on K of varying effect ``name`` with reported ``params``
    over a trialformat.Trial, K0 (1 + s d + c d^2) or K0 (1 + r (1 - exp(-t / T))) over
    K0; None when it cannot be rebuilt (not in :data:`RESIMULATED`, no schedule)."""
    n = int(n_samples)
    if name == "stiffness_saturating":
        t = np.arange(n) / trial.fs
        return 1.0 + float(params["change_rel"]) * (1.0 - np.exp(
            -t / float(params["time_constant_s"])))
    if name not in STATE_EFFECTS:
        return None
    from trialformat import scheduling as sch
    if name == "stiffness_angle":
        try:
            s = sch.scheduling_of(trial)
        except Exception:  # SchedulingError: no usable schedule, no rebuilt factor
            return None
        if s is None or getattr(s, "name", "") == "time":
            return None
        rho = np.asarray(s.values, float).reshape(-1)[:n]
    else:
        rho = sch.slow_part(np.asarray(trial.tau_h[:, 0], float), trial.fs)[:n]
    d = rho - float(params["rho_mid"])
    return 1.0 + float(params["slope_rel"]) * d + float(params["curvature_rel"]) * d * d


# ----------------------------------------------------------------------------- splits
def usable(pr):
    """The samples of prepared record ``pr`` that any fit or gap may use (its default
    split's calibration and held-out parts, ``pr.usable``), whatever split is swapped in."""
    u = getattr(pr, "usable", None)
    return pr.cal | pr.held if u is None else u


def split_masks(pr, name):
    """(calibration, held-out, rule, why) masks over the decimated samples of ``pr``."""
    idx = np.flatnonzero(usable(pr))
    dur = idx.size / pr.fs_d
    nb = int(max(3, min(N_BLOCKS, dur // BLOCK_MIN_S)))
    blocks = np.array_split(idx, nb)
    if name in STATE_EFFECTS:
        rho = schedule(pr, name)[::pr.D][:pr.Nd]
        order = np.argsort([rho[b].mean() for b in blocks], kind="stable")
        held_b = set(order[1::3].tolist())
    else:
        held_b = set(range(1, nb, 3))
    cal = np.zeros(pr.Nd, bool)
    held = np.zeros(pr.Nd, bool)
    for i, b in enumerate(blocks):
        (held if i in held_b else cal)[b] = True
    if name in STATE_EFFECTS:
        lo, hi = np.percentile(rho[cal], [1, 99])
        held &= (rho >= lo) & (rho <= hi)
        rule = "stratified by the scheduling variable"
        why = (f"{nb} blocks ordered by their mean state, every third held out, held-out "
               f"samples outside the calibration's states ({lo:.3g}..{hi:.3g}) dropped: a "
               f"state-varying effect is judged inside the states its fit saw")
    else:
        rule = "interleaved blocks"
        why = (f"{nb} blocks, every third held out: a time-varying effect is judged inside "
               f"the time range its fit saw, not extrapolated beyond it")
    return cal, held, rule, why


@contextmanager
def swapped(preps, split):
    """Temporarily give every record the split's calibration and held-out masks."""
    saved = [(pr.cal, pr.held) for pr in preps]
    try:
        for pr, (c, h) in zip(preps, split):
            pr.cal, pr.held = c, h
        yield
    finally:
        for pr, (c, h) in zip(preps, saved):
            pr.cal, pr.held = c, h


def make_problem(lf, preps, name, fixed, cfg, unit):
    """A limbfit._Problem whose every evaluation (and jackknife) uses the effect's split."""
    masks = [split_masks(pr, name) for pr in preps]
    split = [(c, h) for c, h, _, _ in masks]

    class _SplitProblem(lf._Problem):
        def evaluate(self, params):
            with swapped(self.preps, split):
                return super().evaluate(params)

        def split_context(self):
            return swapped(self.preps, split)

        def search(self, start=None):
            # the misfit of a period is multimodal (every harmonic of the modulation is a
            # basin): a dense log grid of PERIOD_GRID points before the refinement
            if name != "stiffness_modulated" or start is not None:
                return super().search(start)
            import dataclasses
            saved = self.cfg
            self.cfg = dataclasses.replace(saved, grid=PERIOD_GRID)
            try:
                return super().search()
            finally:
                self.cfg = saved

    prob = _SplitProblem(preps, name, fixed, cfg, unit)
    prob.split = split
    prob.split_info = {"rule": masks[0][2], "why": masks[0][3],
                       "held_out_fraction": float(np.mean([h.sum() / max(1, (c | h).sum())
                                                           for c, h in split]))}
    return prob


def split_nominal(lf, prob):
    """The nominal solve on the effect's split (limbfit._solve); sets ``prob.unit`` to
    its calibration energy, the scale of the effect's objectives (the search's and the
    jackknife's: a problem rebuilt from a fit's record needs the same)."""
    with prob.split_context():
        nom = lf._solve(prob.preps, [pr.base for pr in prob.preps])
    prob.unit = nom.cal_energy or 1.0
    return nom


def fit_effect(lf, preps, name, nominal, cfg, *, intervals=True):
    """limbfit.fit_effect for a varying effect (its own split; gaps rescaled, module
    docstring). Returns a limbfit.EffectFit with ``split`` (rule, why, raw gaps)."""
    from . import catalogue as cat
    n = preps[0].n
    prob0 = make_problem(lf, preps, name, {}, cfg, nominal["solution"].cal_energy)
    nom = split_nominal(lf, prob0)
    with prob0.split_context():
        ang = [lf._angle_residual(pr, None) for pr in preps]
        limb0 = nominal["limb"]
        n_cal = lf._gap(preps, nom.residual, ang, limb0, cfg, "cal")
        n_held = lf._gap(preps, nom.residual, ang, limb0, cfg, "held")
    x = prob0.search()
    params = prob0.params(x)
    obj, sol, ang = prob0.evaluate(params)
    with prob0.split_context():
        g_cal = lf._gap(preps, sol.residual, ang, limb0, cfg, "cal")
        g_held = lf._gap(preps, sol.residual, ang, limb0, cfg, "held")
    d_cal, d_held = nominal["gaps"]["cal"].value, nominal["gaps"]["held"].value
    ratio_cal = g_cal.value / n_cal.value if n_cal.value > 0 else 1.0
    ratio_held = g_held.value / n_held.value if n_held.value > 0 else 1.0
    reduction = None if n_held.value <= 0 else 1.0 - ratio_held
    out_params = summary(preps, name, params, sol.coef)
    limb = lf._limb_from(sol.coef, n)
    bound = cat.at_search_bound(name, out_params)
    obj_scaled = obj / prob0.unit * nominal["solution"].cal_energy
    fit = lf.EffectFit(name, out_params, None, limb, obj_scaled, d_cal * ratio_cal,
                       d_held * ratio_held, reduction, bound, prob0.n_eval)
    fit.split = {**prob0.split_info, "nominal_calibration_gap": n_cal.value,
                 "nominal_held_out_gap": n_held.value, "calibration_gap": g_cal.value,
                 "held_out_gap": g_held.value}
    fit._problem = (prob0, x, {})
    fit.held_out_residual = g_held.residual_against(n_held.value)  # on its own split
    if intervals and cfg.n_jackknife >= 2 and prob0.nl:
        lf.add_intervals(fit, cfg)
    return fit


def prefer_simpler(fits, name_reduction=0.5):
    """Reorder limbfit.EffectFit's (best first) by :data:`PREFERRED`: a preferred effect
    ranked below an alternative is moved above it unless the alternative's held-out
    reduction exceeds its own by NEST_MARGIN (or the preferred one is not nameable).
    Sets ``preferred_over`` on a promoted fit."""
    fits = list(fits)
    for _ in range(len(fits)):
        changed = False
        for pref, other in PREFERRED:
            ip = next((i for i, f in enumerate(fits) if f.effect == pref), None)
            io = next((i for i, f in enumerate(fits) if f.effect == other), None)
            if ip is None or io is None or ip < io:
                continue
            fp, fo = fits[ip], fits[io]
            rp = fp.held_out_reduction if fp.held_out_reduction is not None else -math.inf
            ro = fo.held_out_reduction if fo.held_out_reduction is not None else -math.inf
            if fp.at_search_bound or rp < name_reduction or ro > rp + NEST_MARGIN:
                continue
            fits.insert(io, fits.pop(ip))
            fp.preferred_over = getattr(fp, "preferred_over", []) + [
                f"{other} (held-out reduction {100 * ro:.0f} % vs {100 * rp:.0f} %: "
                f"not more by {100 * NEST_MARGIN:.0f} points)"]
            changed = True
        if not changed:
            break
    return fits
