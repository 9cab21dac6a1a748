"""One recording from a :class:`labsim.spec.RecordingSpec`: :func:`simulate`.

Steps (docs/labsim.md): the reference (slow movement plus perturbation) and the subject's
torque on a fine grid (``oversample`` steps per sample, from ``-preroll_s``); the joint
driven by the servo (ideal: the reference itself; pd: the loop solved with the limb,
labsim.servo); the torque on the sensor; the channels recorded (labsim.sensors); the
truth. Nothing here imports the project's diagnosis or estimation.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

import trialformat

from . import signals as sg
from .lti import StateSpace
from .limb import (LimbModel, angle_factor, as_matrix, delayed, per_joint, rectifier,
                   reflex_filter, scalar_factor)
from .checks import check_spec
from .sensors import acquire
from .servo import ServoLoop, solve_loop
from .spec import RecordingSpec, spec_to_dict

__version__ = "1"


@dataclass
class Recording:
    """A simulated recording.

    Attributes
    ----------
    trial : trialformat.Trial
        Position-perturbation trial (theta, tau_h, theta_ref when recorded; an extra
        column of the scheduling variable when the joint moves), in the project's
        conventions (the file stores tau_h with ``sensors.torque_sign``).
    truth : dict
        Every true parameter, and arrays at fs (``truth["arrays"]``: ``t``, ``K``, ``B``,
        ``I`` (N,) for one joint or (N, n, n), the reflex gain ``G``, the scheduling
        variable ``sv``, ``perturbed`` (0 in rest segments), torques of each part); see
        docs/labsim.md.
    spec : RecordingSpec
        The spec with derived values filled (friction and voluntary levels in N m).
    """

    trial: trialformat.Trial
    truth: dict
    spec: RecordingSpec


def _joints(sel, n: int, what: str) -> list:
    joints = [1] if sel is None else [int(j) for j in sel]
    bad = [j for j in joints if not 1 <= j <= n]
    if bad:
        raise ValueError(f"{what}.joints {bad} outside 1..{n}")
    return joints


def _reference(spec, t, h, fine_rate):
    """Perturbation p and slow movement x_s (each a (x, x', x'') of (n, Nf) arrays)."""
    n, pert = spec.n_dof, spec.perturbation
    zero = np.zeros((n, t.size))
    p = [zero.copy(), zero.copy(), zero.copy()]
    xs = [zero.copy(), zero.copy(), zero.copy()]
    start = sg.envelope(t, t[0], 0.5 * spec.preroll_s)
    env = sg.envelope(t, t[0], 0.5 * spec.preroll_s, pert.rest, pert.taper_s)
    for j in _joints(pert.joints, n, "perturbation"):
        rng = sg.rng_for(spec.seed, "perturbation", j)
        if pert.kind == "noise":
            one = sg.noise_reference(t, h, pert, rng)
        elif pert.kind == "prbs":
            one = sg.prbs_reference(t, h, pert, rng)
        else:
            one = sg.multisine_reference(t, spec.duration_s, pert, rng, fine_rate)
        one = sg.product(env, one)
        for i in range(3):
            p[i][j - 1] = one[i]
    if spec.movement is not None:
        for j in _joints(spec.movement.joints, n, "movement"):
            one = sg.product(start, sg.movement_trajectory(t, spec.movement))
            for i in range(3):
                xs[i][j - 1] = one[i]
    return p, xs, start, env


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def _smoothed(spec, x, h):
    """x with derivatives; a PRBS's raw steps (no derivatives) smoothed first as a servo of
    servo.f_hz (damping 0.7) would: the levels set from fractions need the motion."""
    pert = spec.perturbation
    if pert.kind != "prbs" or pert.prefilter_hz is not None:
        return x
    w = 2 * np.pi * (spec.servo.f_hz if spec.servo.kind == "pd" else 100.0)
    lp = StateSpace.from_zpk([], np.roots([1.0, 1.4 * w, w * w]), w * w, derivatives=2)
    out = [lp.simulate(x[0][j], h) for j in range(x[0].shape[0])]
    return [np.vstack([o[i] for o in out]) for i in range(3)]


def _reflex_gain(spec, r_dot, t, h, scale, tau_bg, slow) -> float:
    """The gain giving joint 1's reflex torque a fluctuation (standard deviation over the
    recording) of ``fraction`` times the nominal perturbation torque's RMS, for the
    reference's velocity and the gain's own variation (time, torque, angle factors)."""
    rx = spec.reflex
    u = rectifier(rx, delayed(r_dot[:1], rx.delay_s / h))[0]
    if rx.gain_var is not None:
        u = u * (scalar_factor(rx.gain_var, t, spec.duration_s, tau_bg[:1])[0]
                 * angle_factor(rx.gain_var, slow[0]))
    y = reflex_filter(rx).simulate(u, h, smooth=True)
    sd = float(np.std(y[t >= 0]))
    if sd == 0:
        raise ValueError("reflex.fraction: the reference's velocity never passes the "
                         "reflex's rectifier and threshold")
    return rx.fraction * scale / sd


def _resolve(spec, p, r, t, h, I0, B0, K0) -> tuple[RecordingSpec, float]:
    """A copy of the spec with the levels given as fractions turned into N m."""
    spec = copy.deepcopy(spec)
    rec = t >= 0
    tau_p = I0 @ p[2] + B0 @ p[1] + K0 @ p[0]
    j = _joints(spec.perturbation.joints, spec.n_dof, "perturbation")[0] - 1
    scale = _rms(tau_p[j, rec])
    if spec.voluntary is not None and spec.voluntary.level_nm is None:
        spec.voluntary.level_nm = spec.voluntary.fraction * scale
    fp = spec.footplate
    if fp is not None and fp.friction and fp.Fc is None:
        fp.Fc = fp.friction_fraction * scale
    return spec, scale


def simulate(spec: RecordingSpec) -> Recording:
    """Simulate one recording (module docstring).

    With a movement and ``spec.movement_removed``, the recording is stored as the Kearney
    lab's moving-ankle pilot is (Sobhani Tehrani & Kearney 2022): angle, torque and
    reference less those of an unperturbed trial along the same movement (simulated with
    its own noise and voluntary torque: seed + 1000003), the scheduling variable beside.

    Raises
    ------
    ValueError
        A spec value outside its domain (the message names it).
    labsim.SimulationError
        The servo loop does not converge.
    """
    rec = _simulate_one(spec)
    if not (spec.movement_removed and spec.movement is not None):
        return rec
    twin = copy.deepcopy(rec.spec)
    twin.perturbation.amplitude_rad = 0.0
    twin.seed = int(spec.seed) + 1000003
    still = _simulate_one(twin)
    trial = rec.trial
    trial.theta = trial.theta - still.trial.theta
    trial.tau_h = trial.tau_h - still.trial.tau_h
    if trial.theta_ref is not None:
        trial.theta_ref = trial.theta_ref - still.trial.theta_ref
    trial.meta["source"] += "; movement removed (less an unperturbed trial along it)"
    rec.truth["movement_removed"] = {
        "seed_unperturbed": twin.seed,
        "rms_unperturbed": still.truth["rms"],
        "solver_unperturbed": still.truth["solver"]}
    return rec


def _simulate_one(spec: RecordingSpec) -> Recording:
    check_spec(spec)
    n, fs, m = spec.n_dof, float(spec.fs), int(spec.oversample)
    fine_rate = fs * m
    h = 1.0 / fine_rate
    N = int(round(spec.duration_s * fs))
    pre = int(round(spec.preroll_s * fs)) * m
    Nf = pre + (N - 1) * m + 1
    t = (np.arange(Nf) - pre) * h
    p, xs, start, env = _reference(spec, t, h, fine_rate)
    lb = spec.limb
    I0, B0, K0 = (as_matrix(v, n, k) for k, v in (("I", lb.I), ("B", lb.B), ("K", lb.K)))
    r = [p[i] + xs[i] for i in range(3)]
    ps, rs = _smoothed(spec, p, h), _smoothed(spec, r, h)
    spec, tau_scale = _resolve(spec, ps, rs, t, h, I0, B0, K0)

    tau_vol = np.zeros((n, Nf))
    if spec.voluntary is not None:
        v = spec.voluntary
        for j in range(n):
            tau_vol[j] = v.level_nm * sg.lowpass_noise(
                t, h, v.band_hz, v.order, sg.rng_for(spec.seed, "voluntary", j + 1))
    bg0 = per_joint(lb.background_torque_nm, n, "limb.background_torque_nm")
    tau_bg = start[0][None, :] * (bg0[:, None] + tau_vol)
    if spec.reflex is not None and spec.reflex.fraction is not None:
        spec.reflex.gain = _reflex_gain(spec, rs[1], t, h, tau_scale, tau_bg, xs[0])
        spec.reflex.fraction = None
    limb = LimbModel(spec, t, h, tau_bg, xs[0])

    first = pre
    samples = first + np.arange(N) * m
    if spec.servo.kind == "ideal":
        x, v, a = r
        tau_h, parts = limb.torque(x, v, a)
        loop_info = {"iterations": 0, "residual": 0.0}
        servo_truth = {"kind": "ideal"}
    else:
        fp = spec.footplate
        loop = ServoLoop(spec.servo, I0, B0, K0, h,
                         fp.contact_hz if fp is not None and fp.backlash_rad else None)
        if spec.servo.dac == "zoh":
            held = (np.arange(Nf) // m) * m  # the last sample at or before each point
            r_in = r[0][:, held]
        else:
            r_in = r[0]
        smooth = spec.servo.dac == "continuous" and not (
            spec.perturbation.kind == "prbs" and spec.perturbation.prefilter_hz is None)
        sol = solve_loop(loop, limb, r_in, smooth_reference=smooth)
        x, v, a, tau_h, parts = sol["x"], sol["v"], sol["a"], sol["tau_h"], sol["parts"]
        loop_info = {"iterations": sol["iterations"], "residual": sol["residual"],
                     "limb_vs_sensor_max_nm": float(np.max(np.abs(sol["tau_limb"] - tau_h)))}
        servo_truth = {"kind": "pd", "Kp": loop.Kp.tolist(), "Kd": loop.Kd.tolist(),
                       "Ki": loop.Ki.tolist(), "motor_inertia": loop.Jm.tolist(),
                       "f_hz": spec.servo.f_hz, "damping": spec.servo.damping,
                       "actuator_lag_s": spec.servo.actuator_lag_s, "dac": spec.servo.dac}

    sens = spec.sensors
    theta, theta_clean = acquire(x, h, first, m, N, fs, sens.antialias, sens.theta,
                                 lambda j: sg.rng_for(spec.seed, "noise_theta", j + 1))
    tau, tau_clean = acquire(tau_h, h, first, m, N, fs, sens.antialias, sens.tau,
                             lambda j: sg.rng_for(spec.seed, "noise_tau", j + 1))
    ref = r[0][:, samples]
    trial = _trial(spec, theta, tau, ref, xs[0][:, samples])
    truth = _truth(spec, limb, samples, xs, x, parts, env, tau_scale, servo_truth,
                   loop_info, theta, theta_clean, tau, tau_clean, p)
    return Recording(trial=trial, truth=truth, spec=spec)


def _trial(spec, theta, tau, ref, slow) -> trialformat.Trial:
    n, fs = spec.n_dof, float(spec.fs)
    joints = _joints(spec.perturbation.joints, n, "perturbation")
    pert = spec.perturbation
    meta = {
        "format": trialformat.FORMAT, "fs": fs, "n_dof": n,
        "perturbed_dof": joints[0] if len(joints) == 1 else None,
        "perturbation": {"kind": "position", "signal": pert.kind, "seed": int(spec.seed)},
        "posture_deg": [0.0] * n,
        "sensors": {"torque_sign": int(spec.sensors.torque_sign),
                    "torque_sampling": "instantaneous",
                    "encoder_resolution_deg": 0.0, "torque_resolution_nm": 0.0},
        "friction": {"Fc": [0.0] * n, "Fs": [0.0] * n, "sigma2": [0.0] * n,
                     "sigma0": 1000.0, "sigma1": 1.0, "ws": 0.01},
        # nothing of the truth (not even the kind): the trial is read blind
        "source": f"labsim {__version__}: simulated lab recording",
    }
    if pert.kind in ("noise", "multisine"):
        meta["perturbation"]["cutoff_hz"] = float(pert.band_hz[1])
    elif pert.kind == "prbs":
        meta["perturbation"]["switch_s"] = float(pert.switch_s)
    if spec.condition:
        meta["condition"] = spec.condition
    extra = {}
    if spec.movement is not None and spec.scheduling_channel:
        j = _joints(spec.movement.joints, n, "movement")[0] - 1
        extra[spec.scheduling_channel] = slow[j].copy()
        # declared as a lab's sidecar does (docs/spec/log-format.md, "scheduling")
        meta["scheduling"] = {"name": spec.scheduling_channel, "units": "rad"}
    return trialformat.Trial(
        meta=meta, t=np.arange(theta.shape[1]) / fs, theta=theta.T.copy(),
        tau_h=tau.T.copy(), theta_ref=ref.T.copy() if spec.record_reference else None,
        extra=extra)


def _effects(spec, resolved_servo) -> list:
    """The truth's list of what the set-up holds beyond a linear, constant K-B-I limb on
    an ideal servo (docs/spec/effects.md's ``{"name", "params"}`` entries)."""
    out = []

    def add(name, part):
        out.append({"name": name, "params": part if isinstance(part, dict) else
                    spec_to_dict(part)})

    if spec.servo.kind == "pd":
        add("servo_dynamics", resolved_servo)
    lb = spec.limb
    for name in ("K", "B", "I"):
        var = getattr(lb, f"{name}_var")
        if var is None:
            continue
        if var.time != "constant" and var.ratio != 1.0:
            add(f"time_varying_{name}", var)
        if var.angle != "constant" and var.angle_coef != 0:
            add(f"angle_dependent_{name}", var)
        if var.torque_coef:
            add(f"torque_dependent_{name}", var)
    if np.any(np.asarray(lb.k3)):
        add("stiffening_spring", {"k3": lb.k3})
    if np.any(np.asarray(lb.srs_K)):
        add("short_range_stiffness", {"srs_K": lb.srs_K, "srs_limit_rad": lb.srs_limit_rad})
    if np.any(np.asarray(lb.background_torque_nm)):
        add("background_torque", {"background_torque_nm": lb.background_torque_nm})
    for name, part in (("reflex", spec.reflex), ("wobbling_mass", spec.wobbling),
                       ("voluntary_torque", spec.voluntary), ("movement", spec.movement)):
        if part is not None:
            add(name, part)
    fp = spec.footplate
    if fp is not None:
        if fp.friction:
            add("footplate_friction", {k: getattr(fp, k) for k in
                                       ("friction", "Fc", "Fs", "v_s", "sigma0", "sigma1",
                                        "sigma2")})
        if fp.backlash_rad:
            add("backlash", {"backlash_rad": fp.backlash_rad, "contact_hz": fp.contact_hz})
        if fp.contact_limit_nm:
            add("contact_clipping", {"contact_limit_nm": fp.contact_limit_nm})
    if spec.perturbation.rest:
        add("rest_periods", {"rest": spec.perturbation.rest})
    sens = spec.sensors
    for ch_name, ch in (("theta", sens.theta), ("tau_h", sens.tau)):
        if ch.filter is not None:
            add("channel_filter", {"channel": ch_name, **spec_to_dict(ch.filter)})
        if ch.delay_s:
            add("channel_delay", {"channel": ch_name, "delay_s": ch.delay_s})
        if ch.white_std:
            add("sensor_noise", {"channel": ch_name, "white_std": ch.white_std})
        if ch.pink_std or ch.hum_std:
            add("coloured_noise", {"channel": ch_name, "pink_std": ch.pink_std,
                                   "hum_std": ch.hum_std, "hum_hz": ch.hum_hz,
                                   "hum_harmonics": ch.hum_harmonics})
        if ch.resolution:
            add("quantization", {"channel": ch_name, "resolution": ch.resolution})
        if ch.offset:
            add("offset", {"channel": ch_name, "offset": ch.offset})
    return out


def _truth(spec, limb, samples, xs, x, parts, env, tau_scale, servo_truth, loop_info,
           theta, theta_clean, tau, tau_clean, p) -> dict:
    n = spec.n_dof
    sv = xs[0][:, samples]
    local = limb.local(sv, samples)
    arrays = {"t": np.arange(samples.size) / spec.fs}
    for k in ("K", "B", "I"):
        arr = np.moveaxis(local[k], -1, 0)  # (N, n, n)
        arrays[k] = arr[:, 0, 0].copy() if n == 1 else arr
    if "G" in local:
        arrays["G"] = local["G"][0] if n == 1 else local["G"].T
    arrays["sv"] = sv[0] if n == 1 else sv.T
    arrays["perturbed"] = env[0][samples]
    arrays["tau_bg"] = limb.tau_bg[0, samples] if n == 1 else limb.tau_bg[:, samples].T
    for k, v in parts.items():
        arrays[f"tau_{k}"] = v[0, samples] if n == 1 else v[:, samples].T
    varies = [k for k in ("K", "B", "I", "G") if k in arrays
              and np.ptp(np.asarray(arrays[k]).reshape(samples.size, -1), axis=0).max()
              > 1e-12 * (np.abs(arrays[k]).max() + 1e-300)]
    rec = np.ones(samples.size, bool)
    nominal = {k: (float(v[0, 0]) if n == 1 else v.tolist()) for k, v in
               (("K", limb.K0), ("B", limb.B0), ("I", limb.I0))}
    mean = {k: (float(np.mean(arrays[k])) if n == 1 else np.mean(arrays[k], 0).tolist())
            for k in ("K", "B", "I")}
    rms = {"theta": _rms(theta[:, rec]), "tau_h": _rms(tau[:, rec]),
           "theta_noise": _rms(theta - theta_clean), "tau_noise": _rms(tau - tau_clean),
           "perturbation": _rms(p[0][:, samples])}
    for k, v in parts.items():
        rms[f"tau_{k}"] = _rms(v[:, samples])
    truth = {
        "format": "labsim-truth/1", "labsim_version": __version__,
        "kind": spec.kind, "seed": int(spec.seed), "n_dof": n, "fs": float(spec.fs),
        "effects": _effects(spec, servo_truth),
        "nominal": nominal, "mean": mean, "varies": varies,
        "servo": servo_truth, "solver": loop_info,
        "perturbation_torque_rms_nm": tau_scale, "rms": rms,
        "scheduling": ({"name": spec.scheduling_channel or "sv",
                        "variable": "commanded slow joint angle [rad]"}
                       if spec.movement is not None else None),
        "spec": spec_to_dict(spec),
        "arrays": arrays,
    }
    var = spec.limb.K_var
    if var is not None and var.angle != "constant" and var.angle_coef:
        rho = np.linspace(sv.min(), sv.max(), 101) if np.ptp(sv) > 0 else \
            np.linspace(-0.4, 0.2, 101)
        truth["K_of_rho"] = {"rho": rho, "K": float(limb.K0[0, 0]) * angle_factor(var, rho)
                             + 3 * limb.k3[0] * rho ** 2,
                             "note": "joint 1, time and torque factors at 1"}
    return truth
