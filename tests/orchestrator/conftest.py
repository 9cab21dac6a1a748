"""Fixtures of the orchestrator tests: the reference C plant and the pythonfmu linear plant,
each built once per session into a temporary folder, and a loaded Plant of each."""

from __future__ import annotations

import pytest

from orchestrator import Plant


@pytest.fixture(scope="session")
def reference_fmu(tmp_path_factory):
    """The ArmExoPlant C FMU built from source (package fmus)."""
    fmus = pytest.importorskip("fmus")
    return fmus.build_fmu(tmp_path_factory.mktemp("reference_fmu"))


@pytest.fixture(scope="session")
def reference_plant(reference_fmu):
    with Plant(reference_fmu) as plant:
        yield plant


@pytest.fixture(scope="session")
def linear_fmu(tmp_path_factory):
    """The linear arm plant exported by pythonfmu (another exporter)."""
    pytest.importorskip("pythonfmu")
    from orchestrator.plants import build_linear_arm_fmu
    return build_linear_arm_fmu(tmp_path_factory.mktemp("linear_fmu"))


@pytest.fixture(scope="session")
def linear_plant(linear_fmu):
    with pytest.warns(Warning):  # pythonfmu omits ModelStructure/InitialUnknowns
        plant = Plant(linear_fmu)
    with plant:
        yield plant


@pytest.fixture
def joint_two_diverges(monkeypatch):
    """Make every joint-2 trial of a grid diverge (one sample of delay under the reference
    tuning), so a test can check that a failure is reported and the rest completes."""
    import orchestrator.trial
    real = orchestrator.trial.simulate_trial

    def fail_joint_two(setup, **kwargs):
        if kwargs["perturbed_dof"] == 2:
            kwargs["effects"] = {"delay": {"samples": 1}}
        return real(setup, **kwargs)

    monkeypatch.setattr(orchestrator.trial, "simulate_trial", fail_joint_two)


@pytest.fixture(scope="session")
def swap(tmp_path_factory):
    """variant -> path of the hand-written swap plant FMU of that variant
    (tests/orchestrator/swap_plants), each built once per session."""
    from swap_plants import build_swap_plant

    folder = tmp_path_factory.mktemp("swap")
    built = {}

    def get(variant):
        if variant not in built:
            built[variant] = build_swap_plant(folder, variant)
        return built[variant]
    return get
