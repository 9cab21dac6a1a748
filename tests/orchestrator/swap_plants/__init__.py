"""Test plants of the swap-in cases, built from ``swap_plant.c`` (hand-written on the FMI 2.0
headers fmpy ships) with the system C compiler.

:func:`build_swap_plant` writes ``<name>.fmu`` for one :data:`VARIANTS` entry: the C defines,
and what its modelDescription.xml declares (units, fixed communication step, variable names,
binary platform).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import zipfile
from pathlib import Path

SOURCE = Path(__file__).with_name("swap_plant.c")
GUID = "{5a1d0c1e-0000-4000-8000-5a1d0c1e0001}"
MODEL = "SwapPlant"
DEG = 0.017453292519943295

#: variant -> C defines and model-description options
VARIANTS = {
    "nominal": {},
    "reset_fails": {"defines": ["RESET_FAILS"]},
    "reset_keeps_state": {"defines": ["RESET_KEEPS_STATE"]},
    "start_offset": {"defines": ["START_OFFSET=0.05"]},
    "deg": {"defines": ["UNIT_DEG"], "theta_unit": "deg", "omega_unit": "deg/s"},
    "deg_undefined": {"defines": ["UNIT_DEG"], "theta_unit": "deg", "omega_unit": "deg/s",
                      "unit_definitions": False},
    "fixed_step": {"defines": ["FIXED_STEP=5e-4"], "fixed_step": 5e-4},
    "fixed_step_odd": {"defines": ["FIXED_STEP=3e-4"], "fixed_step": 3e-4},
    "no_linux": {"platforms": ("win64", "darwin64")},
    "names_underscore": {"rename": lambda name: name.replace("[", "_").replace("]", "")
                         if name.startswith("theta") else name},
    "names_prefixed": {"rename": lambda name: "plant." + name if name.startswith("theta")
                       else name},
    # issue 16: plants at the edges of the contract
    "motor_enable": {"defines": ["MOTOR_ENABLE"], "motor_enable": True},
    "once_reset_fails": {"defines": ["ONCE_PER_PROCESS", "RESET_FAILS"], "once": True},
    "once_ever_reset_fails": {"defines": ["ONCE_EVER", "RESET_FAILS"], "once": True},
    "no_licence": {"defines": ["NO_LICENCE"]},
}


def _variables(opts):
    """(name, vr, causality, unit, start) of every variable."""
    out = []
    for j in (1, 2):
        out.append((f"tau_m[{j}]", j - 1, "input", "N.m", 0.0))
    for base, vr0, unit in (("theta", 2, opts.get("theta_unit", "rad")), ("tau_h", 4, "N.m"),
                            ("omega", 6, opts.get("omega_unit", "rad/s"))):
        for j in (1, 2):
            out.append((f"{base}[{j}]", vr0 + j - 1, "output", unit, None))
    starts = {"M_h": (0.187, 0.084, 0.079, 0.060), "B_h": (0.651, 0.239, 0.236, 0.407),
              "K_h": (7.967, 3.187, 1.663, 6.901)}
    units = {"M_h": "kg.m2", "B_h": "N.m.s/rad", "K_h": "N.m/rad"}
    for k, key in enumerate(("M_h", "B_h", "K_h")):
        for e, (i, j) in enumerate(((1, 1), (1, 2), (2, 1), (2, 2))):
            out.append((f"arm.{key}[{i},{j}]", 8 + 4 * k + e, "parameter", units[key],
                        starts[key][e]))
    if opts.get("motor_enable"):
        out.append(("motor_enable", 20, "input", None, 0.0))
    return out


def model_description(variant: str) -> str:
    """The FMI 2.0 modelDescription.xml of a variant."""
    opts = VARIANTS[variant]
    rename = opts.get("rename", lambda name: name)
    fixed = opts.get("fixed_step")
    units = {"rad": 'rad="1"', "rad/s": 'rad="1" s="-1"', "N.m": 'kg="1" m="2" s="-2"',
             "kg.m2": 'kg="1" m="2"', "N.m.s/rad": 'kg="1" m="2" s="-1" rad="-1"',
             "N.m/rad": 'kg="1" m="2" s="-2" rad="-1"', "deg": f'rad="1" factor="{DEG!r}"',
             "deg/s": f'rad="1" s="-1" factor="{DEG!r}"'}
    if opts.get("unit_definitions", True) is False:
        units = {k: v for k, v in units.items() if not k.startswith("deg")}
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<fmiModelDescription fmiVersion="2.0" modelName="{MODEL}" guid="{GUID}" '
             f'generationTool="hand-written C (tests/orchestrator/swap_plants, {variant})" '
             'variableNamingConvention="structured" numberOfEventIndicators="0">',
             f'  <CoSimulation modelIdentifier="{MODEL}" canHandleVariableCommunicationStepSize='
             f'"{"false" if fixed else "true"}"'
             + (' canBeInstantiatedOnlyOncePerProcess="true"' if opts.get("once") else "")
             + "/>",
             "  <UnitDefinitions>"]
    lines += [f'    <Unit name="{name}"><BaseUnit {attrs}/></Unit>' for name, attrs in units.items()]
    lines += ["  </UnitDefinitions>",
              f'  <DefaultExperiment startTime="0" stopTime="1" stepSize="{fixed or 1e-3!r}"/>',
              "  <ModelVariables>"]
    outputs = []
    for index, (name, vr, causality, unit, start) in enumerate(_variables(opts), 1):
        variability = "fixed" if causality == "parameter" else "continuous"
        extra = ' initial="exact"' if causality == "parameter" else ""
        start_attr = f' start="{start!r}"' if start is not None else ""
        unit_attr = f' unit="{unit}"' if unit else ""
        lines.append(f'    <ScalarVariable name="{rename(name)}" valueReference="{vr}" '
                     f'causality="{causality}" variability="{variability}"{extra}>'
                     f'<Real{unit_attr}{start_attr}/></ScalarVariable>')
        if causality == "output":
            outputs.append(index)
    lines += ["  </ModelVariables>", "  <ModelStructure>", "    <Outputs>"]
    lines += [f'      <Unknown index="{i}"/>' for i in outputs]
    lines += ["    </Outputs>", "    <InitialUnknowns>"]
    lines += [f'      <Unknown index="{i}"/>' for i in outputs]
    lines += ["    </InitialUnknowns>", "  </ModelStructure>", "</fmiModelDescription>", ""]
    return "\n".join(lines)


def build_swap_plant(dest_dir, variant: str, *, name: str | None = None) -> Path:
    """Compile and package ``<name or variant>.fmu`` into dest_dir; return its path."""
    import fmpy

    opts = VARIANTS[variant]
    dest_dir = Path(dest_dir)
    dest_dir.mkdir(parents=True, exist_ok=True)
    headers = Path(fmpy.__file__).resolve().parent / "c-code"
    with tempfile.TemporaryDirectory(prefix="swap-plant-") as tmp:
        lib = Path(tmp) / f"{MODEL}.so"
        defines = [f"-D{d}" for d in opts.get("defines", ())]
        cc = os.environ.get("CC", "cc")
        subprocess.run([cc, "-O2", "-fPIC", "-shared", *defines, "-I", str(headers), "-o", str(lib),
                        str(SOURCE), "-lm"], check=True, capture_output=True, text=True)
        fmu = dest_dir / f"{name or variant}.fmu"
        with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", model_description(variant))
            for platform in opts.get("platforms", ("linux64",)):
                ext = {"win64": ".dll", "darwin64": ".dylib"}.get(platform, ".so")
                z.write(lib, f"binaries/{platform}/{MODEL}{ext}")  # the bytes do not matter there
            z.write(SOURCE, "sources/swap_plant.c")
    return fmu


def have_compiler() -> bool:
    return shutil.which(os.environ.get("CC", "cc")) is not None
