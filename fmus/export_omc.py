"""Export the plant FMU from the Modelica source with OpenModelica (omc), where installed.

Usage: ``python -m fmus.export_omc [--out-dir DIR] [--model ArmExo.ArmExoPlant]``
(or ``modelica/export_fmu.sh``).  Produces ``<out-dir>/ArmExo_ArmExoPlant.fmu`` (FMI 2.0
Co-Simulation, OpenModelica's own solver inside; its parameter and variable names equal
those of the C FMU except ``rk4_step``).  Without omc it says so and points to the C
build, ``python -m fmus.build``, which needs only a C compiler.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

MODELICA_DIR = Path(__file__).resolve().parents[1] / "modelica"
DEFAULT_OUT = Path(__file__).resolve().parent / "build"


class OmcNotFound(RuntimeError):
    """OpenModelica's omc is not on PATH."""


def mos_script(model: str, package_mo: Path) -> str:
    """The OpenModelica script that loads the package and builds the FMU."""
    return "\n".join([
        f'loadFile("{package_mo.as_posix()}"); getErrorString();',
        f'buildModelFMU({model}, version = "2.0", fmuType = "cs", '
        f'fileNamePrefix = "{model.replace(".", "_")}", platforms = {{"static"}}); getErrorString();',
        "",
    ])


def export_fmu(out_dir: str | Path | None = None, model: str = "ArmExo.ArmExoPlant", omc: str | None = None) -> Path:
    """Run omc on the Modelica source; return the path of the exported ``.fmu``."""
    omc = omc or shutil.which("omc")
    if not omc:
        raise OmcNotFound("OpenModelica's omc is not installed (not on PATH): cannot export the FMU from the "
                          "Modelica source here. Build the C FMU instead: python -m fmus.build")
    out_dir = Path(out_dir) if out_dir else DEFAULT_OUT
    out_dir.mkdir(parents=True, exist_ok=True)
    name = model.replace(".", "_") + ".fmu"
    with tempfile.TemporaryDirectory(prefix="armexo-omc-") as tmp:
        script = Path(tmp) / "export.mos"
        script.write_text(mos_script(model, MODELICA_DIR / "ArmExo" / "package.mo"))
        proc = subprocess.run([omc, str(script)], cwd=tmp, capture_output=True, text=True)
        fmu = Path(tmp) / name
        if proc.returncode != 0 or not fmu.exists():
            raise RuntimeError(f"omc failed to export {model}:\n{proc.stdout}\n{proc.stderr}")
        shutil.copy2(fmu, out_dir / name)
    return out_dir / name


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m fmus.export_omc", description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", default=None, help="output folder (default fmus/build/)")
    ap.add_argument("--model", default="ArmExo.ArmExoPlant", help="Modelica model to export")
    args = ap.parse_args(argv)
    try:
        print(export_fmu(args.out_dir, args.model))
    except OmcNotFound as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
