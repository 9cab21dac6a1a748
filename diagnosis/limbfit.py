"""Fitting the limb/position-servo effects of the catalogue (docs/diagnosis.md, section
"The limb and the position-servo catalogue").

A position experiment gives the imposed angle theta (N, n) [rad], the measured torque tau
(N, n) [N m] and, when recorded, the servo reference theta_ref. The model of a candidate
effect E with parameters p is diagnosis.limb: tau = limb_torque(theta; K, B, I, E(p)).
That model is *linear* in K, B, I and in the effect's gain-like parameters (reflex gain,
wobbling mass) once the other parameters are fixed, so the fit is a variable projection:

* for given nonlinear parameters (reflex delay and activation frequency, stiffness
  exponent, drift rate, wobbling frequency, sensor time constant, channel delay), the
  linear ones and every entry of K, B, I (plus a torque offset and trend per trial and
  joint) come from one least-squares solve on the calibration samples;
* the nonlinear ones are searched on a grid over the catalogue's search bounds, then
  refined by Nelder-Mead from the best grid points;
* discrete choices (a rectified reflex or not) are tried in turn.

Both sides are low-passed by the same zero-phase Butterworth filter (``band_hz``) before
the solve, which keeps the model relation exact (the filter is linear) and bounds the
noise that double differentiation of the measured angle brings.

The gap (the misfit above noise) is computed in the frequency domain: the Welch spectrum
of the torque residual integrated over the analysis band, minus the noise floor expected
there. The floor is measured from the recording itself: torque and angle noise are taken
as white, at the level of their spectra in the band [0.25, 0.45] fs where the
perturbation carries no power, the angle's noise mapped through the nominal impedance.
The gap is the remaining energy relative to the torque energy of the band; with a
recorded theta_ref the servo's angle tracking error is added the same way. A nominal gap
is significant when it exceeds ``significance_sigma`` standard errors of the Welch
estimate plus ``floor_margin`` times the floor plus the model tolerance: per record, twice
what this very pipeline leaves of a noise-free torque of the fitted nominal limb simulated
from the record's measured angle with accurate derivatives (:func:`_pipeline_tolerance`;
``FitConfig.model_tolerance`` a number: a constant instead).

Intervals: delete-one-block jackknife over ``n_jackknife`` contiguous blocks of the
calibration samples (each block's fit refined from the full fit), +- 1.96 standard
errors: contiguous blocks respect the residual's correlation in time, which the Jacobian
of a least-squares fit ignores. The named (best) fit's intervals then include its form
(``FitConfig.form_profile``, diagnosis.formprofile): refits at the plausible alternatives
of the choices it ties (the reflex's and the wobbling mass's damping) or picks (the
reflex's rectification), the envelope of the jackknife intervals of those the data do
not reject, the point estimate the best-fitting choice.

The fit uses only the calibration part (the first ``1 - held_out_fraction`` of every
trial); the held-out reduction is 1 - gap(effect) / gap(nominal) on the last part, with
the calibration fit's parameters, K, B and I.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize
from scipy import signal

from . import catalogue as cat
from . import limb as lm
from . import limbpairs as lp
from . import varying_effects as vary

VERDICT_EFFECT = "effect"
VERDICT_NONE = "no significant gap"
VERDICT_UNEXPLAINED = "unexplained"

#: parameters solved linearly (variable projection), per effect
LINEAR = {"stretch_reflex": ("gain",), "wobbling_mass": ("mass",)}


@dataclass(frozen=True)
class FitConfig:
    """Settings of the position-experiment fits (defaults used by the validation).

    band_hz : analysis low-pass cut-off [Hz] (clipped to 0.2 fs).
    band_low_hz : lowest frequency of the gap integral [Hz].
    lowpass_order : Butterworth order of the analysis low-pass (applied forwards and back).
    welch_s : Welch segment length [s].
    held_out_fraction : last part of every trial kept for the held-out check.
    edge_s : (first, last) seconds of every trial left out of fits and gaps.
    n_jackknife : calibration blocks of the jackknife intervals (0: no intervals).
    significance_sigma, floor_margin : the nominal gap's significance threshold.
    noise_floor : "coherence" (the Welch non-coherent floor, the white level above the
        band when there are too few segments) or "white" (always the white level: the
        floor before issue 21, kept for comparison benches).
    model_tolerance : relative gap (of the band's torque energy) a nominal model may leave
        unexplained whatever the noise: the discrete model's own error (central
        differences, the analysis low-pass, the offsets), which the coherence floor counts
        as gap. ``"measured"`` (default): per record, ``tolerance_factor`` times the
        pipeline's own residual on a noise-free torque of the fitted nominal limb,
        simulated from the record's measured angle with derivatives of 8th order
        (:func:`_pipeline_tolerance`); a number: that constant for every record (1e-4 was
        the constant before; up to 2.6e-5 measured on labsim's nominal sets).
    tolerance_factor : the measured tolerance's multiple of the noise-free residual.
    name_reduction : held-out reduction an effect needs to be named.
    grid : grid points per nonlinear parameter; refine_starts: grid points refined.
    pairs : try a second effect on top of the best single (diagnosis.limbpairs).
    time_gate : a change found by the shared time-variation test (estimation.timevarying,
        the one ``armimp estimate`` warns from) on any record and joint makes the gap
        significant whatever the whole-record gap says: a gap confined to part of a
        record is not averaged away, and the two commands never contradict each other.
    form_profile : widen the named (best) fit's jackknife intervals to their envelope over
        refits at the plausible alternatives of the choices the fit ties or picks
        (diagnosis.formprofile: reflex and wobbling-mass damping, rectification).
    search_trials : with more records than this, the grid and the Nelder-Mead search of a
        candidate's nonlinear parameters run on this many evenly spaced records, and only
        the final refinement on all (a session's cost then grows with the records through
        the refinements alone; 0: always all records). The answer is the optimum on all
        records from the subset's start, as for any start.
    """

    band_hz: float = 30.0
    band_low_hz: float = 0.3
    lowpass_order: int = 8
    welch_s: float = 2.0
    held_out_fraction: float = 1.0 / 3.0
    n_jackknife: int = 6
    significance_sigma: float = 4.0
    floor_margin: float = 0.1
    name_reduction: float = 0.5
    grid: int = 12
    refine_starts: int = 2
    effects: tuple = ()
    edge_s: tuple = (1.0, 0.5)
    pairs: bool = True
    noise_floor: str = "coherence"
    time_gate: bool = True
    form_profile: bool = True
    model_tolerance: float | str = "measured"
    tolerance_factor: float = 2.0
    search_trials: int = 16


@dataclass
class PositionRecord:
    """One position-perturbation trial as the fits see it.

    theta, tau : (N, n) measured angle [rad] and torque [N m] (device on limb);
    theta_ref : (N, n) servo reference [rad] or None; fs [Hz]; name for messages.
    """

    theta: np.ndarray
    tau: np.ndarray
    fs: float
    theta_ref: np.ndarray | None = None
    name: str = ""

    def __post_init__(self):
        self.theta = lm._as_signal(self.theta, f"{self.name or 'trial'} theta")
        n = self.theta.shape[1]
        self.tau = lm._as_signal(self.tau, f"{self.name or 'trial'} tau_h", n)
        if self.tau.shape[0] != self.theta.shape[0]:
            raise ValueError(f"{self.name or 'trial'}: theta has {self.theta.shape[0]} "
                             f"samples, tau_h {self.tau.shape[0]}")
        if self.theta_ref is not None:
            self.theta_ref = lm._as_signal(self.theta_ref, f"{self.name or 'trial'} "
                                           f"theta_ref", n)
        self.fs = float(self.fs)

    @property
    def n_dof(self) -> int:
        return int(self.theta.shape[1])

    @classmethod
    def from_trial(cls, trial) -> "PositionRecord":
        """From a trialformat.Trial of a position perturbation (theta, tau_h[, theta_ref]);
        its scheduling variable (trialformat.scheduling, None when stationary) kept as
        ``scheduling`` for the state-varying effects."""
        rec = cls(trial.signal("theta"), trial.signal("tau_h"), trial.fs,
                  trial.theta_ref, trial.name)
        from trialformat import scheduling as sch
        try:
            rec.scheduling = sch.scheduling_of(trial)
        except Exception:  # noqa: BLE001 - an auxiliary variable never sinks a file
            rec.scheduling = None
        if rec.scheduling is not None and sch.varying_refusal(rec.scheduling, trial.name):
            rec.scheduling = None  # refused as estimate refuses it (diagnose warns)
        return rec


# ----------------------------------------------------------------------------- design
class _Prepared:
    """Per-record cached signals: derivatives, low-passed torque, masks, noise floors."""

    def __init__(self, rec: PositionRecord, cfg: FitConfig):
        self.rec, self.fs, self.n = rec, rec.fs, rec.n_dof
        N = rec.theta.shape[0]
        self.N = N
        self.band = min(cfg.band_hz, 0.2 * rec.fs)
        self.sos = signal.butter(cfg.lowpass_order, self.band, fs=rec.fs, output="sos")
        self._zi = signal.sosfilt_zi(self.sos)
        # low-passed signals are kept every D-th sample (D fs / D >= 4 band): the fits
        # solve on those rows, the gap's spectra use fs_d
        self.D = max(1, int(rec.fs // (4.0 * self.band)))
        self.fs_d = rec.fs / self.D
        self.omega, self.alpha = lm.derivatives(rec.theta, rec.fs)
        self.tau_lp = self.lp(rec.tau)
        Nd = self.tau_lp.shape[0]
        self.Nd = Nd
        n_cal = int(round(Nd * (1.0 - cfg.held_out_fraction)))
        self.cal = np.zeros(Nd, bool)
        self.cal[:n_cal] = True
        self.held = ~self.cal
        # the ends are left out of every fit and gap: one-sided derivatives, the filters'
        # start from rest and the zero-phase low-pass's edges live there
        head, tail = int(round(cfg.edge_s[0] * self.fs_d)), int(round(cfg.edge_s[1] * self.fs_d))
        if head + tail >= Nd // 2:
            raise ValueError(f"{rec.name or 'trial'}: {N / rec.fs:g} s is too short for the "
                             f"position fits (at least {4 * sum(cfg.edge_s):g} s)")
        self.cal[:head] = False
        self.held[Nd - tail:] = False
        # the samples any fit or gap may use (the default split's two parts): a varying
        # effect's split swaps cal and held in and out (varying_effects.swapped), this not
        self.usable = self.cal | self.held
        if rec.theta_ref is not None:
            self.theta_lp = self.lp(rec.theta)
        self.t = (np.arange(N) / rec.fs)[::self.D]
        self.base = self._base_columns()
        self.offset_cols = self.offsets()
        self.noise_tau = _white_level(rec.tau, rec.fs)
        self.noise_theta = _white_level(rec.theta, rec.fs)

    def reflex(self, params: dict):
        """lm.reflex_torque of this record's velocity for the stretch reflex ``params``,
        its delayed (and rectified) velocity kept for the last two delays and
        rectifications (a search varies the activation frequency at one delay: the grid's
        inner axis)."""
        p = lm.effect_params("stretch_reflex", params)
        key = lm.reflex_drive_key(p)
        cache = self.__dict__.setdefault("_reflex_drive", {})
        v = cache.get(key)
        if v is None:
            v = lm.reflex_drive(self.omega, self.fs, p)
            if len(cache) >= 2:
                cache.pop(next(iter(cache)))  # the oldest
            cache[key] = v
        return lm.reflex_torque(self.omega, self.fs, params, drive=v)

    def motion_inputs(self):
        """The coherence floor's inputs (:func:`_motion_inputs`), computed once."""
        if "_inputs" not in self.__dict__:
            self.__dict__["_inputs"] = _motion_inputs(self)
        return self.__dict__["_inputs"]

    def lp(self, x, decimate: bool = True):
        """Zero-phase low-pass (forwards and backwards, odd extension of 0.5 s at each
        end, each pass started at its first value), every D-th sample kept (all with
        ``decimate=False``)."""
        pad = min(x.shape[0] - 1, int(0.5 * self.fs))
        ext = np.concatenate([2 * x[:1] - x[pad:0:-1], x, 2 * x[-1:] - x[-2:-pad - 2:-1]])
        zi = self._zi.reshape(self._zi.shape + (1,) * (ext.ndim - 1))
        y, _ = signal.sosfilt(self.sos, ext, axis=0, zi=zi * ext[:1])
        y = y[::-1]
        y, _ = signal.sosfilt(self.sos, y, axis=0, zi=zi * y[:1])
        y = y[::-1][pad:pad + x.shape[0]]
        return y[::self.D] if decimate else y

    def intrinsic_raw(self, scale=None):
        """Raw (N, n, 3 n^2) columns of K, B, I entries (K columns scaled)."""
        n, N = self.n, self.N
        cols = np.zeros((N, n, 3 * n * n))
        th = self.rec.theta
        if scale is not None:
            scale = np.broadcast_to(scale, th.shape)
        for j in range(n):
            for k in range(n):
                c = j * n + k
                cols[:, j, c] = th[:, k] * (1.0 if scale is None else scale[:, j])
                cols[:, j, n * n + c] = self.omega[:, k]
                cols[:, j, 2 * n * n + c] = self.alpha[:, k]
        return cols

    def offsets(self):
        n, N = self.n, self.Nd
        cols = np.zeros((N, n, 2 * n))
        for j in range(n):
            cols[:, j, j] = 1.0
            cols[:, j, n + j] = self.t - self.t[-1] / 2
        return cols

    def _base_columns(self):
        raw = self.intrinsic_raw()
        # kept at the full rate too: the torque-channel effects (a sensor low-pass, a
        # channel delay) are linear and time-invariant, so they commute with the
        # analysis low-pass and are applied to these columns directly (the edges, where
        # the two orders differ, are left out of every fit)
        self.base_full = self.lp(raw.reshape(self.N, -1), decimate=False)
        return self.base_full[::self.D].reshape((self.Nd,) + raw.shape[1:])

    def columns(self, name: str | None, params: dict):
        """Low-passed design columns (N, n, p) shared across records, for the effect
        ``name`` with nonlinear ``params`` (linear ones excluded)."""
        if vary.is_varying(name):
            return vary.columns(self, name, params)
        eff = {} if name is None else {name: _with_unit_linear(name, params)}
        channel = name in lm.CHANNEL_EFFECTS
        scaled = name in ("stiffness_amplitude", "stiffness_drift")
        extra = []
        if name == "stretch_reflex":
            extra.append(self.reflex(eff[name]))
        elif name == "wobbling_mass":
            p = lm.effect_params(name, eff[name])
            b, a = lm.second_order_lowpass(float(p["frequency_hz"]), float(p["damping"]),
                                           self.fs, numerator="spring_damper")
            extra.append(signal.lfilter(b, a, self.alpha, axis=0))
        if not channel and not scaled:
            cols = self.base
            if extra:
                ex = self.lp(np.stack(extra, axis=2).reshape(self.N, -1))
                cols = np.concatenate([cols, ex.reshape(self.Nd, self.n, -1)], axis=2)
            return cols
        if channel:
            out = lm.channel_apply(self.base_full, self.fs, eff)[::self.D]
            return out.reshape(self.base.shape)
        scale = lm.stiffness_scale(self.rec.theta, self.fs, eff) if scaled else None
        raw = self.intrinsic_raw(scale)
        if channel:
            shape = raw.shape
            raw = lm.channel_apply(raw.reshape(self.N, -1), self.fs, eff).reshape(shape)
        return self.lp(raw.reshape(self.N, -1)).reshape((self.Nd,) + raw.shape[1:])


def _with_unit_linear(name, params):
    p = dict(params)
    for key in LINEAR.get(name, ()):
        p[key] = 1.0
    return p


def _white_level(x, fs):
    """Median Welch PSD of each column of x in [0.25, 0.45] fs (the white noise level)."""
    f, p = signal.welch(x, fs=fs, nperseg=min(x.shape[0], 1024), axis=0)
    sel = (f >= 0.25 * fs) & (f <= 0.45 * fs)
    return np.median(p[sel], axis=0)


# ----------------------------------------------------------------------------- solve
@dataclass
class _Solution:
    coef: np.ndarray            # shared coefficients (p,)
    offsets: list               # per record (2n,)
    residual: list              # per record low-passed torque residual (N, n)
    cal_energy: float           # sum over records of the normalised calibration SSR


def _solve(preps, cols_list, masks=None) -> _Solution:
    """Least squares of the low-passed torque on shared columns + per-record offsets.

    The offsets (a constant and a trend per record and joint) are projected out of every
    record's rows first (Frisch-Waugh-Lovell): the shared coefficients are those of the
    least squares of the projected torque on the projected columns, and each record's
    offsets follow from its own rows. Same solution as one dense solve with offset
    columns per record (:func:`_solve_dense`), at a cost linear in the records (the dense
    design has a column pair per record and joint: its cost grows with the square of the
    records, cubically in the normal equations)."""
    p = cols_list[0].shape[2]
    parts = []
    for i, (pr, cols) in enumerate(zip(preps, cols_list)):
        m = pr.cal if masks is None else masks[i]
        parts.append(_project_offsets(pr, cols, m))
    G = np.zeros((p, p))
    b = np.zeros(p)
    for Xr, yr, _, _ in parts:
        G += Xr.T @ Xr
        b += Xr.T @ yr
    scale = np.sqrt(np.diag(G)).copy()
    scale[scale == 0] = 1.0
    try:  # normal equations of the column-scaled problem (p is small; fast under load)
        coef = np.linalg.solve(G / np.outer(scale, scale), b / scale) / scale
    except np.linalg.LinAlgError:
        As = np.vstack([Xr for Xr, _, _, _ in parts]) / scale
        coef, *_ = np.linalg.lstsq(As, np.concatenate([yr for _, yr, _, _ in parts]),
                                   rcond=None)
        coef = coef / scale
    residual, offsets, energy = [], [], 0.0
    for i, (pr, cols) in enumerate(zip(preps, cols_list)):
        m = pr.cal if masks is None else masks[i]
        _, _, Q, R = parts[i]
        fit = pr.tau_lp - cols @ coef                      # (Nd, n)
        qo = Q.T @ fit[m]                                   # (k, n) projections
        c = np.linalg.lstsq(R, qo, rcond=None)[0]           # (2, n): constant, trend
        o = c.reshape(-1)                                   # [const_j..., trend_j...]
        r = fit - pr.offset_cols @ o
        energy += float(np.sum(r[m] ** 2)) / pr.norm ** 2
        residual.append(r)
        offsets.append(o)
    return _Solution(coef, offsets, residual, energy)


def _project_offsets(pr, cols, m):
    """The record's masked rows with its offsets projected out (a constant and a trend
    per joint, the same two on every joint's rows): (Xr (M n, p), yr (M n,)) scaled by
    1 / pr.norm, and the orthonormal basis Q (M, k) of the offsets' span on those rows with
    R (k, 2), offset basis = Q R."""
    p = cols.shape[2]
    Q, R = _offset_basis(pr, m)
    X = cols[m].reshape(Q.shape[0], -1)                     # (M, n p)
    y = pr.tau_lp[m]                                        # (M, n)
    Xr = X - Q @ (Q.T @ X)
    yr = y - Q @ (Q.T @ y)
    return Xr.reshape(-1, p) / pr.norm, yr.reshape(-1) / pr.norm, Q, R


#: offset bases kept per record (the masks of a fit, its jackknife blocks and splits)
_OFFSET_CACHE = 16


def _offset_basis(pr, m):
    """(Q, R) of :func:`_project_offsets` for record ``pr`` on mask ``m``: a function of
    the mask alone, kept per record for the last _OFFSET_CACHE masks (every evaluation of
    a search solves on the same rows)."""
    cache = pr.__dict__.setdefault("_offset_qr", {})
    key = hash(m.tobytes())
    hit = cache.get(key)
    if hit is not None and np.array_equal(hit[0], m):
        return hit[1], hit[2]
    basis = np.stack([np.ones(int(m.sum())), pr.t[m] - pr.t[-1] / 2], axis=1)
    Q, R = np.linalg.qr(basis)
    keep = np.abs(np.diag(R)) > 1e-12 * max(1.0, np.abs(R).max())
    Q, R = Q[:, keep], R[keep]
    if len(cache) >= _OFFSET_CACHE:
        cache.pop(next(iter(cache)))  # the oldest
    cache[key] = (m.copy(), Q, R)
    return Q, R


def _solve_dense(preps, cols_list, masks=None) -> _Solution:
    """:func:`_solve` as one dense least squares with offset columns per record (the
    reference its tests compare against; its cost grows with the square of the records)."""
    p = cols_list[0].shape[2]
    n_off = [2 * pr.n for pr in preps]
    rows_a, rows_y = [], []
    offs = [pr.offset_cols for pr in preps]
    total_off = sum(n_off)
    start = 0
    for i, (pr, cols) in enumerate(zip(preps, cols_list)):
        m = pr.cal if masks is None else masks[i]
        A = np.zeros((int(m.sum()) * pr.n, p + total_off))
        A[:, :p] = cols[m].reshape(-1, p)
        A[:, p + start:p + start + n_off[i]] = offs[i][m].reshape(-1, n_off[i])
        rows_a.append(A / pr.norm)
        rows_y.append(pr.tau_lp[m].reshape(-1) / pr.norm)
        start += n_off[i]
    A = np.vstack(rows_a)
    y = np.concatenate(rows_y)
    scale = np.sqrt(np.sum(A * A, axis=0))
    scale[scale == 0] = 1.0
    As = A / scale
    try:
        x = np.linalg.solve(As.T @ As, As.T @ y)
    except np.linalg.LinAlgError:
        x, *_ = np.linalg.lstsq(As, y, rcond=None)
    x = x / scale
    coef = x[:p]
    residual, offsets, energy, start = [], [], 0.0, 0
    for i, (pr, cols) in enumerate(zip(preps, cols_list)):
        o = x[p + start:p + start + n_off[i]]
        start += n_off[i]
        r = pr.tau_lp - cols @ coef - offs[i] @ o
        m = pr.cal if masks is None else masks[i]
        energy += float(np.sum(r[m] ** 2)) / pr.norm ** 2
        residual.append(r)
        offsets.append(o)
    return _Solution(coef, offsets, residual, energy)


def _limb_from(coef, n) -> lm.LimbModel:
    nn = n * n
    return lm.LimbModel(coef[:nn].reshape(n, n), coef[nn:2 * nn].reshape(n, n),
                        coef[2 * nn:3 * nn].reshape(n, n))


# ----------------------------------------------------------------------------- gap
def _band_energy(r, pr: _Prepared, mask, cfg: FitConfig, floor_fn=None):
    """(energy above the floor, standard error) of residual r (N, n) on ``mask`` rows,
    integrated over [band_low_hz, band] (the low-pass response applied to the floor)."""
    x = r[mask]
    nper = int(min(x.shape[0], round(cfg.welch_s * pr.fs_d)))
    f, P = signal.welch(x, fs=pr.fs_d, nperseg=nper, axis=0)
    sel = (f >= cfg.band_low_hz) & (f <= pr.band)
    df = f[1] - f[0]
    n_avg = max(1.0, 2.0 * x.shape[0] / nper - 1.0)
    E = float(np.sum(P[sel])) * df
    se = float(np.sqrt(np.sum(P[sel] ** 2) / n_avg)) * df * 1.5
    floor = 0.0
    if floor_fn is not None:
        _, h = signal.sosfreqz(pr.sos, worN=f[sel], fs=pr.fs)  # the filter ran at fs
        floor = float(np.sum(floor_fn(f[sel]) * np.abs(h) ** 4)) * df
    return E - floor, se, floor


# ----------------------------------------------------------------------------- floor
#: the floor sources, in order of preference (issue 21 item 1); the report names the one used
FLOOR_COHERENCE = ("welch non-coherent: the part of the residual not coherent, across the "
                   "Welch segments of the analysis band, with the servo reference (else the "
                   "angle) and non-linear "
                   "functions of the motion (theta^2, theta^3, |w| w, a smoothed sign(w), "
                   "two play operators), bias-corrected for the number of segments and "
                   "inputs")
FLOOR_WHITE = ("spectrum above the band: white torque and angle noise at the level of their "
               "spectra in [0.25, 0.45] fs (too few Welch segments for the coherence floor; "
               "a non-linear effect's harmonics can raise it)")


@dataclass
class _Floor:
    """The noise floor of one record on one mask: what the model may leave unexplained.

    energy : floor energy over the analysis band, summed over joints [N^2 m^2];
    se : standard error, under noise alone, of (band energy - floor) [N^2 m^2];
    source : FLOOR_COHERENCE or FLOOR_WHITE.
    """

    energy: float
    se: float
    source: str


#: widths of the play (backlash) operators among the floor's inputs, in units of the
#: angle's standard deviation: hysteresis that a static function of the motion misses
#: (friction in stick between the steps of a PRBS, a play between encoder and footplate)
PLAY_WIDTHS = (0.05, 0.3)
#: the motion the non-linear functions are taken of is low-passed at this multiple of the
#: analysis band (4th order, zero phase): above the band where the perturbation has power,
#: below where the angle's sensor noise dominates its velocity
MOTION_BAND = 2.5
#: ... and high-passed here: a subject's voluntary torque (0-2 Hz) moves the joint against
#: the servo; of a two-level perturbation (PRBS), theta^3 - A^2 theta is that displacement
#: alone, which the floor would then count as gap
MOTION_HIGHPASS_HZ = 3.0
#: width of the smoothed sign(w), in units of the velocity's standard deviation
SIGN_WIDTH = 0.1


def _play(x, width):
    """Play operator of x (N,) of half-width ``width``: y follows x only when x leaves
    [y - width, y + width]; returns (x - y) / width in [-1, 1]."""
    y = np.empty_like(x)
    cur = float(x[0])
    for i, v in enumerate(x.tolist()):
        if v > cur + width:
            cur = v - width
        elif v < cur - width:
            cur = v + width
        y[i] = cur
    return (x - y) / width


def _nonlinear_functions(theta, omega):
    """(N, m) static and hysteretic functions of one joint's motion (theta, omega (N,)),
    centred and of unit RMS: theta^2, theta^3, |w| w, tanh(w / (0.1 std w)) (Coulomb
    friction), play operators of PLAY_WIDTHS (stick-slip, backlash)."""
    x = theta - np.mean(theta)
    sx = float(np.std(x)) or 1.0
    sw = float(np.std(omega)) or 1.0
    cols = [(x / sx) ** 2, (x / sx) ** 3, np.abs(omega) * omega / sw ** 2,
            np.tanh(omega / (SIGN_WIDTH * sw))]
    cols += [_play(x, w * sx) for w in PLAY_WIDTHS]
    return np.stack(cols, axis=1)


def _motion_inputs(pr: _Prepared):
    """(Nd, n, q) low-passed, decimated inputs of the coherence floor for each joint's
    channel (torque and, with a reference, angle): the servo reference of every joint
    when recorded, else the measured angle, then the functions of the joint's own motion
    (:func:`_nonlinear_functions`), each centred and of unit RMS. Any residual coherent
    with these (through an LTI filter of each) is model error, not noise."""
    # the perturbation itself when recorded: a torque the subject adds moves the joint
    # against the servo and is then coherent with the measured angle, never with the
    # reference
    th = pr.rec.theta if pr.rec.theta_ref is None else pr.rec.theta_ref
    n = pr.n
    # the functions of the *band-limited* motion: of the raw angle, they would carry its
    # sensor noise (a function's slope times the noise, most of all for sign(w) near rest),
    # which is coherent with the residual's share of that noise (-Z n_theta): noise
    # counted as gap (measured on labsim's nominal PRBS sets)
    top = min(MOTION_BAND * pr.band, 0.45 * pr.fs)
    sos = (signal.butter(4, [MOTION_HIGHPASS_HZ, top], btype="bandpass", fs=pr.fs,
                         output="sos") if MOTION_HIGHPASS_HZ > 0 else
           signal.butter(4, top, fs=pr.fs, output="sos"))
    th_b = signal.sosfiltfilt(sos, pr.rec.theta, axis=0)
    w_b = np.gradient(th_b, 1.0 / pr.fs, axis=0)
    nl = [_nonlinear_functions(th_b[:, k], w_b[:, k]) for k in range(n)]
    m = nl[0].shape[1]
    full = np.zeros((pr.N, n, n + m))
    for j in range(n):
        full[:, j, :n] = th
        full[:, j, n:] = nl[j]
    full = full - full.mean(axis=0)
    sd = full.std(axis=0)
    full = full / np.where(sd > 0, sd, 1.0)
    return pr.lp(full.reshape(pr.N, -1)).reshape(pr.Nd, n, n + m)


#: window of the local-impedance input of the coherence floor [s]: short against the
#: time a limb takes to change state (a co-contraction level held 3-10 s, a drift, a
#: movement of 10-20 s period), long against the parameters it fits (3 n per joint)
LOCAL_WINDOW_S = 1.0


def _local_input(pr: _Prepared, r0):
    """(Nd, n, 1) the local-impedance input of the coherence floor, and the share of a
    white residual's in-band energy its fit takes.

    Per window of LOCAL_WINDOW_S and joint j, the nominal residual r0[:, j] is regressed
    on that joint's K, B, I columns, band-passed from MOTION_HIGHPASS_HZ to the analysis
    band (and a constant); the input is the fitted
    torque (the constant's share left out). A limb whose K, B or I changes in time or
    with the state leaves in r0 the torque dK(t) theta + dB(t) w + dI(t) a, which no LTI
    filter of a stationary input reproduces, so the floor's other inputs leave it in the
    floor: the effect would set its own threshold (a stiffness switching 1 <-> 2x gave a
    floor of 12 % of the torque energy, its gap hidden). Of a stationary limb the windows
    fit noise alone: p of the window's in-band degrees of freedom, corrected for."""
    n, Nd = pr.n, pr.Nd
    w = max(8, int(round(LOCAL_WINDOW_S * pr.fs_d)))
    u = np.zeros((Nd, n, 1))
    p = 0
    # the columns high-passed as the floor's motion functions are: a voluntary torque
    # (0-2 Hz) moves the joint against the servo, which a window's fit on the raw angle
    # takes for a changing stiffness (labsim's voluntary sets: the floor 12 % lower)
    lo = min(MOTION_HIGHPASS_HZ, 0.5 * pr.band)
    hp = signal.butter(2, lo, btype="highpass", fs=pr.fs_d, output="sos")
    base = signal.sosfiltfilt(hp, pr.base, axis=0)
    for j in range(n):
        cols = base[:, j, :]
        cols = cols[:, np.any(cols != 0.0, axis=0)]
        p = cols.shape[1] + 1
        for a in range(0, Nd, w):
            b = Nd if Nd - a < 2 * w else a + w   # the last window takes the remainder
            A = np.column_stack([cols[a:b], np.ones(b - a)])
            c = np.linalg.lstsq(A, r0[a:b, j], rcond=None)[0]
            u[a:b, j, 0] = cols[a:b] @ c[:-1]
            if b == Nd:
                break
    u = u - u.mean(axis=0)
    sd = u.std(axis=0)
    u = u / np.where(sd > 0, sd, 1.0)
    in_band = max(1e-9, 2.0 * (pr.band - lo) / pr.fs_d)  # band-passed columns
    share = min(0.5, p / (w * in_band))
    return u, share


#: Hann segments overlapping by half: the squared correlation of neighbouring segments'
#: periodograms of white noise is 1/9, so K segments count as K / (1 + 2/9) independent ones
_OVERLAP_FACTOR = 1.0 + 2.0 / 9.0


def _segments_fft(x, nper):
    """Hann-windowed, mean-removed FFTs of 50 %-overlapping segments of x (N, c):
    (K, nf, c) and the one-sided density scale (as scipy.signal.welch)."""
    step = nper // 2
    starts = np.arange(0, x.shape[0] - nper + 1, step)
    win = signal.get_window("hann", nper)
    seg = np.stack([x[s:s + nper] for s in starts])
    seg = seg - seg.mean(axis=1, keepdims=True)
    X = np.fft.rfft(seg * win[None, :, None], axis=1)
    return X, 1.0 / np.sum(win ** 2)


def _coherence_floor(r, X, pr: _Prepared, mask, cfg: FitConfig, fitted_share=0.0):
    """The non-coherent floor of residual r (Nd, n) given inputs X (Nd, n, q) on ``mask``
    rows, or None when there are too few Welch segments for q inputs.

    Per frequency bin and joint, the residual's PSD conditioned on the q inputs,
    S_rr (1 - gamma^2), divided by (1 - q / n) (n the equivalent number of independent
    segments: the conditioned spectrum of noise alone keeps n - q of n degrees of
    freedom), summed over the analysis band. Under noise alone gamma^2 is Beta(q, n - q):
    that variance, with 1.5 for the correlation of neighbouring Hann bins, gives ``se``.
    ``fitted_share``: the share of a white residual's in-band energy that inputs fitted to
    r itself take (:func:`_local_input`); the floor is divided by (1 - it) too."""
    x, u = r[mask], X[mask]
    nper = int(min(x.shape[0], round(cfg.welch_s * pr.fs_d)))
    if x.shape[0] < nper or nper < 8:
        return None
    q = u.shape[2]
    R, scale = _segments_fft(x, nper)
    f = np.fft.rfftfreq(nper, 1.0 / pr.fs_d)
    sel = (f >= cfg.band_low_hz) & (f <= pr.band)
    n_eff = R.shape[0] / _OVERLAP_FACTOR
    if n_eff < 1.5 * q + 4:  # too few degrees of freedom left for the noise
        return None
    df = f[1] - f[0]
    beta = q / n_eff
    var_g = q * (n_eff - q) / (n_eff ** 2 * (n_eff + 1.0))
    energy = var = 0.0
    for j in range(pr.n):
        U, _ = _segments_fft(u[:, j, :], nper)          # (K, nf, q)
        Rj = R[:, :, j][:, sel]                          # (K, b)
        Uj = U[:, sel, :]                                # (K, b, q)
        s_rr = np.mean(np.abs(Rj) ** 2, axis=0)
        s_uu = np.einsum("kbi,kbj->bij", Uj.conj(), Uj) / Uj.shape[0]
        s_ur = np.einsum("kbi,kb->bi", Uj.conj(), Rj) / Uj.shape[0]
        coh = np.zeros(s_rr.shape)
        for b in range(s_rr.size):
            h = np.linalg.lstsq(s_uu[b], s_ur[b], rcond=1e-10)[0]
            coh[b] = min(1.0, max(0.0, float(np.real(np.vdot(s_ur[b], h))) /
                                  s_rr[b])) if s_rr[b] > 0 else 0.0
        p = 2.0 * scale / pr.fs_d * s_rr               # one-sided density, as welch
        noise = p * (1.0 - coh) / ((1.0 - beta) * (1.0 - fitted_share))
        energy += float(np.sum(noise)) * df
        var += float(np.sum(noise ** 2)) * var_g / (1.0 - beta) ** 2
    return _Floor(energy, 1.5 * df * math.sqrt(var), FLOOR_COHERENCE)


def _mask_key(part, mask):
    return (part, hash(mask.tobytes()))


def _floors(pr: _Prepared, mask, cfg: FitConfig, limb0, part: str):
    """(torque floor, angle floor or None) of record ``pr`` on ``mask``, from the nominal
    residual (``pr.nominal_residual``, set by :func:`fit_nominal`): computed once per
    mask and kept, so every candidate is judged against the same floor, which no
    candidate's own residual can raise. Falls back to the white level above the band."""
    cache = pr.__dict__.setdefault("_floor_cache", {})
    key = _mask_key(part, mask)
    if key in cache:
        return cache[key]
    if cfg.noise_floor not in ("coherence", "white"):
        raise ValueError(f"FitConfig.noise_floor = {cfg.noise_floor!r}: 'coherence' or 'white'")
    coherence = cfg.noise_floor == "coherence"
    r0, a0 = pr.nominal_residual
    fl = None
    if coherence:
        u, share = _local_input(pr, r0)
        X = np.concatenate([pr.motion_inputs(), u], axis=2)
        fl = _coherence_floor(r0, X, pr, mask, cfg, share)
    if fl is None:
        _, s, e = _band_energy(r0, pr, mask, cfg, _torque_floor(pr, limb0))
        fl = _Floor(e, s, FLOOR_WHITE)
    fa = None
    if a0 is not None:
        fa = (_coherence_floor(a0, pr.motion_inputs(), pr, mask, cfg)
              if coherence else None)
        if fa is None:
            _, s, e = _band_energy(a0, pr, mask, cfg,
                                   lambda f: np.full(f.shape, float(np.sum(pr.noise_theta))))
            fa = _Floor(e, s, FLOOR_WHITE)
    cache[key] = (fl, fa)
    return fl, fa


def _torque_floor(pr: _Prepared, limb: lm.LimbModel):
    """Expected residual noise PSD at f summed over joints: torque noise plus the angle
    noise through the impedance K + j w B - w^2 I."""
    def fn(f):
        w = 2 * np.pi * f
        out = np.full(f.shape, float(np.sum(pr.noise_tau)))
        for j in range(pr.n):
            for k in range(pr.n):
                z = limb.K[j, k] + 1j * w * limb.B[j, k] - w * w * limb.I[j, k]
                out += np.abs(z) ** 2 * pr.noise_theta[k]
        return out
    return fn


@dataclass
class _Gap:
    value: float          # relative excess energy (clipped at 0)
    excess: float         # unclipped
    se: float             # standard error of ``excess``
    floor: float          # relative noise floor
    source: str = FLOOR_COHERENCE   # the floor source (FLOOR_WHITE if any record used it)
    tolerance: float = 0.0          # measured model tolerance, summed over records
    tolerances: tuple = ()          # ... per record (relative to that record's torque)

    def significant(self, cfg: FitConfig) -> bool:
        return self.excess > self.threshold(cfg)

    def residual_against(self, nominal_gap: float) -> dict:
        """This fit's held-out residual beside the nominal's, floor included (issue 21:
        a gap clipped at the floor is no measurement of how much the model explains).

        ``nominal_gap``: the nominal gap on the same mask and split (relative, clipped).
        Returns ``{"floor", "residual", "nominal_residual", "residual_reduction",
        "clipped"}``: relative energies (torque energy = 1); ``clipped`` when this
        residual lies below the floor (its gap reads 0 whatever it is)."""
        nominal = max(float(nominal_gap), 0.0) + self.floor
        own = self.excess + self.floor
        return {"floor": float(self.floor), "residual": float(own),
                "nominal_residual": float(nominal),
                "residual_reduction": float(1.0 - own / nominal) if nominal > 0 else None,
                "clipped": bool(self.excess < 0)}

    def model_tolerance(self, cfg: FitConfig) -> float:
        """The model tolerance the threshold adds: the measured one (summed over the
        records, as the gap is) or ``cfg.model_tolerance`` when that is a number."""
        return self.tolerance if _measured_tolerance(cfg) else float(cfg.model_tolerance)

    def threshold(self, cfg: FitConfig) -> float:
        """significance_sigma standard errors + floor_margin x floor + model tolerance."""
        return (cfg.significance_sigma * self.se + cfg.floor_margin * self.floor
                + self.model_tolerance(cfg))

    def tolerance_report(self, preps, cfg: FitConfig) -> dict:
        """The model tolerance used, per record, for report.json."""
        measured = _measured_tolerance(cfg)
        per = [{"record": pr.rec.name or f"record {i}",
                "tolerance": float(self.tolerances[i]) if measured and
                i < len(self.tolerances) else float(cfg.model_tolerance)}
               for i, pr in enumerate(preps)]
        return {"model_tolerance": float(self.model_tolerance(cfg)),
                "model_tolerance_source": (TOLERANCE_MEASURED.format(cfg.tolerance_factor)
                                           if measured else TOLERANCE_CONSTANT),
                "model_tolerance_per_record": per}


#: what the report says of the model tolerance (``gap.model_tolerance_source``)
TOLERANCE_MEASURED = ("measured per record: {:g} x the relative band energy of the "
                      "pipeline's own residual on a noise-free torque of the fitted nominal "
                      "limb, simulated from the record's measured angle with 8th-order "
                      "derivatives (the discrete model's error: central differences, "
                      "low-pass, offsets)")
TOLERANCE_CONSTANT = "constant (FitConfig.model_tolerance), the same for every record"


def _measured_tolerance(cfg: FitConfig) -> bool:
    if isinstance(cfg.model_tolerance, str):
        if cfg.model_tolerance != "measured":
            raise ValueError(f"FitConfig.model_tolerance = {cfg.model_tolerance!r}: "
                             f"'measured' or a number")
        return True
    return False


#: 8th-order central-difference stencils of the first and second derivative (offsets
#: -4..4, times fs and fs^2): their error at the analysis band's top (30 Hz at 1 kHz) is
#: below 1e-8 of the derivative, where the pipeline's second-order differences are off by
#: 0.6 % (velocity) and 0.3 % (acceleration)
_D1 = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0.0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])
_D2 = np.array([-1 / 560, 8 / 315, -1 / 5, 8 / 5, -205 / 72, 8 / 5, -1 / 5, 8 / 315,
                -1 / 560])


