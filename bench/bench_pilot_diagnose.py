"""Time the diagnosis of the measured moving-ankle recording (docs/diagnosis.md, section
"Time- and state-varying effects"; issue target: <= 30 s on the 2-core machine).

    nice -n 10 python3 bench/bench_pilot_diagnose.py

Reads ../shared/data/reklab-pilot/ (GPL data, never copied: only figures are written) and
writes bench/results/time_state_pilot.json: wall and CPU time, load average, the
verdict, and the state-varying effect's rank, held-out reduction and split.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

PILOT = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "reklab-pilot"
         / "IEEETBME2022_PilotData_AV_PT1_UT2.mat")


def main() -> int:
    if not PILOT.is_file():
        print(f"no pilot recording at {PILOT.name} (../shared/data/reklab-pilot/): skipped")
        return 0
    from diagnosis.core import diagnose
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        t0, c0 = time.perf_counter(), time.process_time()
        rep = diagnose(str(PILOT), Path(tmp) / "out", progress=False, workers=1)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    rows = rep.ranking
    angle = next(((i + 1, r) for i, r in enumerate(rows) if "stiffness_angle" in r["effects"]),
                 (None, None))
    out = {"wall_s": wall, "cpu_s": cpu, "load_1min": load, "target_s": 30.0,
           "verdict": rep.verdict, "named": rep.named, "summary": rep.summary,
           "stiffness_angle": None if angle[1] is None else {
               "rank": angle[0], "held_out_reduction": angle[1]["held_out_reduction"],
               "params": angle[1]["params"], "split": angle[1].get("split")},
           "ranking": [{"effects": r["effects"], "held_out_reduction": r["held_out_reduction"]}
                       for r in rows],
           # pairs on the best single (diagnosis.limbpairs) with the second's held-out test
           "pairs": [{"effects": r["effects"], "held_out_reduction": r["held_out_reduction"],
                      "params": r["params"],
                      "second_effect_test": r.get("second_effect_test")}
                     for r in rep.pairs]}
    res = Path(__file__).parent / "results"
    res.mkdir(exist_ok=True)
    (res / "time_state_pilot.json").write_text(json.dumps(out, indent=1, default=float))
    print(f"pilot diagnosed in {wall:.1f} s wall, {cpu:.1f} s CPU (load {load:.1f}); "
          f"verdict {rep.verdict}; stiffness_angle rank {angle[0]}, held-out reduction "
          f"{angle[1] and angle[1]['held_out_reduction']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
