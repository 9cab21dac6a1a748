"""Known-answer recordings of a joint with intrinsic and reflex pathways (parallel cascade).

Independent of :mod:`estimation.reflex` (which fits the model): the angle is a multisine
whose velocity and acceleration are exact (analytic derivatives), the reflex input is the
analytic velocity at ``t - delay``, rectified, and the activation dynamics are simulated in
continuous time by ``scipy.signal.lsim``; torque noise is white Gaussian. Used by the tests
and by bench/bench_reflex.py.
"""

from __future__ import annotations

import numpy as np

from trialformat import FORMAT, Trial
from trialformat.logs import complete_metadata


def parallel_cascade(*, K=80.0, B=1.0, I=0.015, G=4.0, delay_s=0.045, cutoff_hz=3.0,
                     damping=0.7, rectify="positive", duration_s=40.0, fs=1000.0,
                     angle_std=0.015, f_max_hz=12.0, noise=0.05, seed=0, corner_hz=4.0):
    """Angle and torque of ``tq = K th + B th' + I th'' + G LP[N(th'(t - d))] + noise``.

    Parameters
    ----------
    K [N m/rad], B [N m s/rad], I [kg m^2] : intrinsic pathway
    G [N m s/rad], delay_s [s], cutoff_hz [Hz], damping [-] : reflex pathway, LP(s) =
        wn^2 / (s^2 + 2 damping wn s + wn^2), wn = 2 pi cutoff_hz
    rectify : "positive" (N(v) = max(v, 0)), "negative" (max(-v, 0)) or "none" (v)
    duration_s [s], fs [Hz] : length and sampling rate
    angle_std [rad] : standard deviation of the angle
    f_max_hz [Hz] : the multisine holds every third frequency of the 1/duration grid from
        0.15 Hz to f_max_hz, amplitudes falling as a 2nd-order low-pass at 4 Hz, random
        phases (the ankle recordings' perturbation has most power below 4 Hz)
    corner_hz [Hz] : corner of that amplitude roll-off; None for a flat (broadband)
        spectrum up to f_max_hz
    noise : torque noise standard deviation as a fraction of the noise-free torque's
    seed : random phases and noise

    Returns
    -------
    dict with ``t`` (N,) [s], ``theta`` (N,) [rad], ``tau`` (N,) [N m], ``reflex`` (N,)
    [N m] (the reflex pathway's torque, noise-free) and ``truth`` (the parameters, delay
    in ms).
    """
    from scipy import signal
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration_s * fs))) / fs
    f = np.arange(0.15, f_max_hz, 3.0 / duration_s)
    amp = np.ones(f.size) if corner_hz is None else 1.0 / np.sqrt(1.0 + (f / corner_hz) ** 4)
    phase = rng.uniform(0.0, 2 * np.pi, f.size)
    w = 2 * np.pi * f

    def angle(tt, k):  # k-th derivative of sum a sin(w t + p)
        out = np.zeros_like(tt)
        for a, wi, p in zip(amp, w, phase):
            out += a * wi ** k * np.sin(wi * tt + p + k * np.pi / 2)
        return out

    scale = angle_std / angle(t, 0).std()
    th, vel, acc = (scale * angle(t, k) for k in (0, 1, 2))
    vd = scale * angle(t - delay_s, 1)
    u = {"positive": np.maximum(vd, 0.0), "negative": np.maximum(-vd, 0.0),
         "none": vd}[rectify]
    wn = 2 * np.pi * cutoff_hz
    _, activation, _ = signal.lsim(([wn * wn], [1.0, 2 * damping * wn, wn * wn]), u, t)
    reflex = G * activation
    tau = K * th + B * vel + I * acc + reflex
    tau = tau + noise * tau.std() * rng.standard_normal(t.size)
    truth = {"K": K, "B": B, "I": I, "G": G, "delay_ms": 1e3 * delay_s,
             "cutoff_hz": cutoff_hz, "damping": damping}
    return {"t": t, "theta": th, "tau": tau, "reflex": reflex, "truth": truth}


def parallel_cascade_trial(name="reflex", **kwargs) -> Trial:
    """:func:`parallel_cascade` as a one-joint position-perturbation trialformat.Trial."""
    sim = parallel_cascade(**kwargs)
    fs = float(kwargs.get("fs", 1000.0))
    meta = {"format": FORMAT, "fs": fs, "n_dof": 1, "perturbed_dof": 1,
            "perturbation": {"kind": "position"}, "posture_deg": [0.0],
            "sensors": {"torque_sampling": "instantaneous"},
            "source": "estimation.synthetic_reflex: parallel cascade "
                      + ", ".join(f"{k}={v:g}" for k, v in sim["truth"].items())}
    complete_metadata(meta, name)  # the set-up keys this simulation does not model
    return Trial(meta=meta, t=sim["t"], theta=sim["theta"][:, None],
                 tau_h=sim["tau"][:, None], name=name)
