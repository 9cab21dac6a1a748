"""A truncated .npz in OUT/.diagnosis-cache is recomputed, not a BadZipFile traceback
(issue 22)."""

import numpy as np

import trialformat as tf
from diagnosis.pipeline.resume import ResumeStore


class _Runner:
    def __init__(self):
        self.calls = 0

    def map(self, fn, args, desc, done):
        out = []
        for j, a in enumerate(args):
            self.calls += 1
            out.append(fn(*a))
            done(j, out[-1])
        return out


def _make(n):
    t = np.arange(n) / 100.0
    return tf.Trial(meta={"fs": 100.0, "n_dof": 1}, t=t, theta=np.zeros((n, 1)),
                    tau_h=np.ones((n, 1)), name=f"sim{n}")


def test_truncated_npz_entry_is_recomputed(tmp_path):
    store = ResumeStore(tmp_path, "k")
    runner = _Runner()
    first = store.map(runner, _make, [(50,)], "simulate")
    files = list(store.folder.glob("*.npz"))
    assert len(files) == 1 and runner.calls == 1
    data = files[0].read_bytes()
    files[0].write_bytes(data[: len(data) // 2])  # a disk that filled up, a killed job
    again = ResumeStore(tmp_path, "k")
    second = again.map(runner, _make, [(50,)], "simulate")
    assert runner.calls == 2 and again.n_corrupt == 1
    np.testing.assert_array_equal(second[0].tau_h, first[0].tau_h)
    third = ResumeStore(tmp_path, "k").map(runner, _make, [(50,)], "simulate")
    assert runner.calls == 2 and third[0].name == "sim50"  # the rewritten entry is reused