def _accurate_derivatives(theta, fs):
    """Velocity and acceleration of theta (N, n) by the 8th-order stencils (the
    pipeline's own second-order ones in the 4 samples at each end, which no fit uses)."""
    omega, alpha = lm.derivatives(theta, fs)
    omega, alpha = omega.copy(), alpha.copy()
    N = theta.shape[0]
    if N > 9:
        for j in range(theta.shape[1]):
            # np.convolve flips the kernel: pass it reversed for a correlation
            omega[4:N - 4, j] = np.convolve(theta[:, j], _D1[::-1], mode="valid") * fs
            alpha[4:N - 4, j] = np.convolve(theta[:, j], _D2[::-1], mode="valid") * fs * fs
    return omega, alpha


def _clean_proxies(preps, limb: lm.LimbModel):
    """Copies of the records whose low-passed torque is a noise-free torque of ``limb``
    simulated from each record's own measured angle with accurate derivatives."""
    import copy
    proxies = []
    for pr in preps:
        th = pr.rec.theta
        om, al = _accurate_derivatives(th, pr.fs)
        tau = th @ limb.K.T + om @ limb.B.T + al @ limb.I.T
        q = copy.copy(pr)
        q.tau_lp = pr.lp(tau)
        proxies.append(q)
    return proxies


