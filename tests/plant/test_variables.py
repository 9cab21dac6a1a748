"""One source of truth: the XML, the C code and fmus.variables agree."""
from __future__ import annotations

import re

import pytest

from fmus import generate
from fmus import variables as V


def test_generated_files_are_up_to_date():
    """variables.h and both model descriptions in the repository equal the generator's output."""
    assert (generate.MODEL_DIR / "variables.h").read_text() == generate.header_text()
    assert (generate.MODEL_DIR / "modelDescription.xml").read_text() == generate.model_description_text()
    assert (generate.MODEL_DIR / "modelDescription3.xml").read_text() == generate.model_description_text(3)


def test_xml_matches_python_table(model_description):
    mv = model_description.modelVariables
    assert [v.name for v in mv] == [v.name for v in V.VARIABLES]
    for xv, pv in zip(mv, V.VARIABLES):
        assert xv.valueReference == pv.vr
        assert xv.causality == pv.causality
        assert xv.variability == pv.variability
        assert (xv.unit or "") == pv.unit
        assert xv.type == "Real"
        if pv.start is None:
            assert xv.start is None
        else:
            assert float(xv.start) == pv.start
    assert model_description.guid == V.GUID
    assert model_description.coSimulation.modelIdentifier == V.MODEL_NAME


def test_c_header_matches_python_table():
    text = (generate.MODEL_DIR / "variables.h").read_text()
    enum = dict((name, int(vr)) for name, vr in re.findall(r"^\s+(vr_\w+) = (\d+),", text, re.M))
    assert enum == {V.c_identifier(v.name): v.vr for v in V.VARIABLES}
    names = re.findall(r'^\s+"([^"]+)",$', text, re.M)
    assert names == [v.name for v in V.VARIABLES]


def test_contract_variables_present():
    for j in (1, 2):
        assert V.BY_NAME[f"tau_m[{j}]"].causality == "input"
        for out, unit in (("theta", "rad"), ("tau_h", "N.m"), ("omega", "rad/s")):
            assert V.BY_NAME[f"{out}[{j}]"].causality == "output"
            assert V.BY_NAME[f"{out}[{j}]"].unit == unit


def test_defaults_match_reference_json():
    """The table's defaults are the reference configuration (docs/spec/reference.json)."""
    import json
    from pathlib import Path

    ref = json.loads((Path(__file__).resolve().parents[2] / "docs" / "spec" / "reference.json").read_text())
    arm, robot, fr = ref["human_arm"], ref["robot"], ref["friction"]
    s = {v.name: v.start for v in V.VARIABLES}
    assert [s["posture_deg[1]"], s["posture_deg[2]"]] == arm["posture_deg"]
    for key in ("M_h", "B_h", "K_h"):
        for i in (1, 2):
            for j in (1, 2):
                assert s[f"arm.{key}[{i},{j}]"] == arm[key][i - 1][j - 1]
    for key in ("m1", "L1", "lc1", "I1", "m2", "L2", "lc2", "I2"):
        assert s[f"robot.{key}"] == robot[key]
    assert [s["robot.Jm[1]"], s["robot.Jm[2]"]] == robot["Jm"]
    assert s["rk4_step"] == ref["timing"]["rk4_step_s"]
    for key in ("sigma0", "sigma1", "ws"):
        assert s[f"friction.{key}"] == fr[key]
    for level, values in enumerate(fr["levels"]):
        assert V.friction_parameters(level) == {f"friction.{k}[{j}]": values[k] for k in values for j in (1, 2)}


def test_every_parameter_set_and_read_back_by_vr(make_slave):
    """Set each parameter through its VR with fmpy and read it back from the C instance."""
    slave, _ = make_slave()
    slave.setupExperiment(startTime=0.0)
    vrs = [V.VR[n] for n in V.PARAMETERS]
    values = [1000.0 + vr for vr in vrs]
    slave.setReal(vrs, values)
    slave.enterInitializationMode()
    assert slave.getReal(vrs) == values
    assert slave.getReal([V.VR["tau_m[1]"], V.VR["tau_m[2]"]]) == [0.0, 0.0]


@pytest.mark.parametrize("name", V.OUTPUTS)
def test_c_names_outputs_by_vr(make_slave, name):
    """The C name table at each output VR is the Python name (seen in the refusal message)."""
    slave, log = make_slave()
    with pytest.raises(Exception):
        slave.setReal([V.VR[name]], [1.0])
    assert f"{name} is an output" in log.text()


@pytest.mark.parametrize("name", [n for n in V.PARAMETERS if n != "rk4_step"])
def test_c_names_parameters_by_vr(make_slave, name):
    """After initialisation, setting a parameter is refused with its C name = Python name."""
    slave, log = make_slave()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    with pytest.raises(Exception):
        slave.setReal([V.VR[name]], [1.0])
    assert f"{name} is a fixed parameter" in log.text()
