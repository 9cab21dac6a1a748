"""Issue 22 item 3: an nldat recording stored in degrees, K estimated with its chanUnits
read ("deg") and with the units not stated ("Default Units"). Prints a table and writes
bench/results/units_read.json. Run: python3 bench/bench_units_read.py"""

import json
import tempfile
from pathlib import Path

import numpy as np
from matio import save_to_mat
from matio.utils.matclass import MatlabOpaque

import trialformat as tf
from estimation.lab import AnalysisOptions, analyse, estimation_units
from estimation.synthetic import position_trial

K_TRUE = 80.0


def _cell(strings):
    c = np.empty((1, len(strings)), dtype=object)
    for i, s in enumerate(strings):
        c[0, i] = np.array([s])
    return c


def k_estimate(units: str, folder: Path) -> float:
    si = position_trial(K=K_TRUE, B=1.2, I=0.012, duration_s=30, seed=3,
                        record_reference=False, name="z")
    data = np.column_stack([np.degrees(si.theta[:, 0]), si.tau_h[:, 0]])
    obj = MatlabOpaque({"dataSet": data, "chanNames": _cell(["pos1", "tq1"]),
                        "chanUnits": _cell([units, "Nm"]), "domainIncr": np.array([[0.001]]),
                        "domainStart": np.array([[0.0]]), "comment": np.array(["bench"])},
                       "nldat")
    path = folder / f"{units.replace(' ', '_')}.mat"
    save_to_mat(str(path), {"z": obj}, version="v7")
    trials = tf.read_trials(path)
    (unit,) = estimation_units(trials)
    return float(analyse(unit, AnalysisOptions()).fit.K[0, 0])


def main():
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for units in ("deg", "Default Units"):
            k = k_estimate(units, Path(d))
            rows.append({"chanUnits": units, "K_nm_per_rad": k, "K_true": K_TRUE,
                         "ratio": K_TRUE / k})
    print("| chanUnits | K [N m/rad] | true | true/estimate |\n|---|---|---|---|")
    for r in rows:
        print(f"| {r['chanUnits']} | {r['K_nm_per_rad']:.2f} | {K_TRUE:g} | {r['ratio']:.2f} |")
    out = Path(__file__).parent / "results" / "units_read.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