def _clean_residuals(preps, limb: lm.LimbModel):
    """The pipeline's residual (per record, low-passed, decimated) on a noise-free torque
    of ``limb`` (:func:`_clean_proxies`), fitted as the nominal model is (shared K, B, I,
    offsets per record)."""
    return _solve(_clean_proxies(preps, limb), [pr.base for pr in preps]).residual


def derivative_allowance(preps, limb: lm.LimbModel) -> dict:
    """What the pipeline's own derivatives (second-order central differences,
    :func:`limb.derivatives`) move ``limb``'s K, B, I by on these records: the nominal
    model fitted (as :func:`fit_nominal`) to a noise-free torque of ``limb`` simulated from
    each record's measured angle with accurate derivatives (:func:`_accurate_derivatives`),
    minus ``limb``. {"K_h", "B_h", "M_h"}: the absolute differences, (n, n) lists, for an
    interval's allowance (the differences make the fitted inertia ~1 % high and the
    viscosity ~0.4 % high at a 40 Hz band, 1 kHz: the stencil's gain falls as
    1 - (w h)^2 / 3 for the acceleration). A choice of the pipeline's form, like the
    effects' tied choices: truth and fit differ by it whatever the data."""
    fitted = _limb_from(_solve(_clean_proxies(preps, limb), [pr.base for pr in preps]).coef,
                        preps[0].n)
    return {"K_h": np.abs(fitted.K - limb.K).tolist(), "B_h": np.abs(fitted.B - limb.B).tolist(),
            "M_h": np.abs(fitted.I - limb.I).tolist()}


