"""The plant's log messages are kept, not printed: a failing call's FMUCallError carries
them, and nothing reaches stdout (a candidate refused inside a diagnosis search is silent)."""

import copy
import dataclasses

import pytest

from orchestrator import Setup, simulate_trial
from orchestrator.errors import FMUCallError


@pytest.fixture(scope="module", params=[2, 3], ids=["fmi2", "fmi3"])
def plant_fmu(request, tmp_path_factory):
    fmus = pytest.importorskip("fmus")
    return fmus.build_fmu(tmp_path_factory.mktemp(f"fmi{request.param}"),
                          fmi_version=request.param)


def test_a_refused_parameter_set_raises_with_the_plant_message_and_prints_nothing(
        plant_fmu, capfd):
    setup = Setup.reference(0, 0)
    with pytest.raises(FMUCallError, match=r"ExitInitializationMode.*the plant logged: "
                                           r"\[ERROR\] the mass matrix"):
        simulate_trial(setup, perturbed_dof=1, level=3, seed=1, duration_s=0.5,
                       plant=plant_fmu, parameters={"arm.M_h[1,1]": -1.0})
    assert "mass matrix" not in capfd.readouterr().out


def test_a_non_finite_state_raises_with_the_state_named_and_prints_nothing(plant_fmu, capfd):
    setup = Setup.reference(3, 0)
    friction = copy.deepcopy(setup.friction)
    friction["sigma0"] = 1e6  # LuGre bristles too stiff for the 1e-5 s RK4 step
    setup = dataclasses.replace(setup, friction=friction)
    with pytest.raises(FMUCallError, match=r"the plant logged: \[ERROR\].*non-finite"):
        simulate_trial(setup, perturbed_dof=1, level=3, seed=1, duration_s=0.5,
                       plant=plant_fmu)
    assert "non-finite" not in capfd.readouterr().out
