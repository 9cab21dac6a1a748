"""A session scales (issue 22 item 3): the time-domain fit's per-trial offsets projected out
(Frisch-Waugh-Lovell) give the dense solve's answer; SIGTERM stops `diagnose` as Ctrl-C
does (one "interrupted" line, exit 143); a progress line per stage under --quiet.
The timings: bench/bench_session.py."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from diagnosis import limb as lm
from diagnosis import limbfit as lf

ROOT = Path(__file__).resolve().parents[2]
FS = 1000.0


def _records(n_dof, n_rec, offsets):
    """``n_rec`` 8 s records of one limb, each with its own torque offset and trend."""
    rng = np.random.default_rng(5)
    limb = lm.LimbModel(np.eye(n_dof) * 60.0 + 5.0, np.eye(n_dof) * 0.8 + 0.05,
                        np.eye(n_dof) * 0.02)
    recs = []
    for i in range(n_rec):
        x = rng.standard_normal((8000 + 2000, n_dof))
        from scipy import signal as sg
        theta = 0.01 * sg.sosfilt(sg.butter(4, 15.0, fs=FS, output="sos"), x, axis=0)[2000:]
        t = np.arange(theta.shape[0]) / FS
        tau = lm.limb_torque(theta, FS, limb, {})
        tau = tau + offsets[i][0] + offsets[i][1] * (t - t[-1] / 2)[:, None]
        tau = tau + 0.002 * rng.standard_normal(tau.shape)
        recs.append(lf.PositionRecord(theta, tau, FS, None, f"r{i}"))
    return recs, limb


@pytest.mark.parametrize("n_dof", [1, 2])
def test_projected_offsets_give_the_dense_solution_and_the_known_offsets(n_dof):
    offsets = [(0.5, 0.02), (-1.0, -0.05), (2.0, 0.0)]
    recs, limb = _records(n_dof, 3, offsets)
    preps = lf.prepare(recs)
    cols = [pr.base for pr in preps]
    rng = np.random.default_rng(1)
    masks = [pr.cal & (rng.uniform(size=pr.cal.shape) > 0.2) for pr in preps]
    for mk in (None, masks):
        fast = lf._solve(preps, cols, mk)
        dense = lf._solve_dense(preps, cols, mk)
        np.testing.assert_allclose(fast.coef, dense.coef, rtol=1e-8, atol=1e-10)
        for a, b in zip(fast.offsets, dense.offsets):
            np.testing.assert_allclose(a, b, rtol=1e-7, atol=1e-9)
        for a, b in zip(fast.residual, dense.residual):
            np.testing.assert_allclose(a, b, atol=1e-9)
        assert fast.cal_energy == pytest.approx(dense.cal_energy, rel=1e-8)
    # the known answer: the limb's K, B, I and every record's offset and trend
    got = lf._limb_from(fast.coef, n_dof)
    np.testing.assert_allclose(got.K, limb.K, rtol=1e-2, atol=0.1)
    np.testing.assert_allclose(got.I, limb.I, rtol=5e-2, atol=1e-3)
    for o, (c, tr) in zip(fast.offsets, offsets):
        np.testing.assert_allclose(o[:n_dof], c, atol=5e-3)
        np.testing.assert_allclose(o[n_dof:], tr, atol=5e-3)


def _session(folder, n, seconds=9.0):
    """``n`` labsim recordings of one drawn ankle (a stretch reflex), ``seconds`` each."""
    import copy

    import labsim
    base = labsim.draw("nominal+reflex", np.random.default_rng(22), duration_s=seconds)
    for i in range(n):
        spec = copy.deepcopy(base)
        spec.seed = 1000 + i
        labsim.write(labsim.simulate(spec), folder, f"trial{i:03d}")
        meta_path = folder / f"trial{i:03d}.json"  # one limb: one labelled set
        meta_path.write_text(json.dumps({**json.loads(meta_path.read_text()),
                                         "condition": "ankle"}))
    return folder


def _diagnose_cli(folder, out, *extra):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "orchestrator", "diagnose", str(folder),
                             "--out", str(out), "--quiet", *extra], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return _session(tmp_path_factory.mktemp("session") / "data", 2)


def _children(pid):
    """Pids of the living children of ``pid`` (from /proc)."""
    out = set()
    for entry in os.listdir("/proc"):
        try:
            stat = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(stat[1]) == pid and stat[0] != "Z":
            out.add(int(entry))
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_sigterm_stops_diagnose_like_ctrl_c_exit_143_and_keeps_what_finished(session,
                                                                              tmp_path):
    out = tmp_path / "rep"
    proc = _diagnose_cli(session, out, "--workers", "2")
    deadline = time.monotonic() + 300
    while not list(out.glob(".diagnosis-cache/*/*")):  # a first task finished
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no task finished in 300 s"
        time.sleep(0.2)
    kids = _children(proc.pid)
    proc.send_signal(signal.SIGTERM)  # to the parent alone, as a job scheduler does
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 143, (stdout, stderr)
    assert stderr.strip().splitlines()[-1] == "armimp diagnose: interrupted", stderr
    assert "leaked" not in stderr and "Traceback" not in stderr, stderr
    # a line per stage begun, under --quiet
    assert "diagnose: [ankle] stage 1/10 read (" in stderr and "stage 4/10 nominal (" in stderr
    time.sleep(1.0)
    assert not {k for k in kids if Path(f"/proc/{k}").exists()
                and "Z" not in Path(f"/proc/{k}/stat").read_text().rsplit(")", 1)[1][:3]}
    assert not (out / "report.json").exists()
    assert list(out.glob(".diagnosis-cache/*/*")), "the finished tasks are kept for resume"


@pytest.mark.slow
def test_every_stage_prints_a_line_under_quiet(session, tmp_path):
    data = session
    proc = _diagnose_cli(data, tmp_path / "rep", "--workers", "1",
                         "--effects", "torque_sensor_lag")
    stdout, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 0, (stdout, stderr)
    from diagnosis.pipeline import STAGES
    for i, stage in enumerate(STAGES):
        name = stage.__name__.rsplit(".", 1)[-1]
        assert f"diagnose: [ankle] stage {i + 1}/{len(STAGES)} {name} (" in stderr, stderr
    assert "diagnose: [ankle] done (" in stderr and "verdict:" in stdout
