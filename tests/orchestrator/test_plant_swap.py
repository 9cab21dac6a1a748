"""Swapping in plants made elsewhere (issue 9): each case with its expected behaviour.

The plants are hand-written C FMUs (tests/orchestrator/swap_plants/swap_plant.c, variants
built by the C compiler) and the project's FMI 3.0 build of the reference plant.
"""

import warnings
import zipfile

import fmpy
import numpy as np
import pytest
from swap_plants import have_compiler

from orchestrator import (ContractError, Plant, PlantFileError, PlantWarning, RateError, Setup,
                          run_grid, simulate_plant, simulate_trial)

pytestmark = pytest.mark.skipif(not have_compiler(), reason="no C compiler")

SETUP = Setup.reference(0, 0)


def _trial(plant, dof=1, seconds=1.0, **kw):
    return simulate_trial(SETUP, perturbed_dof=dof, duration_s=seconds, plant=plant, seed=4, **kw)


def _same(a, b, rtol=0.0):
    for sig in ("theta", "tau_h", "tau_m"):
        if rtol:
            np.testing.assert_allclose(a.signal(sig), b.signal(sig), rtol=rtol,
                                       atol=rtol * np.abs(b.signal(sig)).max(), err_msg=sig)
        else:
            np.testing.assert_array_equal(a.signal(sig), b.signal(sig), err_msg=sig)


@pytest.fixture(scope="module")
def nominal_trials(swap):
    """Trials of the well-behaved swap plant, each on a new Plant (the independent answer)."""
    out = {}
    for dof in (1, 2):
        with Plant(swap("nominal")) as plant:
            out[dof] = _trial(plant, dof)
    return out


# ---------------------------------------------------------------- FMI 3.0
@pytest.fixture(scope="module")
def fmu3(tmp_path_factory):
    fmus = pytest.importorskip("fmus")
    return fmus.build_fmu(tmp_path_factory.mktemp("fmi3"), fmi_version=3)


def test_fmi3_plant_gives_the_fmi2_trial(reference_plant, fmu3):
    """The FMI 3.0 build of the reference plant (FMU3Slave) gives the FMI 2.0 trial, bit for
    bit, also at two communication steps per control period."""
    setup = Setup.reference(3, 3)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PlantWarning)  # no spurious complaint either
        plant3 = Plant(fmu3)
    with plant3:
        assert plant3.fmi_version == 3 and plant3.n_dof == 2
        for kw in ({}, {"communication_step_s": 5e-4}):
            a = simulate_trial(setup, perturbed_dof=1, duration_s=2.0, plant=reference_plant, **kw)
            b = simulate_trial(setup, perturbed_dof=1, duration_s=2.0, plant=plant3, **kw)
            _same(a, b)
        assert b.meta["simulation"]["communication_step_s"] == 5e-4


def test_fmi3_contract_problems_name_the_fmi3_type(fmu3, tmp_path):
    """Float64 is the FMI 3.0 Real: a Float32 theta[1] is the one problem listed."""
    bad = tmp_path / "float32.fmu"
    with zipfile.ZipFile(fmu3) as zin, zipfile.ZipFile(bad, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = data.decode().replace('<Float64 name="theta[1]"',
                                             '<Float32 name="theta[1]"').encode()
            zout.writestr(item, data)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlantWarning)
        with pytest.raises(ContractError) as info:
            Plant(bad)
    msg = str(info.value)
    assert "1 problem(s)" in msg and "theta[1]: type Float32, expected Float64" in msg
    assert "expected Real" not in msg


# ---------------------------------------------------------------- binaries
def test_plant_without_binary_for_this_platform_refused_in_one_line(swap):
    with pytest.raises(PlantFileError) as info:
        Plant(swap("no_linux"))
    msg = str(info.value)
    assert "\n" not in msg
    assert f"no_linux.fmu has no binary for this platform: binaries/{fmpy.platform}/SwapPlant" \
           f"{fmpy.sharedLibraryExtension} is missing; it has binaries for darwin64, win64" in msg
    assert "sources/" in msg


# ---------------------------------------------------------------- reset
def test_failing_reset_reinstantiates_and_every_trial_succeeds(swap, nominal_trials):
    with Plant(swap("reset_fails")) as plant:
        first = _trial(plant, 1)
        with pytest.warns(PlantWarning, match=r"reset_fails\.fmu: fmi2Reset failed.*"
                                              r"re-instantiated for every trial"):
            second = _trial(plant, 2)
        third = _trial(plant, 1)
        assert plant.reinstantiated == 2
    _same(first, nominal_trials[1])
    _same(second, nominal_trials[2])
    _same(third, nominal_trials[1])


