"""How `estimate` and `diagnose` scale with the size of a session (issue 22 item 3).

A session is one subject's one-joint position-servo trials: the project's independent
simulator (labsim) draws one ankle (a ``nominal+reflex`` draw: the stretch reflex is the
gap the diagnosis must name) and records it ``N`` times for 9 s, each trial with its own
perturbation and noise seed; and one 600 s recording of the same ankle. ``armimp estimate``
and ``armimp diagnose`` run on each set (as subprocesses, ``--quiet``, the default
workers); the table gives the wall time, the CPU time of the process and its children,
and the wall time per trial (per 9 s of data for the long recording). Results go to
``bench/results/session.json``.

    python bench/bench_session.py                    # sizes 10, 50, 200 and the 600 s one
    python bench/bench_session.py --sizes 10,50      # chosen sizes; "600s" the long one
    python bench/bench_session.py --sizes 10 --tag before   # label a run in the JSON
    python bench/bench_session.py --evaluations --sizes 10,50,200   # CPU of one objective
                       # evaluation of every position-fit candidate at T trials, in-process

Sets are written once under ``--work`` (default ``runs/session_bench``, not in git) and reused.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout's packages
import numpy as np  # noqa: E402

RESULTS = ROOT / "bench" / "results"
TRIAL_S = 9.0
LONG_S = 600.0
SEED = 22


def _spec(duration_s: float):
    import labsim
    return labsim.draw("nominal+reflex", np.random.default_rng(SEED), duration_s=duration_s)


def make_session(folder: Path, n_trials: int) -> Path:
    """``n_trials`` 9 s recordings of one drawn ankle (seeds 1000 + i), written as
    ``trialNNN.csv/.json`` (+ truth, never read by the tools); resumable."""
    import labsim
    folder.mkdir(parents=True, exist_ok=True)
    base = _spec(TRIAL_S)
    for i in range(n_trials):
        name = f"trial{i:03d}"
        if (folder / f"{name}.json").is_file() and (folder / f"{name}.csv").is_file():
            continue
        spec = copy.deepcopy(base)
        spec.seed = 1000 + i
        labsim.write(labsim.simulate(spec), folder, name)
        label_condition(folder / f"{name}.json", "ankle")
    return folder


def label_condition(json_path: Path, condition: str) -> None:
    """Label a written trial: recordings of one limb are one set only when labelled
    (estimation.grouping: unlabelled recordings of one joint each stand alone)."""
    import json
    meta = json.loads(json_path.read_text())
    meta["condition"] = condition
    json_path.write_text(json.dumps(meta, indent=1))


def make_long(folder: Path) -> Path:
    """One 600 s recording of the same ankle; resumable."""
    import labsim
    folder.mkdir(parents=True, exist_ok=True)
    if not (folder / "long.json").is_file():
        labsim.write(labsim.simulate(_spec(LONG_S)), folder, "long")
    return folder


def _run(cmd: list[str], log: Path) -> dict:
    """Run ``cmd`` (cwd the repo); wall and CPU seconds (user + system of the children)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with open(log, "w", encoding="utf-8") as fh:
        rc = subprocess.run(cmd, cwd=ROOT, env=env, stdout=fh, stderr=subprocess.STDOUT).returncode
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "returncode": rc, "log": str(log.relative_to(ROOT))
            if log.is_relative_to(ROOT) else str(log)}


def _verdict(out: Path) -> dict:
    path = out / "report.json"
    if not path.is_file():
        return {}
    js = json.loads(path.read_text())
    return {"verdict": js.get("verdict"), "named": js.get("named_effects"),
            "fitted": js.get("fitted_parameters")}


def bench_one(label: str, folder: Path, n_trials: int, data_s: float, work: Path,
              commands: tuple) -> list[dict]:
    rows = []
    for command in commands:
        out = work / "out" / f"{label}-{command}"
        if out.exists():
            import shutil
            shutil.rmtree(out)
        if command == "estimate":  # no progress bars to silence; its results as JSON
            out.mkdir(parents=True)
            cmd = [sys.executable, "-m", "orchestrator", "estimate", str(folder), "--json",
                   str(out / "estimate.json")]
        else:
            cmd = [sys.executable, "-m", "orchestrator", command, str(folder), "--out",
                   str(out), "--quiet"]
        res = _run(cmd, work / f"{label}-{command}.log")
        row = {"set": label, "command": command, "n_trials": n_trials, "data_s": data_s,
               **res, "s_per_trial": res["wall_s"] / max(n_trials, data_s / TRIAL_S)}
        if command == "diagnose":
            row.update(_verdict(out))
        rows.append(row)
        print(f"{label:>6} {command:>9}  wall {res['wall_s']:8.1f} s  cpu {res['cpu_s']:8.1f} s"
              f"  {row['s_per_trial']:6.2f} s/trial  rc {res['returncode']}"
              f"  {row.get('verdict', '')} {row.get('named', '') or ''}", flush=True)
    return rows


