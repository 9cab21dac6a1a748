"""Signals on the fine grid: perturbations, the slow movement, the subject's voluntary
torque, and the channels' noise at the sampling rate.

A signal of motion comes with its first two derivatives, ``(x, x', x'')``, each of shape
(N,), computed exactly: analytic for sines and raised cosines, from the states of the
shaping filter for filtered noise (:meth:`labsim.lti.StateSpace.with_derivatives`). Each
random component draws from its own stream ``default_rng([seed, stream, joint])``, so
switching one component on or off leaves the others' draws unchanged.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from .lti import StateSpace

#: random streams, one per component (the second entry of the generator's seed)
STREAMS = {"perturbation": 1, "voluntary": 2, "noise_theta": 3, "noise_tau": 4,
           "prbs": 5, "draw": 6}


def rng_for(seed: int, stream: str, joint: int = 0) -> np.random.Generator:
    """The generator of one component (module docstring)."""
    return np.random.default_rng([int(seed), STREAMS[stream], int(joint)])


def raised_step(t: np.ndarray, a: float, b: float):
    """0 before ``a``, 1 after ``b``, a raised cosine between; with its two derivatives."""
    if b <= a:
        s = (t >= a).astype(float)
        return s, np.zeros_like(t), np.zeros_like(t)
    s = (t >= b).astype(float)
    d1, d2 = np.zeros_like(t), np.zeros_like(t)
    inside = np.nonzero((t > a) & (t < b))[0]  # only there is the cosine evaluated
    u = np.pi * (t[inside] - a) / (b - a)
    w = np.pi / (b - a)
    s[inside] = 0.5 * (1 - np.cos(u))
    d1[inside] = 0.5 * w * np.sin(u)
    d2[inside] = 0.5 * w * w * np.cos(u)
    return s, d1, d2


def product(f, g):
    """(fg, (fg)', (fg)'') of two signals given with their derivatives."""
    return (f[0] * g[0], f[1] * g[0] + f[0] * g[1],
            f[2] * g[0] + 2 * f[1] * g[1] + f[0] * g[2])


def envelope(t: np.ndarray, start: float, ramp: float, rest=(), taper: float = 0.2):
    """Ramp-in from ``start`` over ``ramp`` s, times a dip to 0 over each rest interval
    [a, b] (raised-cosine edges of ``taper`` s inside it); with derivatives."""
    env = raised_step(t, start, start + ramp)
    for a, b in rest:
        edge = min(taper, 0.5 * (b - a))
        up = raised_step(t, a, a + edge)
        down = raised_step(t, b - edge, b)
        dip = (1 - up[0] + down[0], -up[1] + down[1], -up[2] + down[2])
        env = product(env, dip)
    return env


def noise_reference(t, h, pert, rng):
    """Gaussian noise through an analog Butterworth filter over ``pert.band_hz``, RMS
    ``amplitude_rad`` over t >= 0; (x, x', x'')."""
    lo, hi = float(pert.band_hz[0]), float(pert.band_hz[1])
    if lo > 0:
        z, p, k = signal.butter(pert.order, [2 * np.pi * lo, 2 * np.pi * hi], "bandpass",
                                analog=True, output="zpk")
    else:
        z, p, k = signal.butter(pert.order, 2 * np.pi * hi, analog=True, output="zpk")
    if len(p) - len(z) < 2:
        raise ValueError(f"perturbation.order {pert.order} too low: the shaping filter "
                         f"needs a relative degree of at least 2 (order >= 2)")
    sys = StateSpace.from_zpk(z, p, k, derivatives=2)
    y = sys.simulate(rng.standard_normal(t.size)[None, :], h)
    scale = pert.amplitude_rad / np.std(y[0][t >= 0])
    return tuple(scale * y[i] for i in range(3))


def prbs_reference(t, h, pert, rng):
    """A maximum-length sequence of +-amplitude switching every ``switch_s`` (aligned on
    t = 0), optionally through a 2nd-order Butterworth low-pass at ``prefilter_hz``."""
    first = int(np.floor(t[0] / pert.switch_s))
    count = int(np.floor(t[-1] / pert.switch_s)) - first + 1
    nbits = max(4, int(np.ceil(np.log2(count + 1))))
    state = rng.integers(0, 2, nbits)
    if not state.any():
        state[0] = 1
    seq = signal.max_len_seq(nbits, state=state, length=count)[0] * 2.0 - 1.0
    idx = np.floor(t / pert.switch_s + 1e-9).astype(np.int64) - first
    x = pert.amplitude_rad * seq[np.clip(idx, 0, count - 1)]
    if pert.prefilter_hz is None:
        zero = np.zeros_like(t)
        return x, zero, zero.copy()
    w = 2 * np.pi * pert.prefilter_hz
    sys = StateSpace.from_tf([w * w], [1.0, np.sqrt(2) * w, w * w], derivatives=2)
    y = sys.simulate(x[None, :], h)
    return y[0], y[1], y[2]


def multisine_reference(t, duration, pert, rng, fine_rate):
    """Sum of sines on the grid 1/period over the band, RMS ``amplitude_rad``, by one
    inverse FFT of a period on the fine grid (exact at the grid points); (x, x', x'').

    Raises
    ------
    ValueError
        A period that is not a whole number of fine steps, or a band holding no line.
    """
    period = float(pert.period_s or duration)
    L = int(round(period * fine_rate))
    if abs(L - period * fine_rate) > 1e-6 * L:
        raise ValueError(f"perturbation.period_s={period!r} s is not a whole number of "
                         f"internal steps (1/{fine_rate:g} s)")
    df = 1.0 / period
    k_lo = max(1, int(np.ceil(pert.band_hz[0] / df - 1e-9)))
    k_hi = int(np.floor(pert.band_hz[1] / df + 1e-9))
    lines = np.arange(k_lo, k_hi + 1, max(1, int(pert.every)))
    if lines.size == 0:
        raise ValueError(f"perturbation.band_hz={pert.band_hz} holds no line of the "
                         f"1/{period:g} Hz grid")
    n = lines.size
    if pert.phases == "schroeder":
        phase = -np.pi * np.arange(1, n + 1) * np.arange(n) / n
    elif pert.phases == "random":
        phase = rng.uniform(0, 2 * np.pi, n)
    else:
        raise ValueError(f"perturbation.phases must be 'random' or 'schroeder', got "
                         f"{pert.phases!r}")
    amp = pert.amplitude_rad / np.sqrt(n / 2.0)
    out = []
    for order in range(3):
        X = np.zeros(L // 2 + 1, complex)
        X[lines] = amp * np.exp(1j * phase) * (1j * 2 * np.pi * lines * df) ** order * L / 2
        one = np.fft.irfft(X, n=L)
        idx = np.round(t * fine_rate).astype(np.int64) % L
        out.append(one[idx])
    return tuple(out)


def movement_trajectory(t, mov):
    """The slow movement x_s(t) [rad] with derivatives (:class:`labsim.spec.Movement`)."""
    if mov.kind == "sine":
        lo, hi = float(mov.range_rad[0]), float(mov.range_rad[1])
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        w = 2 * np.pi / mov.period_s
        arg = w * t + mov.phase_rad
        return mid + half * np.sin(arg), half * w * np.cos(arg), -half * w * w * np.sin(arg)
    if mov.kind == "ramps":
        levels = [float(v) for v in mov.levels_rad]
        cycle = len(levels) * (mov.hold_s + mov.ramp_s)
        x = np.full_like(t, levels[0])
        d1, d2 = np.zeros_like(t), np.zeros_like(t)
        n_cycles = int(np.ceil(max(t[-1], 0.0) / cycle)) + 1
        start = 0.0
        for c in range(n_cycles):
            for i in range(len(levels)):
                a = start + mov.hold_s
                step = raised_step(t, a, a + mov.ramp_s)
                jump = levels[(i + 1) % len(levels)] - levels[i]
                x += jump * step[0]
                d1 += jump * step[1]
                d2 += jump * step[2]
                start = a + mov.ramp_s
        return x, d1, d2
    raise ValueError(f"movement.kind must be 'sine' or 'ramps', got {mov.kind!r}")


def lowpass_noise(t, h, band_hz, order, rng):
    """Unit-RMS (over t >= 0) Gaussian noise low-passed by a Butterworth of ``order``."""
    z, p, k = signal.butter(order, 2 * np.pi * band_hz, analog=True, output="zpk")
    y = StateSpace.from_zpk(z, p, k).simulate(rng.standard_normal(t.size)[None, :], h)
    y = np.atleast_2d(y)[0]
    return y / np.std(y[t >= 0])


def pink_noise(n: int, fs: float, rng, f_min: float = 0.1) -> np.ndarray:
    """Unit-RMS noise of power density 1/f between ``f_min`` and fs/2 (flat below f_min,
    none at 0 Hz), shaped in the frequency domain."""
    f = np.fft.rfftfreq(n, 1.0 / fs)
    X = np.fft.rfft(rng.standard_normal(n))
    shape = np.zeros_like(f)
    shape[1:] = 1.0 / np.sqrt(np.maximum(f[1:], f_min))
    y = np.fft.irfft(X * shape, n=n)
    return y / np.std(y)


def hum(t: np.ndarray, f0: float, harmonics, rng) -> np.ndarray:
    """Unit-RMS mains hum: sines at f0, 2 f0, ... of relative amplitudes ``harmonics``,
    random phases."""
    y = np.zeros_like(t)
    for i, a in enumerate(harmonics, start=1):
        y += a * np.sin(2 * np.pi * i * f0 * t + rng.uniform(0, 2 * np.pi))
    return y / np.sqrt(0.5 * np.sum(np.square(harmonics)))
