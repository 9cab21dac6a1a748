"""Speed of the plant exported from Modelica against the hand-written C FMU, side by side.

50 s of plant time (5 million RK4 steps at 1e-5 s), communication step 1 ms, the master's
own access loop (``orchestrator.plant.PlantIO``: write tau_m, doStep, read theta and tau_h)
under bench_plant's seeded multisine (peaks [3, 1.8] N m; three joints: [3, 1.8, 0.6]),
for the configurations nominal (friction level 0), friction level 3 and every effect with
friction level 2, of the two-joint and of the three-joint plant.  Also one 50 s doStep with
a constant torque (the solver alone, CPU time of the thread).  The two plants are run
alternately, best of ``--repeat``; the ratio is exported / C.  The loop is
bench/plantio_loop.py's (shared with bench/bench_plant.py).

With ``--callgrind`` the instructions executed inside fmi2DoStep are counted by valgrind
(``--toggle-collect=fmi2DoStep``) for one doStep of ``--callgrind-seconds`` of plant time
(constant torque), in a small C driver compiled from each FMU's ``sources/`` with the build's
flags: a figure that does not depend on the machine's load.

Usage: ``python bench/bench_modelica_export.py [--repeat 3] [--callgrind] [--only NAME ...]
[--json FILE]``.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.bench_plant import N, T_END, TS, torque  # noqa: E402
from bench.plantio_loop import plantio_loop  # noqa: E402

import fmus  # noqa: E402
from fmus import modelica_build  # noqa: E402
from fmus.variables import friction_parameters  # noqa: E402
from orchestrator.plant import Plant  # noqa: E402

EFFECTS = {"actuator_lag.time_constant_s": 0.003,
           **{f"transmission_compliance.{p}[{j}]": v for p, v in (("k_t", 300.0), ("c_t", 0.5)) for j in (1, 2)},
           **{f"interface_compliance.{p}[{j}]": v for p, v in (("k_s", 400.0), ("c_s", 2.0)) for j in (1, 2)},
           "gravity.tilt_deg": 10.0, "inertia_mismatch.scale": 0.8, "torque_sensor_lag.time_constant_s": 0.002}
EFFECTS3 = {"actuator_lag.time_constant_s": 0.003,
            **{f"transmission_compliance.k_t[{j}]": k for j, k in ((1, 300.0), (2, 300.0), (3, 100.0))},
            **{f"transmission_compliance.c_t[{j}]": c for j, c in ((1, 0.5), (2, 0.5), (3, 0.1))},
            **{f"interface_compliance.k_s[{j}]": k for j, k in ((1, 400.0), (2, 400.0), (3, 100.0))},
            **{f"interface_compliance.c_s[{j}]": c for j, c in ((1, 2.0), (2, 2.0), (3, 0.3))},
            "gravity.tilt_deg": 10.0, "inertia_mismatch.scale": 0.8, "torque_sensor_lag.time_constant_s": 0.002}
#: name -> (joints, FMU parameters)
CONFIGS = {"nominal": (2, friction_parameters(0)), "friction 3": (2, friction_parameters(3)),
           "every effect, friction 2": (2, {**EFFECTS, **friction_parameters(2)}),
           "3 joints, nominal": (3, friction_parameters(0, 3)),
           "3 joints, friction 3": (3, friction_parameters(3, 3)),
           "3 joints, every effect, friction 2": (3, {**EFFECTS3, **friction_parameters(2, 3)})}
PEAKS = {2: (3.0, 1.8), 3: (3.0, 1.8, 0.6)}
H = 1e-5  # the FMUs' default rk4_step


def loop(plant: Plant, params: dict, u: np.ndarray) -> tuple[float, float, np.ndarray]:
    """PlantIO loop over 50 s: (wall, CPU, last outputs)."""
    return plantio_loop(plant, params, u, TS)


def one_call(plant: Plant, params: dict, seconds: float = T_END) -> float:
    """CPU time of this thread in one doStep over ``seconds`` (constant torque [1, 0.5(, 0)])."""
    plant.start(params)
    io = plant.io
    io.val_in[:] = [1.0, 0.5, 0.0][:len(io.val_in)]
    io.write()
    c0 = time.thread_time()
    status = io.step(0.0, seconds, 1)
    cpu = time.thread_time() - c0
    if status:
        raise RuntimeError(f"doStep failed on {plant.path.name}")
    return cpu


_DRIVER = r"""
/* One doStep of SECONDS with a constant torque [1, 0.5]; parameters NAME=VALUE by name. */
#include MODEL_ALL
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
int main(int argc, char **argv) {
    fmi2CallbackFunctions cb = {0};
    fmi2Component c = fmi2Instantiate("bench", fmi2CoSimulation, INSTANTIATION_TOKEN, "", &cb, fmi2False, fmi2False);
    fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    for (int a = 2; a < argc; a++) {
        char *eq = strchr(argv[a], '=');
        unsigned int vr = N_VR;
        *eq = 0;
        for (unsigned int k = 0; k < N_VR; k++) if (!strcmp(VR_NAME[k], argv[a])) vr = k;
        if (vr == N_VR) { fprintf(stderr, "no variable %s\n", argv[a]); return 2; }
        double v = atof(eq + 1);
        fmi2SetReal(c, &vr, 1, &v);
    }
    fmi2EnterInitializationMode(c);
    if (fmi2ExitInitializationMode(c) != fmi2OK) return 3;
    unsigned int vin[2] = {0, 0};
    for (unsigned int k = 0; k < N_VR; k++) {
        if (!strcmp(VR_NAME[k], "tau_m[1]")) vin[0] = k;
        if (!strcmp(VR_NAME[k], "tau_m[2]")) vin[1] = k;
    }
    double u[2] = {1.0, 0.5};
    fmi2SetReal(c, vin, 2, u);
    return fmi2DoStep(c, 0.0, atof(argv[1]), fmi2True) == fmi2OK ? 0 : 4;
}
"""


def callgrind(path: Path, params: dict, seconds: float) -> int:
    """Instructions executed inside fmi2DoStep for one doStep of ``seconds`` (valgrind on a
    C driver compiled with the FMU's own sources and the build's flags)."""
    import zipfile

    from fmus.build import CFLAGS

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        with zipfile.ZipFile(path) as z:
            z.extractall(tmp)
        src = tmp / "sources"
        (src / "driver.c").write_text(_DRIVER)
        ident = read_identifier(tmp / "modelDescription.xml")
        exe = tmp / "driver"
        flags = [f for f in CFLAGS if f not in ("-shared", "-fvisibility=hidden", "-Wall", "-Wextra")]
        cmd = [os.environ.get("CC", "cc"), *flags, "-g", "-I", str(src), f'-DMODEL_ALL="{ident}_all.c"',
               "-o", str(exe), str(src / "driver.c"), "-lm"]
        subprocess.run(cmd, check=True, capture_output=True)
        out = tmp / "callgrind.out"
        args = [f"{k}={v!r}" for k, v in params.items()]
        proc = subprocess.run(["valgrind", "--tool=callgrind", "--toggle-collect=fmi2DoStep",
                               f"--callgrind-out-file={out}", str(exe), str(seconds), *args],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"the callgrind run failed: {proc.stderr[-2000:]}")
        m = re.search(r"^summary:\s*(\d+)", out.read_text(), re.M)
        if not m or int(m.group(1)) == 0:
            raise RuntimeError("no instructions counted inside fmi2DoStep")
        return int(m.group(1))


def read_identifier(description: Path) -> str:
    m = re.search(r'modelIdentifier="([^"]+)"', description.read_text())
    return m.group(1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--callgrind", action="store_true", help="count instructions with valgrind")
    ap.add_argument("--callgrind-seconds", type=float, default=1.0)
    ap.add_argument("--only", nargs="+", default=None, metavar="NAME", choices=list(CONFIGS),
                    help="run only these configurations")
    ap.add_argument("--compare-dir", default=None, metavar="DIR",
                    help="also time the exported FMUs of the same names in DIR (e.g. built from an "
                         "older commit with `python -m fmus.build --out-dir DIR`), alternately with the others")
    ap.add_argument("--json", default=None, help="write the results here (atomically)")
    args = ap.parse_args(argv)
    configs = {k: v for k, v in CONFIGS.items() if args.only is None or k in args.only}
    joints = sorted({n for n, _ in configs.values()})
    paths = {n: {"c": fmus.default_fmu_path(n=n), "modelica": modelica_build.default_fmu_path(n=n)}
             for n in joints}
    if args.compare_dir:
        for n in joints:
            other = Path(args.compare_dir) / modelica_build.fmu_name(2, n)
            if not other.is_file():
                raise SystemExit(f"--compare-dir: {other} does not exist")
            paths[n]["other"] = other
    keys = list(paths[joints[0]])
    results = {"load_average": os.getloadavg(), "configs": {}}
    for n in joints:
        u = torque(peaks=PEAKS[n])
        plants = {k: Plant(paths[n][k]) for k in keys}
        try:
            for name, (nj, params) in configs.items():
                if nj != n:
                    continue
                best = {k: [np.inf, np.inf, np.inf] for k in keys}
                for _ in range(args.repeat):
                    for key, plant in plants.items():
                        wall, cpu, y = loop(plant, params, u)
                        best[key][0] = min(best[key][0], wall)
                        best[key][1] = min(best[key][1], cpu)
                        best[key][2] = min(best[key][2], one_call(plant, params))
                        best[key + "_y"] = y
                diff = float(np.max(np.abs(best["c_y"] - best["modelica_y"])))
                results["configs"][name] = ({"joints": n} | {k: best[k] for k in keys}
                                            | {"last_output_diff": diff})
        finally:
            for plant in plants.values():
                plant.close()
    if args.callgrind:
        for name, (n, params) in configs.items():
            ic = {k: callgrind(p, params, args.callgrind_seconds) for k, p in paths[n].items()}
            results["configs"][name]["instructions"] = ic
            results["configs"][name]["instructions_per_rk4_step"] = {
                k: v / (args.callgrind_seconds / H) for k, v in ic.items()}
    results["load_average_end"] = os.getloadavg()
    print(f"50 s of plant time, 1 ms steps, PlantIO loop; best of {args.repeat}; "
          f"load average {results['load_average'][0]:.1f} -> {results['load_average_end'][0]:.1f}")
    print("| configuration | C FMU loop wall (CPU) | exported loop wall (CPU) | ratio (CPU) "
          "| one 50 s doStep CPU: C / exported | ratio |" + (" instructions per RK4 step: C / exported | ratio |"
                                                         if args.callgrind else ""))
    print("|---|---|---|---|---|---|" + ("---|---|" if args.callgrind else ""))
    for name, r in results["configs"].items():
        c, m = r["c"], r["modelica"]
        row = (f"| {name} | {c[0]:.2f} s ({c[1]:.2f} s) | {m[0]:.2f} s ({m[1]:.2f} s) | {m[1] / c[1]:.2f} "
               f"| {c[2]:.2f} s / {m[2]:.2f} s | {m[2] / c[2]:.2f} |")
        if "instructions" in r:
            ic = r["instructions_per_rk4_step"]
            row += f" {ic['c']:.0f} / {ic['modelica']:.0f} | {ic['modelica'] / ic['c']:.2f} |"
        print(row)
    if "other" in keys:
        print(f"the exported FMUs of {args.compare_dir}, timed alternately with the above:")
        print("| configuration | loop CPU: other / C | ratio | one 50 s doStep CPU: other / C | ratio |"
              + (" instructions per RK4 step: other | ratio |" if args.callgrind else ""))
        print("|---|---|---|---|---|" + ("---|---|" if args.callgrind else ""))
        for name, r in results["configs"].items():
            c, o = r["c"], r["other"]
            row = (f"| {name} | {o[1]:.2f} s / {c[1]:.2f} s | {o[1] / c[1]:.2f} "
                   f"| {o[2]:.2f} s / {c[2]:.2f} s | {o[2] / c[2]:.2f} |")
            if "instructions" in r:
                ic = r["instructions_per_rk4_step"]
                row += f" {ic['other']:.0f} | {ic['other'] / ic['c']:.2f} |"
            print(row)
    if args.json:
        out = Path(args.json)
        tmp = out.with_suffix(".tmp")
        tmp.write_text(json.dumps(results, indent=1, default=float))
        tmp.replace(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
