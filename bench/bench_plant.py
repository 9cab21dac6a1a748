"""Benchmark of the ArmExoPlant FMU: 50 s of plant time driven from Python with fmpy.

5 million RK4 steps at 1e-5 s, communication step 1 ms (50 000 fmi2DoStep calls), one
fmi2SetReal (tau_m) and one fmi2GetReal (theta, tau_h) per step, at friction levels 0
and 3, under the same torque (a seeded sum of sines, 0.2-15 Hz, peaks [3, 1.8] N m).
Targets: < 1.0 s at level 0, < 1.3 s at level 3.

Measured side by side, in one run (best of --repeat):

* ``fmpy``: FMU2Slave.setReal / doStep / getReal (fmpy's checked wrappers);
* ``raw``: the same three fmi2 functions of the library fmpy loaded, called directly
  with preallocated ctypes arrays (what the orchestrator's master does);
* ``inside doStep``: the time summed around the raw fmi2DoStep calls minus the cost of
  a ctypes call (a trivial fmi2GetRealStatus call, timed the same way), i.e. the C time;
  also shown per RK4 step;
* ``C one call``: a single fmi2DoStep of 50 s (constant torque): the solver alone;
* ``PlantIO fmi2 / fmi3``: the master's own access (``orchestrator.plant.PlantIO``: pre-bound
  read / write / step) on the FMI 2.0 build and on the FMI 3.0 build of the same sources,
  which must give identical outputs.

Wall times are sensitive to other processes on the machine: the load average is printed
and stored, and CPU times (process for the loops, thread for the single call) are given
next to them.

Usage: ``python bench/bench_plant.py [--repeat 3] [--json bench/results/plant.json]``.
"""
from __future__ import annotations

import argparse
import ctypes
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import fmpy  # noqa: E402
from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

import fmus  # noqa: E402
from bench.plantio_loop import plantio_loop  # noqa: E402
from orchestrator.plant import Plant  # noqa: E402
from fmus.build import CFLAGS  # noqa: E402
from fmus.variables import MODEL_NAME, VR, friction_parameters  # noqa: E402

T_END = 50.0
TS = 1e-3
H = 1e-5
N = int(round(T_END / TS))
TARGETS = {0: 1.0, 3: 1.3}


