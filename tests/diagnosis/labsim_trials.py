"""labsim recordings for the diagnosis tests (a module name no other test folder uses;
imported as ``from labsim_trials import labsim_trial``, the test folder being on sys.path
under pytest's default import mode, as tests/orchestrator/orch_helpers.py)."""

import dataclasses

import numpy as np

import labsim


def labsim_trial(kind, seed=1, seconds=15.0, channel_delay_s=None):
    """A labsim recording of ``kind`` drawn with ``seed``, as bench/bench_time_state.py
    draws it: no servo reference, a band-limited noise perturbation.

    ``seconds``: its duration (None: labsim.draw's default, 60 s); ``channel_delay_s``:
    a torque-channel delay [s] set on the drawn sensors. Returns ``(trial, spec)``."""
    kw = {} if seconds is None else {"duration_s": seconds}
    spec = labsim.draw(kind, np.random.default_rng(seed), **kw)
    spec = dataclasses.replace(spec, record_reference=False, perturbation=dataclasses.replace(
        spec.perturbation, kind="noise"))
    if channel_delay_s is not None:
        spec.sensors.tau.delay_s = channel_delay_s
    return labsim.simulate(spec).trial, spec