def _pipeline_tolerance(pr: _Prepared, mask, cfg: FitConfig, part: str) -> float:
    """The measured model tolerance of record ``pr`` on ``mask`` [N^2 m^2, summed over
    joints]: ``tolerance_factor`` x the band energy of its noise-free residual
    (``pr.clean_residual``, set by :func:`fit_nominal`); 0 without one."""
    r = getattr(pr, "clean_residual", None)
    if r is None:
        return 0.0
    cache = pr.__dict__.setdefault("_tol_cache", {})
    key = _mask_key(part, mask)
    if key not in cache:
        e, _, _ = _band_energy(r, pr, mask, cfg)
        cache[key] = cfg.tolerance_factor * max(e, 0.0)
    return cache[key]


def _gap(preps, residuals, angle_residuals, limb0, cfg, part: str) -> _Gap:
    ex = se2 = fl = 0.0
    sources, tols = [], []
    for pr, r, ra in zip(preps, residuals, angle_residuals):
        mask = pr.cal if part == "cal" else pr.held if part == "held" else pr.cal | pr.held
        ref_e, _, _ = _band_energy(pr.tau_lp - pr.tau_lp[mask].mean(axis=0), pr, mask, cfg)
        f_tau, f_ang = _floors(pr, mask, cfg, limb0, part)
        # the torque channel's: the angle residual has no discrete model to err
        tols.append(_pipeline_tolerance(pr, mask, cfg, part) / ref_e)
        e, s_r, _ = _band_energy(r, pr, mask, cfg)
        ex += (e - f_tau.energy) / ref_e
        # the white floor is analytic: the error is this residual's own (as before the
        # coherence floor), not the nominal's, or a candidate's gap would be judged by it
        se2 += ((s_r if f_tau.source == FLOOR_WHITE else f_tau.se) / ref_e) ** 2
        fl += f_tau.energy / ref_e
        sources.append(f_tau.source)
        if ra is not None:
            th_e, _, _ = _band_energy(pr.theta_lp - pr.theta_lp[mask].mean(axis=0), pr, mask,
                                      cfg)
            e, s_a, _ = _band_energy(ra, pr, mask, cfg)
            ex += (e - f_ang.energy) / th_e
            se2 += ((s_a if f_ang.source == FLOOR_WHITE else f_ang.se) / th_e) ** 2
            fl += f_ang.energy / th_e
            sources.append(f_ang.source)
    source = FLOOR_WHITE if FLOOR_WHITE in sources else FLOOR_COHERENCE
    return _Gap(max(ex, 0.0), ex, math.sqrt(se2), fl, source, float(sum(tols)), tuple(tols))


