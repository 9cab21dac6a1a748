"""Loading plant FMUs: the contract check, parameters, bad files, reuse with reset."""

import shutil
import warnings
import zipfile

import numpy as np
import pytest

from orchestrator import (ContractError, ParameterError, Plant, PlantFileError, PlantWarning,
                          Setup, simulate_trial)


def test_reference_plant_keeps_the_contract(reference_plant):
    assert reference_plant.n_dof == 2
    assert reference_plant.contract.vr_omega
    assert reference_plant.parameters["rk4_step"] == 1e-5
    # every declared set-up parameter exists in the reference plant
    assert set(Setup.reference(3, 3).plant_parameters()) <= set(reference_plant.parameters)


def test_text_file_renamed_fmu_refused(tmp_path):
    fake = tmp_path / "plant.fmu"
    fake.write_text("this is not an FMU\n")
    with pytest.raises(PlantFileError, match=r"plant\.fmu: not an FMU \(not a ZIP"):
        Plant(fake)
    with pytest.raises(PlantFileError, match="not found"):
        Plant(tmp_path / "missing.fmu")


def test_zip_without_model_description_refused(tmp_path):
    path = tmp_path / "empty.fmu"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("readme.txt", "no model")
    with pytest.raises(PlantFileError, match="no modelDescription.xml"):
        Plant(path)


def test_plant_missing_tau_h_refused(tmp_path):
    pytest.importorskip("pythonfmu")
    from orchestrator.plants import build_linear_arm_fmu
    fmu = build_linear_arm_fmu(tmp_path, omit_outputs=("tau_h",),
                               module_name="linear_arm_no_tau_h")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlantWarning)
        with pytest.raises(ContractError) as info:
            Plant(fmu)
    msg = str(info.value)
    assert "missing variable tau_h[1]" in msg and "missing variable tau_h[2]" in msg
    assert "2 problem(s)" in msg


def _edited_fmu(src, dest, replacements):
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                for old, new in replacements:
                    assert old in text, old
                    text = text.replace(old, new)
                data = text.encode()
            zout.writestr(item, data)
    return dest


def test_every_contract_problem_listed_in_one_error(reference_fmu, tmp_path):
    """Rename tau_h[2] away and make tau_m[1] an output: both problems in one message."""
    bad = _edited_fmu(reference_fmu, tmp_path / "bad.fmu", [
        ('name="tau_h[2]"', 'name="tau_h_x[2]"'),
        ('name="tau_m[1]" valueReference', 'name="tau_m_x[1]" valueReference')])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlantWarning)
        with pytest.raises(ContractError) as info:
            Plant(bad)
    msg = str(info.value)
    assert "missing variable tau_h[2]" in msg and "missing variable tau_m[1]" in msg


def test_mistyped_variable(reference_fmu, tmp_path):
    """theta[1] declared as an input: refused, naming the causality."""
    import re
    with zipfile.ZipFile(reference_fmu) as zf:
        xml = zf.read("modelDescription.xml").decode()
    block = re.search(r'<ScalarVariable name="theta\[1\]".*?</ScalarVariable>', xml, re.S)[0]
    edited = block.replace('causality="output"', 'causality="input"').replace(
        "<Real", '<Real start="0.0"', 1)
    bad = _edited_fmu(reference_fmu, tmp_path / "mistyped.fmu", [(block, edited)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlantWarning)
        with pytest.raises(ContractError, match=r"theta\[1\]: causality 'input', expected "
                                                r"'output'"):
            Plant(bad)


def test_model_structure_complaint_is_a_warning(linear_fmu):
    """pythonfmu leaves ModelStructure/InitialUnknowns empty: simulate anyway, warn."""
    with pytest.warns(PlantWarning, match="InitialUnknowns"):
        plant = Plant(linear_fmu)
    plant.close()


def test_unknown_parameter_refused(reference_plant, linear_plant):
    setup = Setup.reference()
    with pytest.raises(ParameterError, match=r"no parameter robot\.m3"):
        simulate_trial(setup, perturbed_dof=1, duration_s=0.1, plant=reference_plant,
                       parameters={"robot.m3": 1.0})
    with pytest.raises(ParameterError, match="tau_h.*not a parameter"):
        reference_plant.check_parameters(["tau_h[1]"])
    # an effect the plant cannot simulate is refused, not silently dropped
    with pytest.raises(ParameterError, match="actuator_lag.time_constant_s"):
        simulate_trial(setup, perturbed_dof=1, duration_s=0.1, plant=linear_plant,
                       effects={"actuator_lag": {"time_constant_s": 0.004}})


def test_declared_parameters_absent_from_plant_are_recorded(linear_plant):
    trial = simulate_trial(Setup.reference(0), perturbed_dof=1, duration_s=0.2,
                           plant=linear_plant)
    absent = trial.meta["simulation"]["declared_parameters_not_in_plant"]
    assert "friction.Fc[1]" in absent and "robot.m1" in absent  # zero friction: no change
    assert "arm.M_h[1,1]" not in absent


def test_declared_friction_the_plant_lacks_is_refused_by_name(linear_plant):
    """Issue 16: --friction 2 on a plant without friction parameters was ignored silently
    (F2 equal to F0); it is refused naming the parameters and their values."""
    with pytest.raises(ParameterError, match=r"linear_arm\.fmu has no parameter friction\.Fc\[1\]"
                       r".*friction\.Fc\[1\] = 0\.2.*ignored silently"):
        simulate_trial(Setup.reference(2), perturbed_dof=1, duration_s=0.2, plant=linear_plant)


def test_instance_reused_with_reset(reference_fmu):
    setup = Setup.reference(3, 3)
    with Plant(reference_fmu) as plant:
        a = simulate_trial(setup, perturbed_dof=2, duration_s=1.0, plant=plant)
        b = simulate_trial(Setup.reference(1, 1), perturbed_dof=1, duration_s=0.5, plant=plant)
        c = simulate_trial(setup, perturbed_dof=2, duration_s=1.0, plant=plant)
    assert b.n_samples == 500
    for sig in ("theta", "tau_h", "tau_m"):
        np.testing.assert_array_equal(a.signal(sig), c.signal(sig))


def test_plant_copy_with_other_name_loads(reference_fmu, tmp_path):
    copy = tmp_path / "renamed.fmu"
    shutil.copy2(reference_fmu, copy)
    with Plant(copy) as plant:
        assert plant.describe()["file"] == "renamed.fmu"
