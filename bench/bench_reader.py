"""Timing of the trial readers on one 50 s trial (1 kHz, 2 joints, 50 001 rows x 9 columns).

Rows, side by side in one run (best and median of REPEATS):
- the reader (``trialformat.read_trial``: pyarrow parse + metadata + all checks), on the
  project's own 17-digit CSV and on other writers' files (pandas %.7g, BOM+CRLF, float32);
- the reader before issue 11 (``np.loadtxt`` parse of the same file, then the same split),
  reproduced here as it was so the ratio is measured, not remembered;
- a file declared at 1024 Hz with ``t`` printed to 1 ms (each value judged at its own
  printed digit: the slow path of the time check);
- the ``.mat`` reader, v5 (scipy.io) and v7.3 (HDF5, h5py).
Prints a table and writes bench/results/reader.json. Target: at most 30 ms for 50 s.
"""

import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

import trialformat as tf

from benchio import write_results

REPEATS = 15


def best_of(fn, repeats=REPEATS):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), float(np.median(times))


def previous_reader(csv_path):
    """The CSV parse of trialformat before issue 11 (np.loadtxt), with the JSON read."""
    json.loads(Path(csv_path).with_suffix(".json").read_text())
    with open(csv_path, encoding="utf-8") as fh:
        header = [h.strip() for h in fh.readline().strip().split(",")]
        table = np.loadtxt(fh, delimiter=",", dtype=float, ndmin=2)
    return {h: table[:, i].copy() for i, h in enumerate(header)}


def make_trial(seconds=50.0, fs=1000.0, seed=0):
    rng = np.random.default_rng(seed)
    n = int(seconds * fs) + 1
    meta = tf.default_metadata(2)
    return tf.Trial(meta=meta, t=np.arange(n) / fs,
                    **{s: rng.standard_normal((n, 2)) for s in tf.SIGNALS})


def main(argv=None):
    trial = make_trial()
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        plain = tf.write_trial(tmp / "plain", trial)
        frame = pd.read_csv(plain)
        frame.to_csv(tmp / "p7.csv", index=False, float_format="%.7g")
        frame.to_csv(tmp / "bom.csv", index=False, encoding="utf-8-sig", lineterminator="\r\n")
        frame.astype(np.float32).to_csv(tmp / "f32.csv", index=False)
        for stem in ("p7", "bom", "f32"):
            (tmp / f"{stem}.json").write_text(plain.with_suffix(".json").read_text())
        # the same rows declared at 1024 Hz with t printed to 1 ms: every value is judged
        # at its own printed digit (the reader's slow path)
        frame.assign(t=[f"{v:.3f}" for v in np.arange(len(frame)) / 1024.0]).to_csv(
            tmp / "t1ms.csv", index=False, float_format="%.7g")
        (tmp / "t1ms.json").write_text(json.dumps({**trial.meta, "fs": 1024.0}))
        mat5 = tf.write_trial_mat(tmp / "m5.mat", trial)
        import hdf5storage
        data = {"t": trial.t[:, None], **{s: trial.signal(s) for s in tf.SIGNALS},
                "meta": json.dumps(trial.meta)}
        hdf5storage.savemat(str(tmp / "m73.mat"), data, format="7.3",
                            store_python_metadata=False, matlab_compatible=True)
        rows["read_trial, project CSV (round-trip digits)"] = best_of(lambda: tf.read_trial(plain))
        rows["previous reader (np.loadtxt), same file"] = best_of(
            lambda: previous_reader(plain), 5)
        rows["read_trial, pandas %.7g"] = best_of(lambda: tf.read_trial(tmp / "p7.csv"))
        rows["read_trial, BOM + CRLF"] = best_of(lambda: tf.read_trial(tmp / "bom.csv"))
        rows["read_trial, float32 printed"] = best_of(lambda: tf.read_trial(tmp / "f32.csv"))
        rows["read_trial, 1024 Hz, t to 1 ms, %.7g"] = best_of(
            lambda: tf.read_trial(tmp / "t1ms.csv"))
        rows["read_trial, .mat v5 (compressed)"] = best_of(lambda: tf.read_trial(mat5))
        rows["read_trial, .mat v7.3 (HDF5)"] = best_of(lambda: tf.read_trial(tmp / "m73.mat"))
    ratio = rows["previous reader (np.loadtxt), same file"][1] / \
        rows["read_trial, project CSV (round-trip digits)"][1]
    print(f"one 50 s trial, 1 kHz, 2 joints ({trial.n_samples} rows x 9 columns)")
    print(f"{'reader':45s} {'best ms':>8s} {'median ms':>10s}")
    for name, (best, med) in rows.items():
        print(f"{name:45s} {best * 1e3:8.1f} {med * 1e3:10.1f}")
    print(f"previous / new (medians): {ratio:.2f}x; target: new <= 30 ms")
    write_results("reader", {
        "what": "read one 50 s trial (50001 x 9)", "machine": "project 2-core machine, shared (loaded)",
        "python": platform.python_version(),
        "rows_s": {k: {"best": v[0], "median": v[1]} for k, v in rows.items()},
        "previous_over_new_median": ratio}, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