def _angle_residual(pr: _Prepared, params: dict | None):
    """Low-passed measured angle minus the servo's angle (ideal or band-limited)."""
    if pr.rec.theta_ref is None:
        return None
    if params is None:  # the ideal servo's: the same for every candidate, computed once
        if getattr(pr, "_angle_residual0", None) is None:
            pr._angle_residual0 = pr.theta_lp - pr.lp(lm.servo_angle(pr.rec.theta_ref, pr.fs,
                                                                      {}))
        return pr._angle_residual0
    eff = {"servo_bandwidth": params}
    return pr.theta_lp - pr.lp(lm.servo_angle(pr.rec.theta_ref, pr.fs, eff))


# ----------------------------------------------------------------------------- search
def _nonlinear(name):
    e = cat.get_effect(name)
    return [p for p in e.parameters if p.name not in LINEAR.get(name, ())]


def _to_x(p, v):
    """Search coordinate of value v: 0 at the lower bound, 1 at the upper (log scale for
    log parameters)."""
    t = (lambda u: math.log(u)) if p.log else float
    lo, hi = p.bounds
    return (t(v) - t(lo)) / (t(hi) - t(lo))


def _from_x(p, x):
    lo, hi = p.bounds
    x = min(max(float(x), 0.0), 1.0)
    if p.log:
        return math.exp(math.log(lo) + x * (math.log(hi) - math.log(lo)))
    return lo + x * (hi - lo)


def _grid(p, n, band_hz=None):
    """Grid points of parameter p (n per search span; see the channel delay).

    A channel delay (``delay_s`` searched on both sides of 0) gets points dense near zero
    (log-spaced from 0.2 ms) and then at most 1 / (8 band_hz) apart up to the bounds: the
    misfit of a delay error is unimodal only within about a quarter period of the
    analysis band's highest frequency, so a coarser grid (6 log-spaced points per sign,
    the first version) missed the basin of a 30-40 ms delay and another effect was named.
    """
    lo, hi = p.bounds
    if p.log:
        return np.exp(np.linspace(math.log(lo), math.log(hi), n))
    if p.name == "delay_s" and lo < 0 < hi:
        top = min(-lo, hi)
        step = top / max(1, n // 2) if band_hz is None else min(top / max(1, n // 2),
                                                                  1.0 / (8.0 * band_hz))
        small = np.exp(np.linspace(math.log(2e-4), math.log(step), 4))[:-1]
        big = np.linspace(step, top, max(1, int(math.ceil(top / step - 1e-9))))
        g = np.concatenate([small, big])
        pos = g if hi <= top else np.concatenate([g, np.arange(top + step, hi, step)])
        neg = g if -lo <= top else np.concatenate([g, np.arange(top + step, -lo, step)])
        return np.concatenate([-neg[::-1], [0.0], pos])
    return np.linspace(lo, hi, n)


