"""Build the plant FMUs from the C sources with the system compiler.

Usage: ``python -m fmus.build [--out-dir DIR] [--cc CC] [--fmi-version {2,3,all}] [--no-modelica]``.

It also exports the plant from its Modelica source (``fmus.modelica_build``:
``ArmExoPlant_modelica.fmu``, ``ArmExoPlant_modelica_fmi3.fmu``, ``ArmExoPlant3_modelica.fmu``)
when a Python >= 3.12 with ``modelica==0.0.205`` exists; otherwise it says so in one line
and the C plant below is the only one (the fallback and the reference).

``fmus/build/ArmExoPlant.fmu`` is FMI 2.0 Co-Simulation, ``fmus/build/ArmExoPlant_fmi3.fmu``
FMI 3.0 Co-Simulation, both from the same sources (``-DFMI_VERSION=3`` selects the FMI 3.0
front end) and the one variable table. Each FMU holds ``modelDescription.xml``,
``binaries/<platform>/ArmExoPlant.<ext>`` and ``sources/`` (every C file and header needed
to rebuild it, including the FMI headers that FMPy ships; compile
``sources/ArmExoPlant_all.c``; FMI 3.0 adds ``sources/buildDescription.xml``).
"""
from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from . import generate
from .variables import MODEL_NAME, N_LINKS, model_name

PACKAGE_DIR = Path(__file__).resolve().parent
MODEL_DIR = PACKAGE_DIR / MODEL_NAME
FRAMEWORK_DIR = PACKAGE_DIR / "framework"
BUILD_DIR = PACKAGE_DIR / "build"
FMU_NAME = f"{MODEL_NAME}.fmu"
FMU3_NAME = f"{MODEL_NAME}_fmi3.fmu"

#: -O3 without -ffast-math: -ffast-math implies -ffinite-math-only, which lets the
#: compiler delete the isfinite()/NaN checks that stop a diverging step.
#: -fno-math-errno only stops libm from setting errno (and lets sin/cos combine).
CFLAGS = ["-O3", "-fPIC", "-shared", "-fvisibility=hidden", "-fno-math-errno", "-Wall", "-Wextra"]

