"""The built FMU: validation, simulation with fmpy, exported symbols, rebuild from sources/."""
from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

from fmus.variables import MODEL_NAME

# The FMI 2.0 Co-Simulation API: common functions + Co-Simulation functions.
FMI2_CS_API = {
    "fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate", "fmi2FreeInstance",
    "fmi2SetupExperiment", "fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2Terminate",
    "fmi2Reset", "fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal",
    "fmi2SetInteger", "fmi2SetBoolean", "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate",
    "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
    "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus", "fmi2GetRealStatus", "fmi2GetIntegerStatus",
    "fmi2GetBooleanStatus", "fmi2GetStringStatus",
}


def test_fmpy_validation_reports_no_problems(fmu_path):
    assert validate_fmu(str(fmu_path)) == []


def test_fmu_archive_layout(fmu_path):
    names = set(zipfile.ZipFile(fmu_path).namelist())
    assert "modelDescription.xml" in names
    assert f"binaries/linux64/{MODEL_NAME}.so" in names
    assert f"sources/{MODEL_NAME}_all.c" in names
    assert {"sources/model.c", "sources/config.h", "sources/fmi2.c", "sources/solver.h",
            "sources/fmi2Functions.h"} <= names


def test_simulate_fmu_runs(fmu_path):
    res = simulate_fmu(str(fmu_path), stop_time=0.5, output_interval=1e-3,
                       start_values={"tau_m[1]": 0.5, "tau_m[2]": -0.2})
    assert len(res) == 501
    assert np.all(np.isfinite(res["theta[1]"]))
    assert res["theta[1]"][-1] > 0.0  # pushed forward, moves forward


def _dynamic_symbols(so: Path) -> set[str]:
    out = subprocess.run(["nm", "-D", "--defined-only", str(so)], capture_output=True, text=True, check=True)
    return {line.split()[-1] for line in out.stdout.splitlines() if line.strip()}


@pytest.mark.skipif(shutil.which("nm") is None, reason="nm (binutils) not installed")
def test_exported_symbols_are_exactly_the_fmi2_api(unzipdir):
    so = Path(unzipdir) / "binaries" / "linux64" / f"{MODEL_NAME}.so"
    assert _dynamic_symbols(so) == FMI2_CS_API


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_sources_rebuild_standalone(unzipdir, tmp_path):
    """sources/ alone (no repository) compiles to a library with the same API."""
    src = Path(unzipdir) / "sources"
    so = tmp_path / "rebuilt.so"
    subprocess.run(["cc", "-O1", "-fPIC", "-shared", "-fvisibility=hidden", "-I", str(src), "-o", str(so),
                    str(src / f"{MODEL_NAME}_all.c"), "-lm"], check=True, capture_output=True)
    if shutil.which("nm"):
        assert _dynamic_symbols(so) == FMI2_CS_API


def test_default_fmu_path_rebuilds_when_stale(monkeypatch, tmp_path):
    import os

    from fmus import build

    monkeypatch.setattr(build, "BUILD_DIR", tmp_path)
    path = build.default_fmu_path()
    assert path == tmp_path / f"{MODEL_NAME}.fmu" and path.exists()
    first = path.stat().st_mtime_ns
    assert build.default_fmu_path().stat().st_mtime_ns == first  # up to date: not rebuilt
    os.utime(path, (0, 0))                                      # older than every source
    assert build.default_fmu_path().stat().st_mtime > 0
    with pytest.raises(FileNotFoundError, match="python -m fmus.build"):
        monkeypatch.setattr(build, "BUILD_DIR", tmp_path / "none")
        build.default_fmu_path(build_if_missing=False)


def test_build_cli(tmp_path):
    import sys

    out = subprocess.run([sys.executable, "-m", "fmus.build", "--out-dir", str(tmp_path), "--no-modelica"],
                         capture_output=True,
                         text=True, cwd=Path(__file__).resolve().parents[2])
    assert out.returncode == 0, out.stderr
    assert (tmp_path / f"{MODEL_NAME}.fmu").exists()
    assert "RuntimeWarning" not in out.stderr
