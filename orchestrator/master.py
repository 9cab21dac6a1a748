"""The co-simulation master: one base rate (the communication step), the controller and
samplers decimated from it, recording through a recorder object.

Time is ``t = t0 + k * h`` with an integer step counter k (never accumulated). The
controller runs every ``decimation = Ts / h`` base steps, and the input is held over them.
"""

from __future__ import annotations

import math

import numpy as np

# a closed loop whose joint angle deviation leaves +-ANGLE_LIMIT_RAD has diverged (one
# value with the readers' "angles in degrees?" checks)
from trialformat.reference import ANGLE_LIMIT_RAD

from .errors import DivergenceError, FMUCallError, RateError
from .plant import step_error



def decimation(control_period: float, communication_step: float | None) -> int:
    """Number of communication steps per control period.

    Raises
    ------
    RateError
        When the period is not an integer multiple of the step (within 1e-9 relative).
    """
    if communication_step is None:
        return 1
    if not communication_step > 0 or not math.isfinite(communication_step):
        raise RateError(f"communication step must be > 0 s, got {communication_step!r}")
    ratio = control_period / communication_step
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-9 * ratio:
        raise RateError(f"control period {control_period!r} s is not an integer multiple of "
                        f"the communication step {communication_step!r} s (ratio {ratio:.6g})")
    return k


class Recorder:
    """Collects the signals of each control sample; :meth:`arrays` gives (N, n) arrays.

    Parameters
    ----------
    signals : tuple of str
        Names of the recorded signals, in the order :meth:`record` receives them.
    """

    def __init__(self, signals=("theta", "tau_h", "tau_m")):
        self.signals = tuple(signals)
        self._rows = []
        self._append = self._rows.append

    def record(self, *values) -> None:
        """Append one sample: one sequence of per-joint floats per signal, in order."""
        self._append(values)

    def __len__(self) -> int:
        return len(self._rows)

    def arrays(self) -> dict:
        """Signal name -> ndarray (N, n) of the recorded samples."""
        return {s: np.array([row[i] for row in self._rows], dtype=float)
                for i, s in enumerate(self.signals)}


class Sampler:
    """Encoder and torque sensor at the control rate: white noise, then quantisation.

    ``q(x) = r * round(x / r)`` (reference.md section 5; round half to even, as numpy);
    ``r = 0`` means no quantisation. Noise is added before quantisation (effects.md).

    Parameters
    ----------
    n_dof : int
    encoder_resolution_rad : float [rad]
    torque_resolution_nm : float [N m]
    theta_noise, tau_noise : ndarray (N, n) or None
        Pre-drawn noise samples [rad], [N m] (None: no noise).
    """

    def __init__(self, n_dof, encoder_resolution_rad=0.0, torque_resolution_nm=0.0,
                 theta_noise=None, tau_noise=None):
        self.n_dof = n_dof
        self.r_theta = float(encoder_resolution_rad)
        self.r_tau = float(torque_resolution_nm)
        if (theta_noise is None) != (tau_noise is None):
            shape = np.shape(theta_noise if tau_noise is None else tau_noise)
            zeros = np.zeros(shape)
            theta_noise, tau_noise = (zeros if theta_noise is None else theta_noise,
                                      zeros if tau_noise is None else tau_noise)
        self.theta_noise = None if theta_noise is None else np.asarray(theta_noise).tolist()
        self.tau_noise = None if tau_noise is None else np.asarray(tau_noise).tolist()
        self.ideal = self.r_theta == 0 and self.r_tau == 0 and theta_noise is None
        self._both = bool(self.r_theta and self.r_tau)
        self._resolutions = [self.r_theta] * n_dof + [self.r_tau] * n_dof
        self._pairs = tuple(zip(self._resolutions, range(2 * n_dof)))

    def sample(self, n: int, outputs: list) -> list:
        """Measured ``[theta..., tau_h...]`` of sample n from the plant outputs (same order)."""
        if self.ideal:
            return outputs
        if self.theta_noise is not None:
            k = self.n_dof
            outputs = ([x + e for x, e in zip(outputs[:k], self.theta_noise[n])]
                       + [x + e for x, e in zip(outputs[k:], self.tau_noise[n])])
        if self._both:  # the common case: one pass
            return [r * round(outputs[i] / r) for r, i in self._pairs]
        return [r * round(x / r) if r else x for x, r in zip(outputs, self._resolutions)]


class DelayLine:
    """Extra actuation delay: the command of sample n is applied from (n + d) Ts.

    Before the first command arrives the applied torque is zero.
    """

    def __init__(self, samples: int, n_dof: int):
        self.samples = samples
        self._buffer = [[0.0] * n_dof for _ in range(samples)]
        self._index = 0

    def push(self, command: list) -> list:
        """Store ``command`` and return the one issued ``samples`` samples ago."""
        i = self._index
        applied = self._buffer[i]
        self._buffer[i] = command
        self._index = (i + 1) % self.samples
        return applied



class ActiveLimb:
    """An active torque of the limb in the closed loop (a test model outside the catalogue).

    ``human(n, outputs) -> list`` [N m] is evaluated at sample n from the true plant outputs
    [theta..., tau_h...] (SI). The limb is rigidly held, so its torque adds to the applied
    torque over the interval; the torque sensor reads the plant's passive tau_h minus the
    torque the limb applied over the interval before.
    """

    def __init__(self, human, n_dof: int):
        self.human, self.n_dof, self.active = human, n_dof, [0.0] * n_dof

    def wrap(self, sample, push):
        """The sampler and the command path with the limb's torque in them (SI units)."""
        n_dof = self.n_dof

        def sample_with_limb(n, outputs):
            outputs[n_dof:2 * n_dof] = [x - a for x, a in
                                        zip(outputs[n_dof:2 * n_dof], self.active)]
            self.active = list(self.human(n, outputs))
            return sample(n, outputs)

        def push_with_limb(tau_m):
            applied = tau_m if push is None else push(tau_m)
            return [x + a for x, a in zip(applied, self.active)]

        return sample_with_limb, push_with_limb

