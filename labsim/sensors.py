"""Acquisition: analog filters on the fine grid, channel delay, sampling at fs, noise and
quantisation.

Each analog channel passes the common anti-alias filter (:class:`labsim.spec.Sensors`,
e.g. a 4th-order Butterworth at 0.4 fs, the same on every channel so that it leaves the
angle-to-torque FRF unchanged) and its own filter (a torque amplifier's 2nd-order
low-pass, which does change the FRF), both continuous-time systems stepped exactly
(:mod:`labsim.lti`); it is then read ``delay_s`` late (linear interpolation on the fine
grid), sampled at fs, and receives noise (white, pink, mains hum; added before
quantisation, as docs/spec/effects.md requires) and its offset, then is rounded to its
``resolution``.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from .lti import StateSpace
from .signals import hum, pink_noise


def analog_filter(flt, fs: float) -> StateSpace:
    """The state space of a :class:`labsim.spec.Filter` (unit DC gain)."""
    fc = flt.cutoff_hz if flt.cutoff_hz is not None else 0.4 * fs
    w = 2 * np.pi * fc
    if flt.kind == "butterworth":
        return StateSpace.from_zpk(*signal.butter(flt.order, w, analog=True, output="zpk"))
    if flt.kind == "bessel":
        return StateSpace.from_zpk(*signal.bessel(flt.order, w, analog=True, output="zpk",
                                                  norm="mag"))
    if flt.kind == "second_order":
        return StateSpace.from_tf([w * w], [1.0, 2 * flt.damping * w, w * w])
    raise ValueError(f"filter kind must be butterworth, bessel or second_order; got "
                     f"{flt.kind!r}")


def acquire(x: np.ndarray, h: float, first: int, step: int, n_samples: int, fs: float,
            common, channel, rng_of) -> tuple[np.ndarray, np.ndarray]:
    """Record the fine-grid signal x (n, Nf): (recorded (n, N), noise-free (n, N)).

    ``first``: fine index of sample 0; ``step``: fine steps per sample; ``rng_of(j)``:
    the noise generator of joint j.
    """
    y = np.array(x, dtype=float)
    for flt in (common, channel.filter):
        if flt is not None:
            sys = analog_filter(flt, fs)
            y = np.vstack([sys.simulate(y[j], h, smooth=True) for j in range(y.shape[0])])
    pos = first + np.arange(n_samples) * step - channel.delay_s / h
    if pos[0] < 0:
        raise ValueError(f"channel delay {channel.delay_s!r} s longer than the pre-roll")
    grid = np.arange(y.shape[1])
    clean = np.vstack([np.interp(pos, grid, y[j]) for j in range(y.shape[0])])
    out = clean + channel.offset
    t = np.arange(n_samples) / fs
    for j in range(out.shape[0]):
        rng = rng_of(j)
        if channel.white_std:
            out[j] += channel.white_std * rng.standard_normal(n_samples)
        if channel.pink_std:
            out[j] += channel.pink_std * pink_noise(n_samples, fs, rng)
        if channel.hum_std:
            out[j] += channel.hum_std * hum(t, channel.hum_hz, channel.hum_harmonics, rng)
    if channel.resolution:
        out = np.round(out / channel.resolution) * channel.resolution
    return out, clean