class _Problem:
    """Objective of one candidate (effect + discrete choices) over its nonlinear params."""

    def __init__(self, preps, name, fixed, cfg, unit=1.0):
        self.preps, self.name, self.fixed, self.cfg = preps, name, dict(fixed), cfg
        self.unit = unit or 1.0  # objectives relative to the nominal one
        self.nl = _nonlinear(name) if name else []
        self.masks = None
        self.active = None  # indices of the search's subset of records (None: all)
        self.memo = None    # columns kept per parameter point (one-step jackknife)
        self.n_eval = 0
        self.servo = name == "servo_bandwidth"
        if self.servo:
            self._torque = _solve(preps, [pr.base for pr in preps])

    def params(self, x) -> dict:
        return {**self.fixed, **{p.name: _from_x(p, xi) for p, xi in zip(self.nl, x)}}

    def evaluate(self, params: dict):
        """(objective, torque solution, angle residuals), on the records of the search's
        subset while one is active (:meth:`search`), else on all."""
        self.n_eval += 1
        preps, masks = self.preps, self.masks
        if self.active is not None:
            preps = [self.preps[i] for i in self.active]
            masks = None if masks is None else [masks[i] for i in self.active]
        if self.servo:
            sol = self._torque if masks is None and self.active is None else _solve(
                preps, [pr.base for pr in preps], masks)
            ang = [_angle_residual(pr, params) for pr in preps]
        else:
            try:
                cols = self._columns(preps, params)
            except ValueError:
                return math.inf, None, None
            sol = _solve(preps, cols, masks)
            ang = [_angle_residual(pr, None) for pr in preps]
        obj = sol.cal_energy
        for i, (pr, a) in enumerate(zip(preps, ang)):
            if a is not None:
                m = pr.cal if masks is None else masks[i]
                obj += float(np.sum(a[m] ** 2)) / pr.theta_norm ** 2
        return obj, sol, ang

    def _columns(self, preps, params):
        """Every record's columns at ``params``; kept while a memo is open (the columns do
        not depend on the masks: a one-step jackknife solves every block on them)."""
        if self.memo is None:
            return [pr.columns(self.name, params) for pr in preps]
        key = (tuple(sorted(params.items())), None if self.active is None
               else tuple(int(i) for i in self.active))
        if key not in self.memo:
            self.memo[key] = [pr.columns(self.name, params) for pr in preps]
        return self.memo[key]

    def objective(self, x):
        return self.evaluate(self.params(x))[0] / self.unit

    @property
    def many(self) -> bool:
        return many_records(self)

    def search(self, start=None):
        """Grid then Nelder-Mead; returns the best x (array). With more records than
        ``cfg.search_trials``, both run on that many evenly spaced records and the best
        is refined on all (FitConfig)."""
        if not self.nl:
            return np.zeros(0)
        if start is not None:
            return self._refine_nm(np.asarray(start, float), maxiter=15 * len(self.nl))
        if not self.many or self.active is not None:
            return self._search_all()
        return self.polish(self._on_subset(self._search_all))

    def _on_subset(self, fn, *args, **kw):
        return on_subset(self, fn, *args, **kw)

    def polish(self, x, steps: int = 2):
        """``x`` (a subset's optimum) finished on all records (:func:`polish`)."""
        return polish(self.objective, x, steps)

    def _search_all(self):
        band = min(pr.band for pr in self.preps)
        grids = [_grid(p, self.cfg.grid if len(self.nl) == 1 else
                       max(6, int(self.cfg.grid * (1.3 if p.name == "delay_s" else 0.7))),
                       band)
                 for p in self.nl]
        pts = np.array(np.meshgrid(*grids, indexing="ij")).reshape(len(grids), -1).T
        vals = [self.evaluate({**self.fixed, **{p.name: v for p, v in zip(self.nl, pt)}})[0]
                for pt in pts]
        order = np.argsort(vals)[:self.cfg.refine_starts]
        best_x, best_v = None, math.inf
        for i in order:
            x0 = np.array([_to_x(p, v) for p, v in zip(self.nl, pts[i])])
            x = self._refine(x0)
            v = self.objective(x)
            if v < best_v:
                best_x, best_v = x, v
        return best_x

    def _refine(self, x0, maxiter=None):
        """Nelder-Mead from ``x0`` (:func:`nelder_mead`); with many records (``many``)
        and no masks, on the search's subset and then polished on all."""
        if self.many and self.active is None and self.masks is None:
            return self.polish(self._on_subset(self._refine_nm, x0, maxiter))
        return self._refine_nm(x0, maxiter)

    def _refine_nm(self, x0, maxiter=None):
        step = 0.03 if maxiter is None else 0.01  # of the search span
        return nelder_mead(self.objective, x0, step=step, maxiter=maxiter)


def nelder_mead(fn, x0, *, step: float = 0.03, maxiter: int | None = None) -> np.ndarray:
    """Nelder-Mead refinement of ``fn`` from ``x0`` (search coordinates in [0, 1]): an
    initial simplex of ``step`` along each axis, inward from the nearer bound; at most
    ``maxiter`` (default 40 per coordinate) iterations."""
    x0 = np.asarray(x0, float)
    simplex = [x0] + [x0 + np.eye(len(x0))[i] * (step if x0[i] < 0.5 else -step)
                      for i in range(len(x0))]
    res = optimize.minimize(fn, x0, method="Nelder-Mead",
                            options={"initial_simplex": np.array(simplex),
                                     "xatol": 2e-5, "fatol": 1e-8,
                                     "maxiter": maxiter or 40 * len(x0)})
    return res.x


def many_records(prob) -> bool:
    """More records than ``cfg.search_trials`` (FitConfig): searches run on a subset, and
    are finished, like the jackknife's replicates, by Newton steps on all records."""
    k = prob.cfg.search_trials
    return 0 < k < len(prob.preps)


def on_subset(prob, fn, *args, **kw):
    """``fn(*args, **kw)`` with ``prob``'s evaluations on ``cfg.search_trials`` evenly
    spaced records (``prob.active``), its objective's scale (``prob.unit``) their share
    of the calibration rows (the objective is a sum over records)."""
    unit = prob.unit
    prob.active = np.unique(np.linspace(0, len(prob.preps) - 1,
                                        prob.cfg.search_trials).round().astype(int))
    rows = [int(pr.cal.sum()) for pr in prob.preps]
    prob.unit = unit * sum(rows[i] for i in prob.active) / max(1, sum(rows))
    try:
        return fn(*args, **kw)
    finally:
        prob.active, prob.unit = None, unit


#: objective (relative to the nominal model's) below which a candidate explains enough of
#: the gap for its refused Newton polish to be replaced by Nelder-Mead on all records
POLISH_RELEVANT = 0.95


def polish(fn, x, steps: int = 2):
    """``x`` (a subset's optimum) finished on ``fn`` (the objective on all records,
    relative to the nominal model's) by at most ``steps`` Newton steps
    (:func:`newton_step`). A step shorter than the differences' step that does not lower
    ``fn`` ends it at ``x`` (the optimum within that resolution: a delay's misfit has a
    kink at every whole sample). Where a step is refused, or a longer one does not lower
    ``fn``: Nelder-Mead from ``x`` (at most 15 iterations per coordinate) when the
    candidate explains a part of the gap (``fn`` below :data:`POLISH_RELEVANT`), else
    ``x`` as it is (a flat misfit: the candidate explains nothing, and its optimum's
    place does not matter)."""
    x = np.asarray(x, float)
    f0 = fn(x)
    for _ in range(steps):
        xn = newton_step(fn, x, f0)
        fn_new = math.inf if xn is None else fn(xn)
        if not fn_new <= f0:
            if f0 >= POLISH_RELEVANT or (xn is not None
                                         and np.max(np.abs(xn - x)) <= NEWTON_H):
                return x  # nothing to find, or at the optimum within the differences' step
            return nelder_mead(fn, x, step=0.01, maxiter=15 * x.size)
        done = np.max(np.abs(xn - x)) < 1e-4
        x, f0 = xn, fn_new
        if done:
            break
    return x


NEWTON_H = 0.01     # finite-difference step of newton_step [search span]
NEWTON_MAX = 0.05   # largest Newton step accepted [search span]


def newton_step(fn, x, f0=None, h: float = NEWTON_H):
    """One Newton step on ``fn`` from ``x`` (search coordinates in [0, 1]) with the
    gradient and Hessian of central finite differences of step ``h``: 1 + 2 p + p (p - 1) / 2
    evaluations for p coordinates. None where the step is not to be trusted: a point
    within ``h`` of a bound, a Hessian not positive definite, or a step longer than
    :data:`NEWTON_MAX` (the caller then refines by Nelder-Mead)."""
    x = np.asarray(x, float)
    p = x.size
    if p == 0 or np.any(x - h < 0) or np.any(x + h > 1):
        return None
    f0 = fn(x) if f0 is None else f0
    e = np.eye(p) * h
    fp = np.array([fn(x + e[i]) for i in range(p)])
    fm = np.array([fn(x - e[i]) for i in range(p)])
    g = (fp - fm) / (2 * h)
    H = np.diag((fp - 2 * f0 + fm) / h ** 2)
    for i in range(p):
        for j in range(i + 1, p):
            H[i, j] = H[j, i] = (fn(x + e[i] + e[j]) - fp[i] - fp[j] + f0) / h ** 2
    if not np.all(np.isfinite(H)) or not np.all(np.isfinite(g)):
        return None
    try:
        np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        return None
    d = -np.linalg.solve(H, g)
    if np.max(np.abs(d)) > NEWTON_MAX:
        return None
    return np.clip(x + d, 0.0, 1.0)