FMI_HEADERS = {2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
               3: ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")}

_BUILD_DESCRIPTION = f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiBuildDescription fmiVersion="3.0">
  <BuildConfiguration modelIdentifier="{MODEL_NAME}">
    <SourceFileSet language="C99">
      <SourceFile name="{MODEL_NAME}_all.c"/>
      <PreprocessorDefinition name="FMI_VERSION" value="3"/>
    </SourceFileSet>
  </BuildConfiguration>
</fmiBuildDescription>
"""


class BuildError(RuntimeError):
    """The C compiler failed or is missing."""


def _fmi_header_dir() -> Path:
    import fmpy

    return Path(fmpy.__file__).resolve().parent / "c-code"


def _platform(fmi_version: int = 2) -> tuple[str, str]:
    """Binary folder and library suffix: FMI 2.0 ``linux64``, FMI 3.0 ``x86_64-linux``."""
    system, machine = platform.system(), platform.machine().lower()
    arch = {"amd64": "x86_64", "arm64": "aarch64"}.get(machine, machine)
    if system == "Linux":
        return ("linux64" if fmi_version == 2 else f"{arch}-linux"), ".so"
    if system == "Darwin":
        return ("darwin64" if fmi_version == 2 else f"{arch}-darwin"), ".dylib"
    raise BuildError(f"unsupported platform {system!r} (build on Linux or macOS)")


def source_files() -> list[Path]:
    """Every file the FMU is built from (the C sources and the generators)."""
    files = (sorted(MODEL_DIR.glob("*.c")) + sorted(MODEL_DIR.glob("*.h"))
             + [MODEL_DIR / "modelDescription.xml", MODEL_DIR / "modelDescription3.xml"]
             + sorted(MODEL_DIR.glob("modelDescription.n*.xml")))
    files += sorted(FRAMEWORK_DIR.glob("*.c")) + sorted(FRAMEWORK_DIR.glob("*.h"))
    files += [PACKAGE_DIR / "variables.py", PACKAGE_DIR / "generate.py", PACKAGE_DIR / "build.py"]
    return files


def _c_sources() -> list[Path]:
    return (sorted(MODEL_DIR.glob("*.c")) + sorted(MODEL_DIR.glob("*.h"))
            + sorted(FRAMEWORK_DIR.glob("*.c")) + sorted(FRAMEWORK_DIR.glob("*.h")))


def fmu_name(fmi_version: int = 2, n: int = 2) -> str:
    """File name of the FMU: ``ArmExoPlant.fmu``, ``ArmExoPlant_fmi3.fmu``, ``ArmExoPlant3.fmu``."""
    if n == 2:
        return FMU_NAME if fmi_version == 2 else FMU3_NAME
    return f"{model_name(n)}.fmu"


def build_fmu(out_dir: str | os.PathLike | None = None, *, cc: str | None = None,
              fmi_version: int = 2, n: int = 2) -> Path:
    """Generate, compile and package the FMU; return the path of the ``.fmu``.

    Parameters
    ----------
    out_dir : path, optional
        Folder for the FMU (default ``fmus/build/``).
    cc : str, optional
        C compiler (default: ``$CC`` or ``cc``).
    fmi_version : {2, 3}
        FMI 2.0 (``ArmExoPlant.fmu``) or FMI 3.0 Co-Simulation (``ArmExoPlant_fmi3.fmu``).
    n : int
        Number of planar links (``fmus.variables.N_LINKS``); n != 2 builds FMI 2.0
        ``ArmExoPlant{n}.fmu`` from the same sources with ``N_JOINTS = n``.

    Raises
    ------
    BuildError
        The compiler is missing or failed.
    ValueError
        Another FMI version.
    """
    if fmi_version not in FMI_HEADERS:
        raise ValueError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    if n not in N_LINKS or (n != 2 and fmi_version != 2):
        raise ValueError(f"the C plant is built for n in {N_LINKS} (FMI 3.0 for n = 2 only), "
                         f"got n={n!r}, fmi_version={fmi_version!r}")
    out_dir = Path(out_dir) if out_dir is not None else BUILD_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    cc = cc or os.environ.get("CC", "cc")
    name, identifier = fmu_name(fmi_version, n), model_name(n)
    description = MODEL_DIR / ("modelDescription.xml" if fmi_version == 2 else "modelDescription3.xml")
    if n != 2:
        description = MODEL_DIR / f"modelDescription.n{n}.xml"
    generate.generate()
    with tempfile.TemporaryDirectory(prefix="armexo-build-") as tmp:
        src = Path(tmp) / "sources"
        src.mkdir()
        for f in _c_sources():
            shutil.copy2(f, src / f.name)
        for h in FMI_HEADERS[fmi_version]:
            shutil.copy2(_fmi_header_dir() / h, src / h)
        if fmi_version == 3:
            (src / "buildDescription.xml").write_text(_BUILD_DESCRIPTION)
        if n != 2:  # the source file the model description names
            (src / f"{identifier}_all.c").write_text(
                f"/* The {n}-link plant: ArmExoPlant_all.c with N_JOINTS = {n}. */\n"
                f"#define N_JOINTS {n}\n#include \"{MODEL_NAME}_all.c\"\n")
        pack_fmu(cc, CFLAGS, fmi_version, src, identifier, description, out_dir / name,
                 (MODEL_DIR / "readme.md").read_text(encoding="utf-8"))
    return out_dir / name



def pack_fmu(cc, cflags, fmi_version, src, identifier, description, fmu, readme):
    """Compile ``src/IDENTIFIER_all.c`` into the platform binary and zip it with the model
    description, the sources and ``readme`` (text) as ``fmu``, atomically: readers never see
    half an FMU.

    Raises
    ------
    BuildError
        The compiler is missing or failed (the command and its last output named).
    """
    fmu = Path(fmu)
    plat, ext = _platform(fmi_version)
    lib = Path(src).parent / f"{identifier}{ext}"
    cmd = [cc, *cflags, f"-DFMI_VERSION={fmi_version}", "-I", str(src), "-o", str(lib),
           str(Path(src) / f"{identifier}_all.c"), "-lm"]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True)
    except FileNotFoundError as exc:
        raise BuildError(f"C compiler {cc!r} not found; install a C compiler or set CC") from exc
    if proc.returncode != 0:
        raise BuildError(f"compiling {fmu.name} failed ({' '.join(cmd)}):\n{proc.stderr[-4000:]}")
    tmp_fmu = fmu.with_name(f".{fmu.name}.{os.getpid()}.tmp")
    with zipfile.ZipFile(tmp_fmu, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(description, "modelDescription.xml")
        z.write(lib, f"binaries/{plat}/{identifier}{ext}")
        for f in sorted(Path(src).iterdir()):
            z.write(f, f"sources/{f.name}")
        z.writestr("documentation/readme.md", readme)
    os.replace(tmp_fmu, fmu)

def default_fmu_path(build_if_missing: bool = True, *, fmi_version: int = 2, n: int = 2) -> Path:
    """Path of ``fmus/build/ArmExoPlant.fmu`` (FMI 2.0) or ``ArmExoPlant_fmi3.fmu`` (FMI 3.0),
    (re)built if missing or older than a source.

    Parameters
    ----------
    build_if_missing : bool
        If False, only return the path (raise FileNotFoundError when it is missing).
    fmi_version : {2, 3}
    n : int
        Number of links (``ArmExoPlant3.fmu`` for 3).
    """
    path = BUILD_DIR / fmu_name(fmi_version, n)
    if not build_if_missing:
        if not path.exists():
            raise FileNotFoundError(f"{path} not built: run `python -m fmus.build`")
        return path
    if not path.exists() or max(f.stat().st_mtime for f in source_files()) > path.stat().st_mtime:
        return build_fmu(fmi_version=fmi_version, n=n)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m fmus.build", description=__doc__.splitlines()[0])
    parser.add_argument("--out-dir", default=None, help="output folder (default fmus/build/)")
    parser.add_argument("--cc", default=None, help="C compiler (default $CC or cc)")
    parser.add_argument("--fmi-version", choices=("2", "3", "all"), default="all",
                        help="FMI 2.0, FMI 3.0 or both (default both)")
    parser.add_argument("--no-modelica", action="store_true",
                        help="do not export the plant from its Modelica source (C plant only)")
    args = parser.parse_args(argv)
    versions = (2, 3) if args.fmi_version == "all" else (int(args.fmi_version),)
    try:
        for version in versions:
            print(build_fmu(args.out_dir, cc=args.cc, fmi_version=version))
        if 2 in versions:  # the n-link plants (FMI 2.0)
            for n in N_LINKS:
                if n != 2:
                    print(build_fmu(args.out_dir, cc=args.cc, fmi_version=2, n=n))
    except BuildError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    if not args.no_modelica:
        from . import modelica_build

        try:
            for path in modelica_build.build_all(args.out_dir, cc=args.cc):
                print(path)
        except modelica_build.ExporterUnavailable as exc:
            print(f"note: Modelica export skipped, the C plant is used: {exc}")
        except BuildError as exc:
            print(f"error: Modelica export: {exc}", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