def run_closed_loop(io, controller, sampler, tau_delta, recorder, *, control_period,
                    n_decimation=1, delay=None, t0=0.0, condition="", human=None) -> None:
    """Run the sampled closed loop for ``len(tau_delta)`` control samples.

    At sample n (t = t0 + n Ts): read the plant outputs (state at the end of the previous
    interval), sample them, compute tau_m[n], record, and hold the (possibly delayed)
    command over ``n_decimation`` communication steps of ``Ts / n_decimation``.

    The FMI calls are made here directly on the pre-bound ctypes functions of ``io`` (a
    method call per FMI call would cost a tenth of the controller budget); they are the same
    for FMI 2.0 and 3.0 plants. A plant in other units than the contract's is converted on
    the way (``io.output_converter``, ``io.input_converter``; nothing is added otherwise).

    Parameters
    ----------
    io : PlantIO
    controller : IMBIC
    sampler : Sampler
    tau_delta : list of list of float [N m]
        Perturbation per sample and joint.
    recorder : Recorder
        Receives (measured, tau_m) per sample, measured = [theta..., tau_h...].
    control_period : float [s]
    n_decimation : int
        Communication steps per control period.
    delay : DelayLine or None
    t0 : float [s]
    condition : str
        Named in a DivergenceError.
    human : callable, optional
        ``human(n, outputs) -> list`` [N m]: an active torque of the limb at sample n from
        the true plant outputs (e.g. a reflex), held over the interval. The limb is
        rigidly held, so it adds to the applied torque; the torque sensor between robot
        and limb reads the plant's passive tau_h minus the torque the limb applied over
        the interval before (a test model of effects outside the catalogue).

    Raises
    ------
    DivergenceError
        The controller's command left its torque limit; the message gives the condition,
        the time and the value.
    FMUCallError
        An FMI call returned a status above Warning.
    """
    h = control_period / n_decimation
    read, write, step, names = io.read, io.write, io.step, io.names
    val_in, val_out = io.val_in, io.val_out
    sample, push = sampler.sample, None if delay is None else delay.push
    if human is not None:
        sample, push = ActiveLimb(human, len(val_in)).wrap(sample, push)
    sample, push = io.output_converter(sample), io.input_converter(push)
    control, record = controller.step, recorder.record
    n = 0
    try:
        for n, d in enumerate(tau_delta):
            if read() > 1:
                raise FMUCallError(f"{names[0]} failed at t={t0 + n * control_period!r} s")
            measured = sample(n, val_out[:])
            tau_m = control(measured, d)
            record(measured, tau_m)
            val_in[:] = tau_m if push is None else push(tau_m)
            if write() > 1:
                raise FMUCallError(f"{names[1]} failed at t={t0 + n * control_period!r} s")
            k = n * n_decimation
            for i in range(n_decimation):
                t = t0 + (k + i) * h
                status = step(t, h, 1)
                if status > 1:
                    raise step_error(status, t, h, names[2])
    except DivergenceError as exc:
        raise divergence(condition, n, control_period, t0, str(exc)) from None


def run_open_loop(io, tau_applied, recorder, *, control_period, n_decimation=1, t0=0.0):
    """Step the plant under a given torque history (no controller): the plant-alone cost.

    Records the plant outputs of each sample (state before the sample's torque acts), in SI
    units.
    Same FMI call pattern as :func:`run_closed_loop`.
    """
    h = control_period / n_decimation
    read, write, step, names = io.read, io.write, io.step, io.names
    val_in, val_out = io.val_in, io.val_out
    to_si = io.output_converter(lambda n, outputs: outputs)
    to_plant = io.input_converter(None)
    record = recorder.record
    for n, tau in enumerate(tau_applied):
        if read() > 1:
            raise FMUCallError(f"{names[0]} failed at t={t0 + n * control_period!r} s")
        record(to_si(n, val_out[:]))
        val_in[:] = tau if to_plant is None else to_plant(tau)
        if write() > 1:
            raise FMUCallError(f"{names[1]} failed at t={t0 + n * control_period!r} s")
        k = n * n_decimation
        for i in range(n_decimation):
            t = t0 + (k + i) * h
            status = step(t, h, 1)
            if status > 1:
                raise step_error(status, t, h, names[2])


def divergence(condition, n, control_period, t0, what) -> DivergenceError:
    t = t0 + n * control_period
    return DivergenceError(f"closed loop diverged{' in ' + condition if condition else ''} "
                           f"at t={t:.3f} s (sample {n}): {what}")


def check_angles(theta: np.ndarray, condition: str, control_period: float,
                 t0: float = 0.0) -> None:
    """Raise DivergenceError at the first sample where |theta| > ANGLE_LIMIT_RAD."""
    bad = ~(np.abs(theta) <= ANGLE_LIMIT_RAD)
    if bad.any():
        n = int(np.argmax(bad.any(axis=1)))
        raise divergence(condition, n, control_period, t0,
                         f"theta={theta[n].tolist()!r} rad beyond +-{ANGLE_LIMIT_RAD} rad")