def test_grid_on_a_plant_whose_reset_fails_completes(swap, tmp_path):
    """The reported case: before, 1 trial done and the other 3 failed."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlantWarning)
        m = run_grid(tmp_path, workers=1, progress=False, fmu_path=swap("reset_fails"),
                     friction_levels=[0], resolution_levels=[0], perturbation_levels=[1, 2],
                     dofs=[1, 2], duration_s=8.2)
    assert m["n_done"] == 4 and m["n_failed"] == 0


def test_reset_that_keeps_the_state_is_caught_not_blamed_on_the_controller(swap, nominal_trials):
    with Plant(swap("reset_keeps_state")) as plant:
        first = _trial(plant, 1)
        with pytest.warns(PlantWarning, match=r"reset_keeps_state\.fmu: fmi2Reset returned OK "
                                              r"but the plant kept its state \(theta\[1\] = "):
            second = _trial(plant, 1)
    _same(first, nominal_trials[1])
    _same(second, nominal_trials[1])


def test_plant_not_starting_from_its_start_state_is_named(swap):
    with Plant(swap("start_offset")) as plant:
        with pytest.raises(ContractError, match=r"start_offset\.fmu does not start from its "
                                                r"start state: theta\[1\] = 0\.05"):
            _trial(plant, 1)


# ---------------------------------------------------------------- units
def test_deg_plant_is_converted(swap, nominal_trials):
    """theta in deg and omega in deg/s with the conversion the XML states: the master sees
    rad, and the trial equals the rad plant's to rounding (it diverged before)."""
    with Plant(swap("deg")) as plant:
        assert plant.describe()["converted_units"]
        trial = _trial(plant, 1)
        open_loop = simulate_plant(SETUP, np.full((300, 2), 0.2), plant=plant)
    _same(trial, nominal_trials[1], rtol=1e-12)
    with Plant(swap("nominal")) as plant:
        want = simulate_plant(SETUP, np.full((300, 2), 0.2), plant=plant)
    np.testing.assert_allclose(open_loop["theta"], want["theta"], rtol=1e-12, atol=1e-18)


def test_unit_without_conversion_is_refused_naming_variable_and_unit(swap):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlantWarning)
        with pytest.raises(ContractError) as info:
            Plant(swap("deg_undefined"))
    msg = str(info.value)
    assert "theta[1]: unit 'deg' has no BaseUnit" in msg and "to 'rad'" in msg
    assert "omega[2]: unit 'deg/s'" in msg


# ---------------------------------------------------------------- fixed step
def test_fixed_step_plant_is_stepped_at_its_step(swap):
    """canHandleVariableCommunicationStepSize=false, stepSize 5e-4: two steps per control
    period (the plant refuses any other step), the same trial as the variable-step plant
    stepped at 5e-4 s."""
    with Plant(swap("fixed_step")) as plant:
        assert plant.contract.fixed_step == 5e-4
        trial = _trial(plant, 1)
        with pytest.raises(RateError, match=r"fixed communication step 0\.0005 s .*"
                                            r"0\.001 s was asked for"):
            _trial(plant, 1, communication_step_s=1e-3)
    assert trial.meta["simulation"]["communication_step_s"] == 5e-4
    with Plant(swap("nominal")) as plant:
        _same(trial, _trial(plant, 1, communication_step_s=5e-4))


def test_fixed_step_that_does_not_divide_the_period_is_refused(swap):
    with Plant(swap("fixed_step_odd")) as plant:
        with pytest.raises(RateError, match=r"fixed communication step 0\.0003 s .* does not "
                                            r"divide the control period 0\.001 s"):
            _trial(plant, 1)


# ---------------------------------------------------------------- names
@pytest.mark.parametrize("variant, near", [("names_underscore", "theta_1"),
                                           ("names_prefixed", "plant.theta[1]")])
def test_contract_error_suggests_near_names(swap, variant, near):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlantWarning)
        with pytest.raises(ContractError) as info:
            Plant(swap(variant))
    msg = str(info.value)
    assert "missing variable theta[1] (output, Real, rad)" in msg
    assert f"the plant has {near}" in msg


def test_fmi3_array_variable_is_named_in_the_refusal(fmu3, tmp_path):
    """An FMI 3.0 plant with one array variable theta instead of theta[1], theta[2]."""
    import re
    bad = tmp_path / "array.fmu"
    with zipfile.ZipFile(fmu3) as zin, zipfile.ZipFile(bad, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode().replace('name="theta[1]"', 'name="theta"')
                text = re.sub(r'\s*<Float64 name="theta\[2\]"[^>]*/>', "", text)
                text = re.sub(r'\s*<(Output|InitialUnknown) valueReference="49"/>', "", text)
                data = text.encode()
            zout.writestr(item, data)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlantWarning)
        with pytest.raises(ContractError, match=r"missing variable theta\[1\] \(output, Float64, "
                                                r"rad\).*the plant has theta\b[^_]"):
            Plant(bad)