# ----------------------------------------------------------------------------- results
@dataclass
class EffectFit:
    """One candidate's fit.

    params : primary parameters (catalogue names; plus discrete choices);
    intervals : {param: [low, high]} 95 % jackknife intervals (None without jackknife);
    limb : the K, B, I re-estimated with the effect;
    calibration_objective : normalised calibration SSR (lower is better);
    calibration_gap, held_out_gap : relative gaps above noise;
    held_out_reduction : 1 - held-out gap / nominal held-out gap (None when no nominal gap);
    at_search_bound : catalogue.at_search_bound messages.
    limb_ci : 95 % jackknife half-widths of the limb's K, B, I with the effect, as
        ArmModel.ci ({"K_h", "B_h", "M_h"}: (n, n) lists); None without jackknife.
    """

    effect: str
    params: dict
    intervals: dict | None
    limb: lm.LimbModel
    calibration_objective: float
    calibration_gap: float
    held_out_gap: float
    held_out_reduction: float | None
    at_search_bound: list = field(default_factory=list)
    n_evaluations: int = 0
    limb_ci: dict | None = None
    #: the intervals' form profile (diagnosis.formprofile.profile), None when not profiled
    form_profile: dict | None = None

    def as_dict(self) -> dict:
        return {"effects": [self.effect], "effect": self.effect, "params": self.params,
                "intervals": self.intervals, "K": self.limb.K.tolist(),
                "B": self.limb.B.tolist(), "I": self.limb.I.tolist(),
                "calibration_objective": self.calibration_objective,
                "calibration_gap": self.calibration_gap, "held_out_gap": self.held_out_gap,
                "held_out_reduction": self.held_out_reduction,
                "at_search_bound": self.at_search_bound,
                "n_evaluations": self.n_evaluations,
                **({"split": self.split} if getattr(self, "split", None) else {}),
                **({"held_out_residual": self.held_out_residual}
                   if getattr(self, "held_out_residual", None) else {}),
                **({"form_profile": self.form_profile} if self.form_profile else {}),
                **({"preferred_over": self.preferred_over}
                   if getattr(self, "preferred_over", None) else {})}


@dataclass
class PositionDiagnosis:
    """The which / how-far / verdict of a set of position trials.

    verdict : VERDICT_EFFECT, VERDICT_NONE or VERDICT_UNEXPLAINED;
    named : [effect], [first, second] (a pair whose second adds significantly on
        held-out data, diagnosis.limbpairs) or [];
    fitted : {effect: params} of the named effect; intervals likewise;
    nominal : the nominal fit (limb K, B, I; gaps); ranking : EffectFit dicts, best first;
    pairs : PairFit dicts built on the best single (diagnosis.limbpairs), best first;
    gap : nominal gaps (calibration, held-out, all), threshold, the named held-out reduction.
    indistinguishable : the alternatives that explain the held-out gap as well as the
        named fit, on its split (diagnosis.limbties; [] when none or nothing named);
    alternatives : every alternative's row (diagnosis.ties), best first.
    """

    verdict: str
    named: list
    fitted: dict
    intervals: dict
    nominal: dict
    ranking: list
    gap: dict
    elapsed_s: float
    n_evaluations: int
    pairs: list = field(default_factory=list)
    indistinguishable: list = field(default_factory=list)
    alternatives: list = field(default_factory=list)


def changes_in_time(records) -> list:
    """Names (``trial`` or ``trial[j]``) of the records and joints in which the shared
    time-variation test (estimation.timevarying.time_variation: Bonferroni over
    parameters, intervals and splits, family-wise false-alarm rate ALPHA) finds a change
    of K, B or I. A record too short for the test is skipped (it cannot find one).

    records : list of PositionRecord (or trialformat.Trial of position perturbations).
    """
    from estimation.timevarying import time_variation
    found = []
    for i, rec in enumerate(records):
        rec = rec if isinstance(rec, PositionRecord) else PositionRecord.from_trial(rec)
        label = rec.name or f"record {i + 1}"
        for j in range(rec.n_dof):
            name = f"{label}[{j + 1}]" if rec.n_dof > 1 else label
            try:
                tv = time_variation(rec.theta[:, j], rec.tau[:, j], rec.fs, name=name)
            except ValueError:
                continue
            if tv.time_varying:
                found.append(name)
    return found


def gap_is_significant(records, gap_all, cfg: FitConfig) -> tuple[bool, list]:
    """(significant, changing) for the fits' gate: the whole-record gap ``gap_all`` (a
    ``_Gap``) above its threshold, or, with ``cfg.time_gate``, a change found in time on
    any record (:func:`changes_in_time`; only tested when the gap alone is not
    significant, so that its cost is paid where it decides)."""
    if gap_all.significant(cfg):
        return True, []
    changing = changes_in_time(records) if cfg.time_gate else []
    return bool(changing), changing


def _norms(preps):
    for pr in preps:
        pr.norm = float(np.std(pr.tau_lp[pr.cal])) or 1.0
        if pr.rec.theta_ref is not None:
            pr.theta_norm = float(np.std(pr.theta_lp[pr.cal])) or 1.0


def prepare(records, cfg: FitConfig = FitConfig()):
    """Cached per-record signals for repeated fits (list of records)."""
    if not records:
        raise ValueError("no position trials to fit")
    n = {r.n_dof for r in records}
    if len(n) != 1:
        raise ValueError(f"position trials of different joint counts: "
                         f"{ {r.name: r.n_dof for r in records} }")
    preps = [_Prepared(r, cfg) for r in records]
    _norms(preps)
    return preps


def fit_nominal(preps, cfg: FitConfig = FitConfig()) -> dict:
    """The nominal model (1): K, B, I on the calibration parts; gaps."""
    sol = _solve(preps, [pr.base for pr in preps])
    limb = _limb_from(sol.coef, preps[0].n)
    ang = [_angle_residual(pr, None) for pr in preps]
    clean = (_clean_residuals(preps, limb) if _measured_tolerance(cfg)
             else [None] * len(preps))
    for pr, r, a, c in zip(preps, sol.residual, ang, clean):  # the floors are read from these
        pr.nominal_residual = (r, a)
        pr.clean_residual = c   # the measured model tolerance from this
        pr.__dict__.pop("_floor_cache", None)
        pr.__dict__.pop("_tol_cache", None)
    gaps = {part: _gap(preps, sol.residual, ang, limb, cfg, part)
            for part in ("cal", "held", "all")}
    return {"limb": limb, "solution": sol, "gaps": gaps}


def candidates(preps, effects=None) -> list[str]:
    """The catalogue's position effects that apply to these records (servo_bandwidth only
    with a recorded theta_ref), or ``effects`` checked against the catalogue."""
    have_ref = all(pr.rec.theta_ref is not None for pr in preps)
    names = list(effects) if effects else list(cat.effects_for("position"))
    for nm in names:
        if not cat.get_effect(nm).applies_to("position"):
            raise ValueError(f"effect {nm!r} does not apply to position experiments; "
                             f"those are {', '.join(cat.effects_for('position'))}")
    return [nm for nm in names if (nm != "servo_bandwidth" or have_ref)
            and vary.applicable(preps, nm)]


def fit_effect(preps, name: str, nominal: dict, cfg: FitConfig = FitConfig(), *,
               intervals: bool = True) -> EffectFit:
    """Fit one catalogue effect (all primary parameters, discrete choices tried in turn)
    on the calibration parts; held-out gap and jackknife intervals."""
    if vary.is_varying(name):  # its own held-out split (diagnosis.varying_effects)
        import sys
        return vary.fit_effect(sys.modules[__name__], preps, name, nominal, cfg,
                               intervals=intervals)
    effect = cat.get_effect(name)
    choices = [dict(zip(effect.choices, combo)) for combo in
               _product(*effect.choices.values())] if effect.choices else [{}]
    # a stretch direction means nothing without rectification (limb.py): try it once
    choices = [c for c in choices if c.get("rectified", True) or c.get("stretch_sign", 1.0) > 0]
    best = None
    n_eval = 0
    for fixed in choices:
        prob = _Problem(preps, name, fixed, cfg, nominal["solution"].cal_energy)
        x = prob.search()
        params = prob.params(x)
        obj, sol, ang = prob.evaluate(params)
        n_eval += prob.n_eval
        if best is None or obj < best[0]:
            best = (obj, sol, ang, params, prob, x)
    obj, sol, ang, params, prob, x = best
    lin = {k: float(sol.coef[3 * preps[0].n ** 2 + i])
           for i, k in enumerate(LINEAR.get(name, ()))}
    full = {**params, **lin}
    limb0 = nominal["limb"]
    limb = _limb_from(sol.coef, preps[0].n)
    g_cal = _gap(preps, sol.residual, ang, limb0, cfg, "cal")
    g_held = _gap(preps, sol.residual, ang, limb0, cfg, "held")
    nom_held = nominal["gaps"]["held"].value
    reduction = None if nom_held <= 0 else 1.0 - g_held.value / nom_held
    ci = None
    if intervals and cfg.n_jackknife >= 2:
        ci, k = _jackknife(prob, x, lin, cfg)
        n_eval += k
    limb_ci = getattr(prob, "limb_ci", None) if ci is not None else None
    out_params = {p.name: full[p.name] for p in effect.parameters}
    out_params.update({k: params[k] for k in effect.choices})
    bound = cat.at_search_bound(name, out_params)
    if any(v < 0 for k, v in lin.items()):
        bound = bound + [f for f in (f"{k} = {v:.4g} < 0 (unphysical)"
                                     for k, v in lin.items() if v < 0) if f not in bound]
    fit = EffectFit(name, out_params, ci, limb, obj, g_cal.value, g_held.value,
                    reduction, bound, n_eval, limb_ci=limb_ci)
    fit._problem = (prob, x, lin)
    fit.nominal_held_out_gap = nom_held
    fit.held_out_residual = g_held.residual_against(nom_held)
    if ci is not None:
        _profile_form(fit, cfg)
    return fit


def _profile_form(fit: EffectFit, cfg: FitConfig):
    """The fit's intervals widened to include its form (diagnosis.formprofile), when
    ``cfg.form_profile`` and the effect has profiled alternatives."""
    if not cfg.form_profile or fit.at_search_bound:  # a flagged fit is never named
        return None
    from . import formprofile
    if not formprofile.profiled(fit.effect):
        return None
    return formprofile.profile(sys.modules[__name__], fit, cfg)


