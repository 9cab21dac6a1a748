"""Start-up time of the command line (issue 17: ``--help`` and bad options within 0.5 s).

Each row runs a fresh ``python3 -m orchestrator ...`` REPEATS times from the repository
root and reports the best and median wall time and the child's CPU time (user + system,
from ``resource.getrusage``: less sensitive to a loaded machine than wall time), with
the heavy modules the run loaded (numpy, scipy, matplotlib, fmpy, pandas). Side by side
in the same run, the cost of the imports the CLI used to load eagerly
(``import numpy, scipy.signal, scipy.stats, matplotlib.pyplot, fmpy``) and of a bare
interpreter. Prints a table and writes bench/results/startup.json (atomically).

    python3 bench/bench_startup.py [REPEATS]
"""

import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

from benchio import write_results

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("numpy", "scipy", "matplotlib", "fmpy", "pandas")
PROBE = ("import sys, runpy; sys.argv = ['orchestrator'] + sys.argv[1:]\n"
         "try:\n    runpy.run_module('orchestrator', run_name='__main__', alter_sys=True)\n"
         "except SystemExit:\n    pass\n"
         "finally:\n    sys.stderr.write('\\nHEAVY ' + ','.join(sorted({m.split('.')[0] for m "
         "in sys.modules if m.split('.')[0] in %r})) + '\\n')\n" % (HEAVY,))

ROWS = [
    ("--help", ["--help"]),
    ("bad option (--bogus)", ["--bogus"]),
    ("estimate --help", ["estimate", "--help"]),
    ("estimate, bad option value", ["estimate", "x", "--nperseg", "many"]),
    ("figures --help", ["figures", "--help"]),
    ("diagnose --help", ["diagnose", "--help"]),
]
REFERENCES = [
    ("bare interpreter (python3 -c pass)", ["-c", "pass"]),
    ("the eager imports of before (numpy, scipy.signal, scipy.stats, matplotlib.pyplot, "
     "fmpy)", ["-c", "import numpy, scipy.signal, scipy.stats, matplotlib.pyplot, fmpy"]),
]


def run(argv, probe=True):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    cmd = [sys.executable, "-c", PROBE, *argv] if probe else [sys.executable, *argv]
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    heavy = ""
    for line in out.stderr.splitlines():
        if line.startswith("HEAVY "):
            heavy = line[6:]
    return wall, cpu, heavy


def measure(argv, repeats, probe=True):
    walls, cpus, heavy = [], [], ""
    for _ in range(repeats):
        w, c, heavy = run(argv, probe)
        walls.append(w)
        cpus.append(c)
    return {"best_wall_s": min(walls), "median_wall_s": statistics.median(walls),
            "median_cpu_s": statistics.median(cpus),
            "heavy_modules": (heavy.split(",") if heavy else []) if probe else None}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    repeats = int(argv[0]) if argv else 7
    rows = {}
    for label, args in ROWS:
        rows[label] = {"command": "python3 -m orchestrator " + " ".join(args),
                       **measure(args, repeats)}
    for label, args in REFERENCES:
        rows[label] = {"command": "python3 " + " ".join(args),
                       **measure(args, repeats, probe=False)}
    print(f"start-up, {repeats} runs each (load average {os.getloadavg()[0]:.1f})")
    print(f"| command | best wall [s] | median wall [s] | median CPU [s] | heavy modules |")
    print("|---|---|---|---|---|")
    for label, r in rows.items():
        print(f"| {label} | {r['best_wall_s']:.3f} | {r['median_wall_s']:.3f} | "
              f"{r['median_cpu_s']:.3f} | "
              f"{'(not probed)' if r['heavy_modules'] is None else ', '.join(r['heavy_modules']) or 'none'} |")
    eager = rows[REFERENCES[1][0]]["median_cpu_s"]
    helped = rows["--help"]["median_cpu_s"]
    print(f"CPU of --help / CPU of the eager imports alone: {helped / eager:.2f}")
    doc = {"repeats": repeats, "python": platform.python_version(),
           "load_average_1min": os.getloadavg()[0], "rows": rows}
    write_results("startup", doc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
