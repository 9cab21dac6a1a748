"""Known-answer trials: a linear 2-DOF closed loop simulated with scipy.signal.

This is an independent route to trials with a known impedance, for tests and demos; it
shares nothing with the orchestrator or the FMU. The closed loop is linear and continuous:

    (Z_a(s) + Z_h(s)) theta = E tau_delta,    tau_h = Z_h(s) theta,

with ``Z_h = M_h s^2 + B_h s + K_h`` the arm, ``E`` selecting the perturbed joints and
``Z_a`` diagonal: the desired (internal model) impedance ``M_rd s^2 + B_rd s + K_rd`` on a
perturbed joint and a holding impedance ``Mbar s^2 + 2 Mbar wn s + Mbar wn^2`` on a held
one (an illustration of a finite hold, not a model of the IMBIC loop). With one joint held
perfectly this is the paper's decomposed loop ``theta_k = R_kk tau_delta_k``,
``tau_h_i = T_ik tau_delta_k``.

The state-space model is simulated exactly by ``scipy.signal.lsim`` at the sample rate:
with ``input_hold="foh"`` the perturbation is piecewise linear between samples (smooth,
so sampling theta and tau_h at the same instants relates them by Z(jw) to within the
aliasing of the hold's images, below 1e-3 at 15 Hz); with ``"zoh"`` it is held, and
``sampling="left_limit"`` then reads tau_h just before each input step, as the FMU does.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

import trialformat as tf
from trialformat import reference as ref

from .errors import EstimationError


def perturbation(level, seed, n_samples, *, n_dof=2, fs=1000.0, perturbed_dof=None,
                 peak=None):
    """Filtered uniform noise of reference.md section 6 [N m], shape (n_samples, n_dof).

    Uniform on [-1, 1], 8th-order Butterworth low-pass at 15 Hz (causal SOS), the first
    2 s discarded, scaled to the level's peak per joint (or ``peak``, one value per joint);
    joints other than ``perturbed_dof`` (1-based, None: all) are zero.
    """
    spec = ref.reference()["perturbation"]
    peaks = np.asarray(ref.perturbation_peak(level) if peak is None else peak,
                       dtype=float)[:n_dof]
    discard = int(round(spec["discard_s"] * fs))
    sos = signal.butter(spec["butterworth_order"], spec["cutoff_hz"], fs=fs, output="sos")
    raw = np.random.default_rng(seed).uniform(-1.0, 1.0, (n_samples + discard, n_dof))
    out = signal.sosfilt(sos, raw, axis=0)[discard:]
    out *= peaks / np.max(np.abs(out), axis=0)
    if perturbed_dof is not None:
        keep = np.zeros(n_dof, bool)
        keep[perturbed_dof - 1] = True
        out[:, ~keep] = 0.0
    return out


def closed_loop_system(M_h, B_h, K_h, *, perturbed, tuning="reference", perfect_hold=False,
                       controller=None):
    """Continuous state-space model: input tau_delta (n), outputs [theta (n), tau_h (n)].

    Parameters
    ----------
    M_h, B_h, K_h : array_like (n, n) [kg m^2], [N m s/rad], [N m/rad]
    perturbed : sequence of bool
        Which joints are perturbed (desired impedance) or held (holding impedance).
    tuning : {"reference", "robust"}
        Controller values (reference.md section 7) for the desired and holding impedances.
    perfect_hold : bool
        Held joints do not move at all (the paper's assumption): they are removed from the
        state and their angle output is 0.
    controller : dict or None
        ``M_rd, B_rd, K_rd, Mbar, wn`` with one value per joint, instead of ``tuning``'s
        (needed for n != 2, e.g. :data:`CONTROLLER_3DOF`).

    Returns
    -------
    scipy.signal.StateSpace with state ``[theta, theta']``.
    """
    M_h, B_h, K_h = (np.asarray(a, dtype=float) for a in (M_h, B_h, K_h))
    n = M_h.shape[0]
    c = ref.controller(tuning) if controller is None else controller
    mbar, wn = np.asarray(c["Mbar"], float), np.asarray(c["wn"], float)
    perturbed = np.asarray(perturbed, bool)
    Ma = np.diag(np.where(perturbed, c["M_rd"], mbar))
    Ba = np.diag(np.where(perturbed, c["B_rd"], 2 * mbar * wn))
    Ka = np.diag(np.where(perturbed, c["K_rd"], mbar * wn ** 2))
    # Moving joints: all, or with a perfect hold only the perturbed ones (S selects them).
    S = np.eye(n)[:, perturbed] if perfect_hold else np.eye(n)
    Mi = np.linalg.inv(S.T @ (Ma + M_h) @ S)
    Kt, Bt = S.T @ (Ka + K_h) @ S, S.T @ (Ba + B_h) @ S
    E = S.T @ np.diag(perturbed.astype(float))
    m = S.shape[1]
    I, O = np.eye(m), np.zeros((m, m))
    A = np.block([[O, I], [-Mi @ Kt, -Mi @ Bt]])
    Bm = np.vstack([np.zeros((m, n)), Mi @ E])
    Mh, Bh, Kh = M_h @ S, B_h @ S, K_h @ S
    C = np.block([[S, np.zeros((n, m))], [Kh - Mh @ Mi @ Kt, Bh - Mh @ Mi @ Bt]])
    D = np.vstack([np.zeros((n, n)), Mh @ Mi @ E])
    return signal.StateSpace(A, Bm, C, D)


def synthetic_trial(*, perturbed_dof, arm=None, level=3, seed=0, duration_s=50.0,
                    fs=1000.0, tuning="reference", perfect_hold=False, input_hold="foh", sampling="instant",
                    theta_noise_std_rad=0.0, tau_noise_std_nm=0.0, noise_seed=None,
                    perturbation_signal=None, name="", controller=None, peak=None):
    """Simulate one trial of the linear closed loop and return it as a trialformat.Trial.

    Parameters
    ----------
    perturbed_dof : int or None
        1-based perturbed joint; None perturbs every joint at once (independent signals).
    arm : (M_h, B_h, K_h) or None
        Arm matrices; Table I by default.
    level, seed : int
        Perturbation level (1-3) and seed (reference.md section 6).
    duration_s, fs : float [s], [Hz]
    tuning : {"reference", "robust"}
    perfect_hold : bool
        Held joints do not move (the paper's decomposed loop).
    input_hold : {"foh", "zoh"}
        Perturbation between samples: linear (smooth) or held.
    sampling : {"instant", "left_limit"}
        tau_h at the sample instant, or just before the input step there (with ``zoh``).
    theta_noise_std_rad, tau_noise_std_nm : float
        White Gaussian measurement noise added to theta [rad] and tau_h [N m].
    noise_seed : int or None
        Seed of the noise (default: ``seed + 1000``).
    perturbation_signal : ndarray (N, n) or None
        Overrides level/seed.
    controller : dict or None
        Desired and holding impedances per joint (``closed_loop_system``); needed for n != 2.
    peak : sequence of float or None
        Perturbation peak per joint [N m] instead of the level's (needed for n > 2).

    Returns
    -------
    trialformat.Trial
        ``tau_m`` holds the interaction torque (the linear model has no robot).
    """
    if input_hold not in ("foh", "zoh"):
        raise EstimationError(f"input_hold must be 'foh' or 'zoh', got {input_hold!r}")
    if sampling not in ("instant", "left_limit"):
        raise EstimationError(f"sampling must be 'instant' or 'left_limit', got {sampling!r}")
    M_h, B_h, K_h = ref.arm_matrices() if arm is None else arm
    n = np.asarray(M_h).shape[0]
    n_samples = int(round(duration_s * fs))
    d = (perturbation(level, seed, n_samples, n_dof=n, fs=fs, perturbed_dof=perturbed_dof,
                      peak=peak)
         if perturbation_signal is None else np.asarray(perturbation_signal, float))
    perturbed = np.ones(n, bool) if perturbed_dof is None else np.arange(1, n + 1) == perturbed_dof
    sys = closed_loop_system(M_h, B_h, K_h, perturbed=perturbed, tuning=tuning,
                             perfect_hold=perfect_hold, controller=controller)
    t = np.arange(n_samples) / fs
    _, y, x = signal.lsim(sys, d, t, interp=(input_hold == "foh"))
    theta, tau_h = y[:, :n], y[:, n:]
    if sampling == "left_limit":
        d_prev = np.vstack([np.zeros((1, n)), d[:-1]])
        tau_h = np.atleast_2d(x.T).T @ sys.C[n:].T + d_prev @ sys.D[n:].T
    rng = np.random.default_rng(seed + 1000 if noise_seed is None else noise_seed)
    theta = theta + theta_noise_std_rad * rng.standard_normal(theta.shape)
    tau_h = tau_h + tau_noise_std_nm * rng.standard_normal(tau_h.shape)
    meta = tf.default_metadata(n)
    meta.update(fs=fs, perturbed_dof=perturbed_dof,
                controller=dict(ref.controller(tuning) if controller is None else controller),
                source=f"estimation.synthetic: linear closed loop, {input_hold} input, "
                       f"{sampling} sampling, scipy.signal.lsim")
    meta["perturbation"].update(level=level, seed=seed, peak=list(
        np.asarray(ref.perturbation_peak(level) if peak is None else peak, float)[:n]))
    meta["sensors"]["torque_sampling"] = "left_limit" if sampling == "left_limit" \
        else "instantaneous"
    return tf.Trial(meta=meta, t=t, tau_delta=d, theta=theta, tau_h=tau_h,
                    tau_m=tau_h.copy(), name=name or f"synthetic_dof{perturbed_dof or 'all'}")


def synthetic_condition(**kwargs):
    """The two decomposition trials (joint 1, then joint 2) with the same options.

    The second trial uses ``seed + 1`` so the two perturbations differ.
    """
    seed = kwargs.pop("seed", 0)
    return [synthetic_trial(perturbed_dof=k, seed=seed + k - 1, **kwargs) for k in (1, 2)]


#: Human arm of docs/spec/reference-3dof.md (shoulder, elbow, wrist): (M_h, B_h, K_h).
ARM_3DOF = ref.arm_matrices("3dof")
#: Controller of reference-3dof.md, reference tuning, and its level-3 peaks [N m].
CONTROLLER_3DOF = dict(ref.controller("reference", arm="3dof"), tuning="reference-3dof")
PEAK_3DOF = ref.perturbation_peak(3, arm="3dof")


def _shaped_noise(rng, f, n, rms, corner, order):
    """Spectrum of a periodic Gaussian signal of ``rms`` with a Butterworth-like magnitude."""
    spec = rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)
    spec /= np.sqrt(1 + (f / corner) ** (2 * order))
    spec[0] = 0.0
    x = np.fft.irfft(spec, n)
    return np.fft.rfft(x * rms / x.std())


def torque_trial(*, K, B, I, duration_s=50.0, fs=1000.0, seed=0, perturbation_rms_nm=3.0,
                 cutoff_hz=15.0, M_rd=0.005, B_rd=0.5, K_rd=10.0, voluntary_rms_nm=0.5,
                 voluntary_hz=2.0, theta_noise_std_rad=2e-5, tau_noise_std_nm=0.1, name=""):
    """A 1-DOF torque-perturbation trial generated exactly in the frequency domain.

    The robot renders ``Z_a = M_rd s^2 + B_rd s + K_rd`` and adds the perturbation d; the
    limb ``Z = I s^2 + B s + K`` adds its own torque ``tau_v``::

        (Z + Z_a) theta = d + tau_v,   tau_h = Z theta - tau_v

    Periodic and band-limited like :func:`position_trial`, so ``G(d, tau_h)/G(d, theta) = Z``
    holds at every bin (no hold or aliasing error, unlike the lsim closed loop).
    """
    n = int(round(duration_s * fs))
    rng = np.random.default_rng(seed)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    s = 2j * np.pi * f
    D = _shaped_noise(rng, f, n, perturbation_rms_nm, cutoff_hz, 8)
    V = _shaped_noise(rng, f, n, voluntary_rms_nm, voluntary_hz, 1)
    Z = I * s ** 2 + B * s + K
    Za = M_rd * s ** 2 + B_rd * s + K_rd
    Th = (D + V) / (Z + Za)
    theta = np.fft.irfft(Th, n) + theta_noise_std_rad * rng.standard_normal(n)
    tau_h = np.fft.irfft(Z * Th - V, n) + tau_noise_std_nm * rng.standard_normal(n)
    meta = tf.default_metadata(1)
    meta.update(fs=fs, n_dof=1, perturbed_dof=1, posture_deg=[0.0],
                controller={"M_rd": [M_rd], "B_rd": [B_rd], "K_rd": [K_rd],
                            "theta_rd_deg": [0.0], "Mbar": [M_rd], "wn": [150.0],
                            "tuning": "custom"},
                source="estimation.synthetic.torque_trial: 1-DOF limb under a torque "
                       "perturbation, frequency-domain generation")
    d = np.fft.irfft(D, n)
    meta["perturbation"].update(level=None, rms_nm=perturbation_rms_nm, cutoff_hz=cutoff_hz,
                                seed=seed, peak=[float(np.abs(d).max())])
    meta["sensors"].update(torque_sampling="instantaneous")
    return tf.Trial(meta=meta, t=np.arange(n) / fs, tau_delta=d[:, None], theta=theta[:, None],
                    tau_h=tau_h[:, None], tau_m=(d - tau_h)[:, None],
                    name=name or f"torque_seed{seed}")


def position_trial(*, K, B, I, duration_s=50.0, fs=1000.0, seed=0, ref_rms_rad=0.02,
                   cutoff_hz=40.0, servo_K=5000.0, servo_B=20.0, voluntary_rms_nm=0.5,
                   voluntary_hz=2.0, theta_noise_std_rad=1e-5, tau_noise_std_nm=0.05,
                   record_reference=True, torque_sign=1, name="", condition=None):
    """A 1-DOF position-perturbation trial (ankle or wrist lab protocol) with a known answer.

    A stiff position servo (PD, ``servo_K + servo_B s``) moves the joint along a random
    reference; the limb ``Z(s) = I s^2 + B s + K`` adds its own voluntary torque noise
    ``tau_v`` (low-pass at ``voluntary_hz``, uncorrelated with the reference)::

        theta = (Zs ref + tau_v) / (Z + Zs),   tau_h = Zs (ref - theta) = Z theta - tau_v

    ``tau_h`` is the torque the device applies to the limb. Signals are generated in the
    frequency domain over the whole record (periodic, exactly band-limited: the sampled
    signals obey Z at every DFT bin), then white sensor noise is added to theta and tau_h.
    ``G(ref, tau_h) / G(ref, theta) = Z`` exactly; the direct estimate from theta to
    tau_h is biased towards ``-Zs`` where ``tau_v`` moves the joint.

    Parameters
    ----------
    K [N m/rad], B [N m s/rad], I [kg m^2] : float
        The limb's impedance.
    ref_rms_rad : float
        RMS of the reference (Gaussian, 4th-order Butterworth magnitude up to ``cutoff_hz``).
    record_reference : bool
        Write ``theta_ref`` (else the trial carries only theta and tau_h).
    torque_sign : {1, -1}
        Sign the file stores tau_h with (declared in ``sensors.torque_sign``).

    Returns
    -------
    trialformat.Trial
        ``perturbation.kind = "position"``, ``sensors.torque_sampling = "instantaneous"``.
    """
    n = int(round(duration_s * fs))
    rng = np.random.default_rng(seed)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    s = 2j * np.pi * f

    R = _shaped_noise(rng, f, n, ref_rms_rad, cutoff_hz, 4)
    V = _shaped_noise(rng, f, n, voluntary_rms_nm, voluntary_hz, 1)
    Zs = servo_K + servo_B * s
    Z = I * s ** 2 + B * s + K
    Th = (Zs * R + V) / (Z + Zs)
    Tau = Zs * (R - Th)
    theta = np.fft.irfft(Th, n) + theta_noise_std_rad * rng.standard_normal(n)
    tau_h = np.fft.irfft(Tau, n) + tau_noise_std_nm * rng.standard_normal(n)
    meta = tf.default_metadata(1)
    meta.update(fs=fs, n_dof=1, perturbed_dof=1, posture_deg=[0.0],
                source="estimation.synthetic.position_trial: 1-DOF limb on a PD position "
                       "servo, frequency-domain generation")
    meta["perturbation"] = {"kind": "position", "rms_rad": ref_rms_rad,
                            "cutoff_hz": cutoff_hz, "seed": seed}
    meta["sensors"].update(torque_sampling="instantaneous", torque_sign=torque_sign)
    if condition is not None:
        meta["condition"] = condition
    trial = tf.Trial(meta=meta, t=np.arange(n) / fs, theta=theta[:, None],
                     tau_h=tau_h[:, None] * 1.0,
                     theta_ref=np.fft.irfft(R, n)[:, None] if record_reference else None,
                     name=name or f"ankle_seed{seed}")
    return trial
