"""The plant as an FMI 3.0 Co-Simulation FMU from the same sources and variable table."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from fmus import variables as V
from fmus.build import _fmi_header_dir

OUT = ["theta[1]", "theta[2]", "tau_h[1]", "tau_h[2]", "omega[1]", "omega[2]", "z[1]", "tau_f[2]"]


def test_fmpy_validates_the_fmi3_model_description(fmu3_path):
    assert validate_fmu(str(fmu3_path)) == []
    md = read_model_description(str(fmu3_path))
    assert md.fmiVersion == "3.0" and md.coSimulation is not None and md.modelExchange is None
    with zipfile.ZipFile(fmu3_path) as z:
        names = set(z.namelist())
    assert f"binaries/x86_64-linux/{V.MODEL_NAME}.so" in names
    assert "sources/buildDescription.xml" in names


def test_fmi3_variables_are_the_fmi2_table(fmu3_path, model_description):
    """Same names, value references, causalities, units and starts (Float64 for Real)."""
    md3 = read_model_description(str(fmu3_path))
    by_name = {v.name: v for v in md3.modelVariables}
    assert by_name.pop("time").causality == "independent"
    assert list(by_name) == [v.name for v in model_description.modelVariables]
    for v2 in model_description.modelVariables:
        v3 = by_name[v2.name]
        assert (v3.type, v3.valueReference, v3.causality, v3.variability, v3.unit) == \
            ("Float64", v2.valueReference, v2.causality, v2.variability, v2.unit)
        assert (v3.start is None) == (v2.start is None)
        if v2.start is not None:
            assert float(v3.start) == float(v2.start)
    assert md3.guid == model_description.guid == V.GUID


def _fmi3_api() -> set:
    text = (_fmi_header_dir() / "fmi3FunctionTypes.h").read_text()
    return {f"fmi3{name}" for name in re.findall(r"\bfmi3(\w+)TYPE\s*\(", text)}


@pytest.mark.skipif(shutil.which("nm") is None, reason="nm (binutils) not installed")
def test_exported_symbols_are_exactly_the_fmi3_api(fmu3_path, tmp_path):
    so = Path(extract(str(fmu3_path), unzipdir=tmp_path)) / "binaries" / "x86_64-linux" / f"{V.MODEL_NAME}.so"
    out = subprocess.run(["nm", "-D", "--defined-only", str(so)], capture_output=True, text=True, check=True)
    api = _fmi3_api()
    assert len(api) > 70
    assert {line.split()[-1] for line in out.stdout.splitlines() if line.strip()} == api


def _multisine_input(stop, seed=5):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, stop + 1e-9, 1e-3)
    sig = np.zeros(len(t), dtype=[("time", float), ("tau_m[1]", float), ("tau_m[2]", float)])
    sig["time"] = t
    for j, name in enumerate(("tau_m[1]", "tau_m[2]")):
        f, ph = rng.uniform(0.3, 9.0, 5), rng.uniform(0, 2 * np.pi, 5)
        sig[name] = 0.5 * np.sin(2 * np.pi * f[:, None] * t + ph[:, None]).sum(0)
    return sig


@pytest.mark.parametrize("params", [
    {},
    {"friction.Fc[1]": 0.4, "friction.Fs[1]": 0.6, "friction.sigma2[1]": 0.08,
     "friction.Fc[2]": 0.2, "friction.Fs[2]": 0.3, "friction.sigma2[2]": 0.04},
    {"actuator_lag.time_constant_s": 0.004, "transmission_compliance.k_t[1]": 800.0,
     "transmission_compliance.c_t[1]": 1.0, "gravity.tilt_deg": 20.0},
], ids=["nominal", "friction3", "effects"])
def test_fmi3_trajectories_equal_fmi2(fmu_path, fmu3_path, params):
    """fmpy drives both versions with the same input: the same RK4 steps, bit for bit."""
    kw = dict(stop_time=3.0, output_interval=1e-3, input=_multisine_input(3.0), output=OUT,
              start_values=params)
    r2 = simulate_fmu(str(fmu_path), **kw)
    r3 = simulate_fmu(str(fmu3_path), **kw)
    assert len(r2) == len(r3) == 3001
    assert np.max(np.abs(r2["theta[1]"])) > 1e-3  # the input moves the plant
    for name in OUT:
        np.testing.assert_array_equal(r3[name], r2[name], err_msg=name)


def _slave3(fmu3_path, tmp_path):
    md = read_model_description(str(fmu3_path))
    s = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmu3_path), unzipdir=tmp_path),
                  modelIdentifier=V.MODEL_NAME, instanceName="p3")
    s.instantiate()
    return s


def test_fmi3_accumulating_clock_and_residual_step(fmu3_path, tmp_path):
    """The FMI 3.0 front end shares the time grid: t += h and a final 1e-13 s step are accepted."""
    s = _slave3(fmu3_path, tmp_path)
    s.enterInitializationMode(startTime=0.0)
    s.exitInitializationMode()
    s.setFloat64([V.VR["tau_m[1]"]], [0.5])
    t = 0.0
    for _ in range(20_000):
        s.doStep(t, 1e-3)
        t += 1e-3
    before = s.getFloat64([V.VR["theta[1]"]])
    s.doStep(t, 1e-13)
    assert s.getFloat64([V.VR["theta[1]"]]) == before
    assert s.getFloat64([len(V.VARIABLES)]) == pytest.approx([20.0], abs=1e-12)  # time
    s.terminate()
    s.freeInstance()


def test_fmi3_wrong_state_call_is_refused(fmu3_path, tmp_path):
    from fmpy.fmi1 import FMICallException

    s = _slave3(fmu3_path, tmp_path)
    with pytest.raises(FMICallException):
        s.doStep(0.0, 1e-3)  # before initialisation
    with pytest.raises(FMICallException):
        s.getFloat64([V.VR["theta[1]"]])  # in Instantiated
    s.enterInitializationMode(startTime=0.0)
    s.exitInitializationMode()
    with pytest.raises(FMICallException):
        s.setFloat64([V.VR["robot.m1"]], [2.0])  # a fixed parameter after initialisation
    s.freeInstance()


_TOKEN_SCRIPT = textwrap.dedent("""
    import sys
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave
    path = sys.argv[1]
    md = read_model_description(path)
    s = FMU3Slave(guid="{%s%n%s%n}", unzipDirectory=extract(path),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="x")
    try:
        s.instantiate()
    except Exception as exc:
        print("refused:", exc)
""")


def test_fmi3_token_with_percent_signs_is_logged_as_text(fmu3_path):
    proc = subprocess.run([sys.executable, "-c", _TOKEN_SCRIPT, str(fmu3_path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "wrong instantiationToken {%s%n%s%n}" in proc.stdout, proc.stdout