def torque(n: int = N, seed: int = 7, peaks=(3.0, 1.8)) -> np.ndarray:
    """Seeded sum of 25 sines, 0.2-15 Hz, scaled to ``peaks`` [N m] (default [3, 1.8]);
    shape (n, len(peaks)); a longer ``peaks`` adds columns, the first ones unchanged."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * TS
    f = np.linspace(0.2, 15.0, 25)
    out = []
    for peak in peaks:
        ph = rng.uniform(0, 2 * np.pi, len(f))
        u = np.sin(2 * np.pi * np.outer(t, f) + ph).sum(axis=1)
        out.append(peak * u / np.max(np.abs(u)))
    return np.column_stack(out)


class Bench:
    def __init__(self, fmu_path: Path):
        md = read_model_description(fmu_path)
        self.slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu_path), modelIdentifier=MODEL_NAME,
                               instanceName="bench")
        self.slave.instantiate()
        self.vin = (ctypes.c_uint * 2)(VR["tau_m[1]"], VR["tau_m[2]"])
        self.vout_list = [VR[k] for k in ("theta[1]", "theta[2]", "tau_h[1]", "tau_h[2]")]
        self.vout = (ctypes.c_uint * 4)(*self.vout_list)
        # raw prototypes of our own (fmpy's attributes go through its checked wrapper)
        dll = self.slave.dll
        real_io = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t,
                                   ctypes.POINTER(ctypes.c_double))
        self.raw_set_real = real_io(("fmi2SetReal", dll))
        self.raw_get_real = real_io(("fmi2GetReal", dll))
        self.raw_do_step = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double,
                                            ctypes.c_int)(("fmi2DoStep", dll))
        self.raw_get_real_status = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_int,
                                                    ctypes.POINTER(ctypes.c_double))(("fmi2GetRealStatus", dll))

    def start(self, level: int) -> None:
        s = self.slave
        s.reset()
        s.setupExperiment(startTime=0.0)
        p = friction_parameters(level)
        s.setReal([VR[k] for k in p], list(p.values()))
        s.enterInitializationMode()
        s.exitInitializationMode()

    def run_fmpy(self, level: int, u: np.ndarray) -> tuple[float, float, np.ndarray]:
        """Returns (wall time, CPU time of the process, last outputs)."""
        self.start(level)
        s, vin, vout = self.slave, list(self.vin), self.vout_list
        ul = u.tolist()
        c0, t0 = time.process_time(), time.perf_counter()
        for k in range(N):
            s.setReal(vin, ul[k])
            s.doStep(k * TS, TS)
            y = s.getReal(vout)
        return time.perf_counter() - t0, time.process_time() - c0, np.array(y)

    def run_raw(self, level: int, u: np.ndarray) -> tuple[float, float, float, np.ndarray]:
        """Returns (wall time of the loop, its CPU time, time summed around fmi2DoStep, last outputs)."""
        self.start(level)
        s = self.slave
        c, set_real, get_real, do_step = s.component, self.raw_set_real, self.raw_get_real, self.raw_do_step
        vin, vout = self.vin, self.vout
        uin, yout = (ctypes.c_double * 2)(), (ctypes.c_double * 4)()
        ul = u.tolist()
        clock = time.perf_counter_ns
        in_step = 0
        status = 0
        c0, t0 = time.process_time(), time.perf_counter()
        for k in range(N):
            uin[0], uin[1] = ul[k]
            status |= set_real(c, vin, 2, uin)
            a = clock()
            status |= do_step(c, k * TS, TS, 1)
            in_step += clock() - a
            status |= get_real(c, vout, 4, yout)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        if status:
            raise RuntimeError("an fmi2 call failed in the raw loop")
        return wall, cpu, in_step * 1e-9, np.array(yout[:])

    def call_overhead(self) -> float:
        """Seconds per timed ctypes call of a trivial fmi2 function (measured like doStep)."""
        self.start(0)
        c, f = self.slave.component, self.raw_get_real_status
        val = ctypes.c_double()
        ref = ctypes.byref(val)
        clock = time.perf_counter_ns
        tot = 0
        for _ in range(N):
            a = clock()
            f(c, 2, ref)
            tot += clock() - a
        return tot * 1e-9 / N

    def run_one_call(self, level: int, u: np.ndarray) -> tuple[float, float]:
        """One fmi2DoStep over 50 s: (wall time, CPU time of this thread)."""
        self.start(level)
        s = self.slave
        s.setReal(list(self.vin), list(np.mean(np.abs(u), axis=0)))
        c0, t0 = time.thread_time(), time.perf_counter()
        s.doStep(0.0, T_END)
        return time.perf_counter() - t0, time.thread_time() - c0


def run_plantio(plant: Plant, level: int, u: np.ndarray) -> tuple[float, float, np.ndarray]:
    """The master's per-sample access on a Plant at friction ``level``: (wall time, CPU time,
    last outputs); the loop is bench/plantio_loop.py's."""
    return plantio_loop(plant, friction_parameters(level), u, TS)


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def compiler_version() -> str:
    try:
        return subprocess.run([os.environ.get("CC", "cc"), "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    except Exception:  # noqa: BLE001
        return "?"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="repetitions, the best is reported (default 3)")
    ap.add_argument("--json", default=str(ROOT / "bench" / "results" / "plant.json"), help="JSON output path")
    args = ap.parse_args(argv)

    load = os.getloadavg()
    fmu_path = fmus.default_fmu_path()
    b = Bench(fmu_path)
    u = torque()
    res = {}
    ovh = min(b.call_overhead() for _ in range(args.repeat))
    plants = {2: Plant(fmu_path), 3: Plant(fmus.default_fmu_path(fmi_version=3))}
    plantio = {}
    for level in (0, 3):
        best = dict.fromkeys(("fmpy", "fmpy_cpu", "raw", "raw_cpu", "in_step", "one_call", "one_call_cpu"), np.inf)
        for _ in range(args.repeat):  # side by side: each mode once per repetition
            t_fmpy, c_fmpy, y1 = b.run_fmpy(level, u)
            t_raw, c_raw, t_in, y2 = b.run_raw(level, u)
            assert np.array_equal(y1, y2), "fmpy and raw loops must give identical results"
            t_one, c_one = b.run_one_call(level, u)
            for key, val in (("fmpy", t_fmpy), ("fmpy_cpu", c_fmpy), ("raw", t_raw), ("raw_cpu", c_raw),
                             ("in_step", t_in - N * ovh), ("one_call", t_one), ("one_call_cpu", c_one)):
                best[key] = min(best[key], val)
            for version, plant in plants.items():
                t_io, c_io, y_io = run_plantio(plant, level, u)
                assert np.array_equal(y_io, y2[[0, 1, 2, 3]]), f"PlantIO FMI {version} differs"
                key = f"fmi{version}"
                best_io = plantio.setdefault(level, {}).setdefault(key, {"wall_s": np.inf, "cpu_s": np.inf})
                best_io["wall_s"] = min(best_io["wall_s"], t_io)
                best_io["cpu_s"] = min(best_io["cpu_s"], c_io)
        steps = T_END / H
        res[level] = {
            "wall_fmpy_s": best["fmpy"],
            "cpu_fmpy_s": best["fmpy_cpu"],
            "wall_raw_s": best["raw"],
            "cpu_raw_s": best["raw_cpu"],
            "inside_doStep_s": best["in_step"],
            "python_overhead_raw_s": best["raw"] - best["in_step"],
            "python_overhead_fmpy_s": best["fmpy"] - best["in_step"],
            "ns_per_rk4_step": best["in_step"] / steps * 1e9,
            "one_call_50s_s": best["one_call"],
            "one_call_50s_cpu_s": best["one_call_cpu"],
            "ns_per_rk4_step_one_call_cpu": best["one_call_cpu"] / steps * 1e9,
            "target_s": TARGETS[level],
            "meets_target_fmpy": bool(best["fmpy"] < TARGETS[level]),
            "meets_target_raw": bool(best["raw"] < TARGETS[level]),
            "meets_target_raw_cpu": bool(best["raw_cpu"] < TARGETS[level]),
            "last_outputs": y2.tolist(),
        }

    print(f"ArmExoPlant: {T_END:g} s plant time, RK4 h = {H:g} s ({T_END / H:.0f} steps), "
          f"communication step {TS:g} s ({N} doStep calls); best of {args.repeat}")
    print(f"ctypes call overhead: {ovh * 1e9:.0f} ns per call")
    print(f"load average before: {load[0]:.2f}, after: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)")
    hdr = f"{'friction':>8} | {'fmpy loop':>9} | {'raw loop':>8} | {'(cpu)':>6} | {'in doStep':>9} | {'ns/step':>7} | " \
          f"{'py ovh raw':>10} | {'py ovh fmpy':>11} | {'1 call 50s':>10} | {'(cpu)':>6} | {'target':>6}"
    print(hdr)
    print("-" * len(hdr))
    for level, r in res.items():
        print(f"{level:>8} | {r['wall_fmpy_s']:8.3f}s | {r['wall_raw_s']:7.3f}s | {r['cpu_raw_s']:5.3f}s | "
              f"{r['inside_doStep_s']:8.3f}s | {r['ns_per_rk4_step']:7.1f} | {r['python_overhead_raw_s']:9.3f}s | "
              f"{r['python_overhead_fmpy_s']:10.3f}s | {r['one_call_50s_s']:9.3f}s | {r['one_call_50s_cpu_s']:5.3f}s | "
              f"{r['target_s']:5.1f}s")
    ratios = {
        "level3_over_level0_inside_doStep": res[3]["inside_doStep_s"] / res[0]["inside_doStep_s"],
        "level3_over_level0_wall_raw": res[3]["wall_raw_s"] / res[0]["wall_raw_s"],
        "fmpy_over_raw_level0": res[0]["wall_fmpy_s"] / res[0]["wall_raw_s"],
        "fmpy_over_raw_level3": res[3]["wall_fmpy_s"] / res[3]["wall_raw_s"],
        "inside_doStep_share_raw_level0": res[0]["inside_doStep_s"] / res[0]["wall_raw_s"],
        "inside_doStep_share_raw_level3": res[3]["inside_doStep_s"] / res[3]["wall_raw_s"],
        "wall_raw_over_target_level0": res[0]["wall_raw_s"] / TARGETS[0],
        "wall_raw_over_target_level3": res[3]["wall_raw_s"] / TARGETS[3],
    }
    print("ratios: " + ", ".join(f"{k} = {v:.2f}" for k, v in ratios.items()))
    print("master's PlantIO loop (read / write / step), same sources as FMI 2.0 and FMI 3.0:")
    for level, r in plantio.items():
        ratios[f"plantio_fmi3_over_fmi2_cpu_level{level}"] = r["fmi3"]["cpu_s"] / r["fmi2"]["cpu_s"]
        print(f"  friction {level}: FMI 2.0 {r['fmi2']['wall_s']:.3f} s (cpu {r['fmi2']['cpu_s']:.3f} s), "
              f"FMI 3.0 {r['fmi3']['wall_s']:.3f} s (cpu {r['fmi3']['cpu_s']:.3f} s), identical outputs")
    for plant in plants.values():
        plant.close()

    out = {
        "benchmark": "bench/bench_plant.py",
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": {"cpu": cpu_model(), "cores": os.cpu_count(), "platform": platform.platform(),
                    "load_average_before": load[0], "load_average_after": os.getloadavg()[0],
                    "python": platform.python_version(), "fmpy": fmpy.__version__, "compiler": compiler_version(),
                    "cflags": " ".join(CFLAGS)},
        "setup": {"plant_time_s": T_END, "rk4_step_s": H, "communication_step_s": TS, "doStep_calls": N,
                  "repeat": args.repeat, "input": "seeded sum of 25 sines 0.2-15 Hz, peaks [3, 1.8] N m"},
        "ctypes_call_overhead_ns": ovh * 1e9,
        "friction_level": {str(k): v for k, v in res.items()},
        "plantio": {str(k): v for k, v in plantio.items()},
        "ratios": ratios,
    }
    path = Path(args.json)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
