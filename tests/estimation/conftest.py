"""Fixtures: known-answer trials from the independent scipy simulation (estimation.synthetic).

Each simulation takes about 0.25 s; they are cached for the session.
"""

import pytest

from estimation.synthetic import synthetic_condition, synthetic_trial
from trialformat import reference as ref


@pytest.fixture(scope="session")
def arm():
    """Table I matrices (M_h, B_h, K_h)."""
    return ref.arm_matrices()


@pytest.fixture(scope="session")
def perfect_hold_trials():
    """The paper's decomposed loop: held joints do not move; smooth (FOH) perturbation."""
    return synthetic_condition(perfect_hold=True)


@pytest.fixture(scope="session")
def loose_hold_trials():
    """Held joints move (robust tuning's loose hold)."""
    return synthetic_condition(tuning="robust")


@pytest.fixture(scope="session")
def all_joints_trial():
    """Every joint perturbed at once by independent perturbations."""
    return synthetic_trial(perturbed_dof=None, seed=7)


@pytest.fixture(scope="session")
def left_limit_trials():
    """Held (ZOH) perturbation, tau_h read just before each step, perfect hold."""
    return synthetic_condition(perfect_hold=True, input_hold="zoh", sampling="left_limit")
