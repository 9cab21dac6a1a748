"""Speed and results of the diagnosis of one-joint position recordings (issue 14).

Diagnoses, each alone (one 60 s, 1 kHz, one-joint recording per diagnosis, one process):

- a synthetic 60 s recording of ``estimation.synthetic.position_trial`` (always run:
  the project's own known-answer data, no reflex, so "no significant gap" is expected);
- the five measured reklab ankle recordings (``../shared/data/reklab-ankle``, or
  ``--data DIR``), read from the ``nldat`` .mat and written as lab-format files to a temp
  folder (GPL data: nothing is kept).

Prints a table (verdict, named effect, fitted parameters with 95 % intervals, held-out
reduction, wall time) and writes ``bench/results/diagnosis_reklab.json`` atomically,
with the machine's load average (timings on a loaded machine are upper bounds).

    python bench/bench_diagnosis_reklab.py            # about a minute on 2 idle cores
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's packages
RESULTS = Path(__file__).resolve().parent / "results"
TARGET_S = 20.0


def _row(name, report, wall, cpu):
    red = report.gap.get("named_held_out_reduction")
    return {"recording": name, "verdict": report.verdict, "named": report.named,
            "fitted": report.fitted, "intervals_95": report.intervals,
            "held_out_reduction": red,
            "nominal_gap_features": report.gap.get("features", report.gap)["nominal_all"],
            "nominal_gap_limbfit": report.gap["nominal_all"] if "features" in report.gap
            else None,
            "K": report.arm["K_h"][0][0], "B": report.arm["B_h"][0][0],
            "I": report.arm["M_h"][0][0], "r2": report.arm["r2"][0][0],
            "conventions": [c["name"] for c in report.conventions],
            "ranking": [{"effect": r["effects"][0], "held_out_reduction":
                         r["held_out_reduction"], "params": r["params"],
                         "at_search_bound": r["at_search_bound"]} for r in report.ranking],
            "wall_s": round(wall, 2), "cpu_s": round(cpu, 2)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="folder holding reklab-ankle/")
    args = ap.parse_args(argv)
    import trialformat as tf
    from diagnosis import diagnose
    from diagnosis.nldat import read_nldat_trials
    from diagnosis.report import _clean
    from estimation.synthetic import position_trial

    data = Path(args.data) if args.data else Path(__file__).resolve().parents[2] / "shared" / "data"
    mat = data / "reklab-ankle" / "experimental_data.mat"
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        recordings = [position_trial(K=60.0, B=0.8, I=0.012, duration_s=60.0,
                                     record_reference=False, voluntary_rms_nm=0.0,
                                     name="synthetic_60s")]
        if mat.is_file():
            recordings += read_nldat_trials(mat)
        else:
            print(f"{mat} absent: only the synthetic recording is timed")
        for t in recordings:
            folder = tmp / t.name
            folder.mkdir()
            tf.write_trial(folder / t.name, t)
            t0, c0 = time.perf_counter(), time.process_time()
            report = diagnose(folder, tmp / f"out_{t.name}", workers=1, progress=False)
            rows.append(_row(t.name, report, time.perf_counter() - t0,
                             time.process_time() - c0))
            print(f"{t.name}: {rows[-1]['wall_s']} s wall, {rows[-1]['cpu_s']} s CPU",
                  flush=True)
    load = os.getloadavg()
    print("\n| recording | verdict | named | fitted (95 % interval) | held-out reduction | "
          "wall [s] | CPU [s] |\n|---|---|---|---|---|---|---|")
    for r in rows:
        fit = "; ".join(
            f"{k}={v:.4g}" + (f" [{r['intervals_95'][e][k][0]:.3g}, "
                              f"{r['intervals_95'][e][k][1]:.3g}]"
                              if r["intervals_95"].get(e, {}).get(k) else "")
            for e, d in r["fitted"].items() for k, v in d.items() if not isinstance(v, bool))
        red = "-" if r["held_out_reduction"] is None else f"{100 * r['held_out_reduction']:.0f} %"
        print(f"| {r['recording']} | {r['verdict']} | {', '.join(r['named']) or '-'} | "
              f"{fit or '-'} | {red} | {r['wall_s']} | {r['cpu_s']} |")
    worst = max(r["wall_s"] for r in rows)
    worst_cpu = max(r["cpu_s"] for r in rows)
    print(f"\nslowest {worst:.1f} s wall ({worst_cpu:.1f} s CPU, one process: the wall time "
          f"of an idle core) per 60 s one-joint recording (target {TARGET_S:.0f} s); load "
          f"average {load[0]:.1f} on {os.cpu_count()} cores")
    RESULTS.mkdir(exist_ok=True)
    out = {"rows": rows, "slowest_s": worst, "slowest_cpu_s": worst_cpu, "target_s": TARGET_S,
           "load_average_1min": load[0], "cores": os.cpu_count()}
    tf.atomic_write(RESULTS / "diagnosis_reklab.json",
                    lambda fh: fh.write(json.dumps(_clean(out), indent=2).encode()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