def evaluation_costs(folder: Path, sizes: list[int], repeat: int = 2) -> list[dict]:
    """CPU seconds of one objective evaluation of every candidate effect of the position
    fit (diagnosis.limbfit: columns, least squares, angle residual) on the first T trials
    of ``folder``, for each T of ``sizes`` (the grid's midpoint; median of ``repeat``).
    Uses only what the fit had before issue 22 (``_Problem``, ``prepare``), so the same
    function times an older checkout."""
    import trialformat as tf
    from diagnosis import catalogue as cat
    from diagnosis import limbfit as lf
    from diagnosis import varying_effects as vary
    trials = tf.read_trials(folder)
    cfg = lf.FitConfig()
    rows = []
    for T in sizes:
        t0 = time.process_time()
        preps = lf.prepare([lf.PositionRecord.from_trial(t) for t in trials[:T]], cfg)
        prep_s = time.process_time() - t0
        costs = {}
        for name in lf.candidates(preps):
            eff = cat.get_effect(name)
            fixed = {k: v[0] for k, v in eff.choices.items()} if eff.choices else {}
            prob = (vary.make_problem(lf, preps, name, fixed, cfg, 1.0) if vary.is_varying(name)
                    else lf._Problem(preps, name, fixed, cfg))
            x = np.full(len(prob.nl), 0.5)
            ts = []
            for _ in range(repeat):
                t0 = time.process_time()
                prob.objective(x)
                ts.append(time.process_time() - t0)
            costs[name] = float(np.median(ts))
        row = {"n_trials": T, "prepare_cpu_s": prep_s, "evaluation_cpu_s": costs,
               "sum_cpu_s": float(sum(costs.values()))}
        rows.append(row)
        print(f"T={T:4d}  prepare {prep_s:6.2f} s  one evaluation of each effect: "
              f"{row['sum_cpu_s']:7.3f} s CPU  (" + ", ".join(
                  f"{k} {v:.3f}" for k, v in costs.items()) + ")", flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="10,50,200,600s",
                    help="comma-separated trial counts; 600s: the one 600 s recording")
    ap.add_argument("--work", type=Path, default=ROOT / "runs" / "session_bench")
    ap.add_argument("--commands", default="estimate,diagnose")
    ap.add_argument("--tag", default="", help="label of this run in the JSON")
    ap.add_argument("--evaluations", action="store_true",
                    help="time one objective evaluation of every position-fit candidate on "
                         "the first T trials of the 200-trial set (T from --sizes), in "
                         "this process; no commands run")
    args = ap.parse_args(argv)
    if args.evaluations:
        sizes = [int(s) for s in args.sizes.split(",") if s.strip().isdigit()]
        folder = make_session(args.work.resolve() / "sets" / "n200", max(sizes))
        rows = evaluation_costs(folder, sizes)
        path = RESULTS / "session.json"
        old = json.loads(path.read_text()) if path.is_file() else {}
        old.setdefault("evaluations", []).append(
            {"tag": args.tag, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
             "load_1min": os.getloadavg()[0], "rows": rows})
        old["bench"] = "bench/bench_session.py"
        RESULTS.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(old, indent=2))
        return 0
    sizes = [s.strip() for s in args.sizes.split(",") if s.strip()]
    commands = tuple(c.strip() for c in args.commands.split(",") if c.strip())
    work = args.work.resolve()
    work.mkdir(parents=True, exist_ok=True)
    rows = []
    for s in sizes:
        if s == "600s":
            folder = make_long(work / "sets" / "long600")
            rows += bench_one("600s", folder, 1, LONG_S, work, commands)
        else:
            n = int(s)
            folder = make_session(work / "sets" / f"n{n:03d}", n)
            rows += bench_one(f"n{n}", folder, n, n * TRIAL_S, work, commands)
    print("\n| set | command | trials | wall [s] | CPU [s] | s/trial |\n|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['set']} | {r['command']} | {r['n_trials']} | {r['wall_s']:.1f} | "
              f"{r['cpu_s']:.1f} | {r['s_per_trial']:.2f} |")
    path = RESULTS / "session.json"
    old = json.loads(path.read_text()) if path.is_file() else {}
    runs = old.get("runs", [])
    runs.append({"tag": args.tag, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                 "cpus": os.cpu_count(), "load_1min": os.getloadavg()[0], "rows": rows})
    RESULTS.mkdir(parents=True, exist_ok=True)
    old.update(bench="bench/bench_session.py", runs=runs)
    path.write_text(json.dumps(old, indent=2))
    print(f"wrote {path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