def fit_record(fit: EffectFit) -> dict:
    """A JSON-able record of a fit made by :func:`fit_effect` (for a resume store):
    everything :func:`fit_from_record` needs to give it back bit for bit, including the
    search coordinates its jackknife intervals start from."""
    prob, x, lin = fit._problem
    d = fit.as_dict()
    d["split"] = getattr(fit, "split", None)
    d.update(x=[float(v) for v in np.atleast_1d(x)], lin={k: float(v) for k, v in lin.items()},
             fixed=dict(prob.fixed))
    return d


def fit_from_record(preps, d: dict, nominal: dict, cfg: FitConfig = FitConfig()) -> EffectFit:
    """The fit of :func:`fit_record` on the same ``preps`` and ``nominal`` (a resumed
    diagnosis), ready for :func:`add_intervals`.

    Raises
    ------
    KeyError, ValueError, TypeError
        A record of another layout (the store then runs the fit again).
    """
    name = d["effect"]
    fit = EffectFit(name, dict(d["params"]), d["intervals"],
                    lm.LimbModel(d["K"], d["B"], d["I"]), float(d["calibration_objective"]),
                    float(d["calibration_gap"]), float(d["held_out_gap"]),
                    None if d["held_out_reduction"] is None else float(d["held_out_reduction"]),
                    list(d["at_search_bound"]), int(d["n_evaluations"]))
    if vary.is_varying(name):
        import sys
        prob = vary.make_problem(sys.modules[__name__], preps, name, d["fixed"], cfg,
                                 nominal["solution"].cal_energy)
        vary.split_nominal(sys.modules[__name__], prob)  # the objective's scale of the fit
        fit.split = d.get("split")
    else:
        prob = _Problem(preps, name, d["fixed"], cfg, nominal["solution"].cal_energy)
    fit.nominal_held_out_gap = nominal["gaps"]["held"].value
    fit.held_out_residual = d.get("held_out_residual")
    x = np.asarray(d["x"], dtype=float)
    if x.shape != (len(prob.nl),):
        raise ValueError(f"record of {name!r} has {x.size} coordinates, not {len(prob.nl)}")
    fit._problem = (prob, x, {k: float(v) for k, v in d["lin"].items()})
    return fit


def add_intervals(fit: EffectFit, cfg: FitConfig = FitConfig()) -> EffectFit:
    """The jackknife intervals of a fit made with ``intervals=False``."""
    prob, x, lin = fit._problem
    from contextlib import nullcontext
    with getattr(prob, "split_context", nullcontext)():  # a varying effect's own split
        fit.intervals, k = _jackknife(prob, x, lin, cfg)
    fit.limb_ci = getattr(prob, "limb_ci", None)
    fit.n_evaluations += k
    if not vary.is_varying(fit.effect):
        _profile_form(fit, cfg)
    return fit


def _product(*lists):
    from itertools import product
    return product(*lists)


def _jackknife(prob: _Problem, x, lin, cfg):
    """Delete-one-block jackknife 95 % intervals of every primary parameter.

    Each replicate's nonlinear parameters are refined from the full fit's ``x`` by
    Nelder-Mead on the data without its block; with many records (``prob.many``) by one
    Newton step instead (the one-step jackknife: the replicates of a smooth objective
    from one set of finite differences, their columns computed once for every block),
    Nelder-Mead where the step is refused (:func:`newton_step`)."""
    m = cfg.n_jackknife
    names = [p.name for p in prob.nl] + list(lin)
    n_eval0 = prob.n_eval
    one_step = prob.many and bool(prob.nl)
    prob.memo = {} if one_step else None
    try:
        reps = [_replicate(prob, x, _block_masks(prob.preps, m, b), one_step)
                for b in range(m)]
    finally:
        prob.masks, prob.memo = None, None
    vals = np.array([[params[p.name] for p in prob.nl]
                     + [float(sol.coef[3 * prob.preps[0].n ** 2 + i]) for i in range(len(lin))]
                     for params, sol in reps])
    limb_reps = np.array([np.asarray(sol.coef[:3 * prob.preps[0].n ** 2], float)
                          for _, sol in reps])
    full = np.array([prob.params(x)[p.name] for p in prob.nl] + list(lin.values()))
    se = jackknife_se(vals)
    prob.limb_ci = _limb_half_widths(limb_reps, prob.preps[0].n)
    return ({nm: [float(v - 1.96 * s), float(v + 1.96 * s)]
             for nm, v, s in zip(names, full, se)}, prob.n_eval - n_eval0)


def jackknife_se(reps) -> np.ndarray:
    """Delete-one jackknife standard errors of replicates ``reps`` (m, ...) along axis 0:
    sqrt((m - 1) / m * sum (r - mean)^2) (Efron & Tibshirani 1993, eq. 11.5)."""
    reps = np.asarray(reps, float)
    m = reps.shape[0]
    return np.sqrt((m - 1) / m * np.sum((reps - reps.mean(axis=0)) ** 2, axis=0))


def _block_masks(preps, m: int, b: int) -> list:
    """Every record's calibration mask without its ``b``-th of ``m`` blocks."""
    masks = []
    for pr in preps:
        mk = pr.cal.copy()
        mk[np.array_split(np.flatnonzero(pr.cal), m)[b]] = False
        masks.append(mk)
    return masks


def _replicate(prob, x, masks, one_step: bool):
    """(params, solution) of the fit refined from ``x`` on ``masks``."""
    prob.masks = masks
    xb = newton_step(prob.objective, x) if one_step else None
    if xb is None:
        xb = prob.search(start=x) if prob.nl else x
    params = prob.params(xb)
    return params, prob.evaluate(params)[1]


def _limb_half_widths(reps, n: int) -> dict:
    """95 % half-widths (1.96 jackknife standard errors) of the limb's K, B, I from the
    delete-one-block replicates ``reps`` (m, 3 n^2), as ArmModel.ci: {"K_h", "B_h",
    "M_h"} each (n, n) [N m/rad], [N m s/rad], [kg m^2]."""
    se = jackknife_se(reps)
    nn = n * n
    return {key: (1.96 * se[i * nn:(i + 1) * nn]).reshape(n, n).tolist()
            for i, key in enumerate(("K_h", "B_h", "M_h"))}


def diagnose_position(records, cfg: FitConfig = FitConfig()) -> PositionDiagnosis:
    """Which catalogue effect closes the gap of these position trials, and how far.

    Parameters
    ----------
    records : list of PositionRecord (or trialformat.Trial of position perturbations)
        Trials of one set-up (same joint count).
    cfg : FitConfig

    Returns
    -------
    PositionDiagnosis
        The verdict is VERDICT_NONE when the nominal gap (all samples) is not significant,
        VERDICT_EFFECT naming the best effect (lowest calibration objective) when its
        fit is inside the search bounds and closes at least ``name_reduction`` of the
        held-out gap, else VERDICT_UNEXPLAINED. When the best single leaves a significant
        calibration gap, pairs are built on it (``cfg.pairs``, diagnosis.limbpairs): the
        best pair is named, both effects, when its second adds significantly on held-out
        data and it closes ``name_reduction`` of the held-out gap.

    Raises
    ------
    ValueError
        No trials, mixed joint counts, bad signals (named), an effect not of this kind.
    """
    t0 = time.perf_counter()
    records = [r if isinstance(r, PositionRecord) else PositionRecord.from_trial(r)
               for r in records]
    preps = prepare(records, cfg)
    nominal = fit_nominal(preps, cfg)
    g = nominal["gaps"]
    threshold = g["all"].threshold(cfg)
    significant, changing = gap_is_significant(records, g["all"], cfg)
    fits = []
    if significant:
        fits = [fit_effect(preps, nm, nominal, cfg, intervals=False)
                for nm in candidates(preps, cfg.effects)]
        fits.sort(key=lambda f: f.calibration_objective)
        fits = vary.prefer_simpler(fits, cfg.name_reduction)
        if fits and cfg.n_jackknife >= 2:
            add_intervals(fits[0], cfg)
    pairs = lp.search_pairs(sys.modules[__name__], preps, fits, nominal, cfg) \
        if significant and cfg.pairs else []
    pair = lp.named_pair(pairs, cfg.name_reduction)
    verdict, named = VERDICT_NONE, []
    if significant:
        verdict = VERDICT_UNEXPLAINED
        if pair is not None:
            verdict, named = VERDICT_EFFECT, list(pair.effects)
        elif fits and not fits[0].at_search_bound and fits[0].held_out_reduction is not None \
                and fits[0].held_out_reduction >= cfg.name_reduction:
            verdict, named = VERDICT_EFFECT, [fits[0].effect]
    best = fits[0] if named else None
    limb0 = nominal["limb"]
    fitted = {best.effect: best.params} if best else {}
    if pair is not None:
        fitted = dict(pair.params)
    alt = {"rows": [], "indistinguishable": [], "n_evaluations": 0}
    if named:
        from . import limbties
        alt = limbties.alternatives(sys.modules[__name__], preps, nominal, cfg,
                                    pair if pair is not None else best, fits, pairs)
    return PositionDiagnosis(
        verdict=verdict, named=named, fitted=fitted,
        intervals={best.effect: best.intervals} if best else {},
        nominal={"K": limb0.K.tolist(), "B": limb0.B.tolist(), "I": limb0.I.tolist()},
        ranking=[f.as_dict() for f in fits],
        pairs=[p.as_dict() for p in pairs],
        gap={"nominal_all": g["all"].value, "nominal_calibration": g["cal"].value,
             "nominal_held_out": g["held"].value, "nominal_excess": g["all"].excess,
             "significance_threshold": threshold, "noise_floor": g["all"].floor,
             "noise_floor_source": g["all"].source,
             "changing_in_time": changing,
             **g["all"].tolerance_report(preps, cfg),
             "named_held_out_reduction": (pair.held_out_reduction if pair is not None
                                          else best.held_out_reduction if best else None)},
        elapsed_s=time.perf_counter() - t0,
        n_evaluations=sum(f.n_evaluations for f in fits) + sum(p.n_evaluations
                                                                 for p in pairs)
        + alt["n_evaluations"],
        indistinguishable=alt["indistinguishable"], alternatives=alt["rows"])
