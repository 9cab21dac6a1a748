"""Ctrl-C and a killed parent (issue 16): commands stop at once, record what finished,
print one line, exit 130; no worker outlives its parent; no temporary folder stays.

Each case runs ``python -m orchestrator`` in a new session with its own temporary folder
(TMPDIR), sends the signal a terminal would (SIGINT to the process group) or SIGKILL to
the parent alone, and then looks at every process the command had started.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from trialformat import processes as workers

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")


def _descendants(root: int) -> set:
    """Pids of every living process below ``root`` (from /proc)."""
    children: dict = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(entry))
    out, todo = set(), [root]
    while todo:
        for kid in children.get(todo.pop(), []):
            out.add(kid)
            todo.append(kid)
    return out


def _alive(pids) -> set:
    alive = set()
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive.add(pid)
    return alive


def _wait_gone(pids, timeout):
    deadline = time.monotonic() + timeout
    while _alive(pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    return _alive(pids)


def _start(args, tmp_path):
    systmp = tmp_path / "systmp"
    systmp.mkdir(exist_ok=True)
    env = {**os.environ, "TMPDIR": str(systmp), "PYTHONPATH": str(ROOT)}
    # SIGINT back to its default: a shell starting the tests in the background (`... &`
    # without job control) makes its children ignore it, and Python then never raises
    # KeyboardInterrupt (the command under test would run to its end)
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", *args], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    return proc, systmp


def _wait_for(predicate, proc, timeout, what):
    deadline = time.monotonic() + timeout
    while not predicate():
        if proc.poll() is not None:
            raise AssertionError(f"ended before {what}: rc {proc.returncode}, "
                                 f"{proc.communicate()}")
        if time.monotonic() > deadline:
            proc.kill()
            raise AssertionError(f"no {what} after {timeout} s")
        time.sleep(0.1)


GRID = ["--workers", "2", "--duration", "3", "--friction", "0", "3", "--resolution", "0", "1",
        "2", "--perturbation", "3", "--dofs", "1", "--no-progress"]


def _interrupted_grid(tmp_path):
    """A grid interrupted by Ctrl-C after its first trial, checked: (out, manifest)."""
    out = tmp_path / "grid"
    proc, systmp = _start(["grid", str(out), *GRID], tmp_path)
    _wait_for(lambda: any(out.glob("fric*.json")), proc, 300, "finished trial")
    before = _descendants(proc.pid)
    assert len(before) >= 2, before  # two workers (and the resource tracker)
    sent = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal sends
    stdout, stderr = proc.communicate(timeout=60)
    stopped_s = time.monotonic() - sent
    assert proc.returncode == 130, (stdout, stderr)
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("armimp grid: interrupted"), stderr
    assert "Traceback" not in stderr + stdout
    assert _wait_gone(before, 5.0) == set(), "workers outlived the parent"
    assert stopped_s < 15.0, stopped_s  # about 0.4 s measured; generous for a loaded machine
    manifest = json.loads((out / "grid.json").read_text())
    statuses = {t["name"]: t["status"] for t in manifest["trials"]}
    assert manifest["n_trials"] == 6 and manifest["n_done"] >= 1
    assert manifest["n_done"] + manifest["n_interrupted"] == 6, statuses
    for name, status in statuses.items():  # done means written; interrupted means absent
        assert (out / f"{name}.json").exists() == (status == "done"), (name, status)
    assert not list(out.glob(".*.tmp")), list(out.iterdir())
    assert not list(systmp.glob("armimp-fmu-*")), list(systmp.iterdir())
    return out, manifest


def test_ctrl_c_on_a_grid_stops_at_once_with_a_manifest_and_no_live_worker(tmp_path):
    _interrupted_grid(tmp_path)


@pytest.mark.slow
def test_an_interrupted_grid_resumes(tmp_path):
    """The next run skips the finished trials and simulates the rest."""
    out, manifest = _interrupted_grid(tmp_path)
    proc, _ = _start(["grid", str(out), *GRID], tmp_path)
    proc.communicate(timeout=600)
    assert proc.returncode == 0
    again = json.loads((out / "grid.json").read_text())
    assert again["n_skipped"] == manifest["n_done"] and again["n_failed"] == 0
    assert again["n_done"] == 6 - manifest["n_done"]


def test_workers_die_when_the_grid_is_killed(tmp_path):
    """SIGKILL of the parent alone: its workers follow it (PR_SET_PDEATHSIG, and a thread
    polling the parent's pid) and remove their extracted FMUs."""
    out = tmp_path / "grid"
    proc, systmp = _start(["grid", str(out), *GRID], tmp_path)
    _wait_for(lambda: list(systmp.glob("armimp-fmu-*")), proc, 300, "worker with a plant")
    kids = _descendants(proc.pid)
    assert kids
    proc.kill()
    proc.communicate(timeout=30)
    assert _wait_gone(kids, 10.0) == set(), "workers outlived their killed parent"
    assert not list(systmp.glob("armimp-fmu-*")), list(systmp.iterdir())


def test_ctrl_c_on_simulate_exits_130_in_one_line_and_leaves_no_temporary_folder(tmp_path):
    out = tmp_path / "long"
    proc, systmp = _start(["simulate", "--out", str(out), "--duration", "600"], tmp_path)
    _wait_for(lambda: list(systmp.glob("armimp-fmu-*")), proc, 300, "extracted plant")
    time.sleep(0.5)
    os.killpg(proc.pid, signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, (stdout, stderr)
    assert stderr.strip() == "armimp simulate: interrupted", stderr
    assert not list(systmp.glob("armimp-fmu-*")) and not list(tmp_path.glob("long*"))


def test_simulate_leaves_no_temporary_folder_on_success_or_error(tmp_path):
    proc, systmp = _start(["simulate", "--out", str(tmp_path / "ok"), "--duration", "0.2"],
                          tmp_path)
    proc.communicate(timeout=300)
    assert proc.returncode == 0 and (tmp_path / "ok.json").exists()
    proc, _ = _start(["simulate", "--out", str(tmp_path / "bad"), "--duration", "0.2",
                      "--plant-parameter", "no_such_parameter=1"], tmp_path)
    _, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 1 and "has no parameter no_such_parameter" in stderr, stderr
    assert list(systmp.iterdir()) == [], list(systmp.iterdir())


def _sleep(seconds):
    time.sleep(seconds)
    return os.getpid()


def test_stopping_a_pool_cancels_pending_tasks_and_terminates_running_ones():
    """KeyboardInterrupt inside ``process_pool``: 10 s tasks end within a few seconds."""
    with pytest.raises(KeyboardInterrupt):
        with workers.process_pool(2) as ex:
            pids = {ex.submit(_sleep, 0.0).result()}  # the workers are up
            futures = [ex.submit(_sleep, 10.0) for _ in range(6)]
            procs = [p.pid for p in ex._processes.values()]
            time.sleep(0.5)
            start = time.monotonic()
            raise KeyboardInterrupt
    assert time.monotonic() - start < 5.0
    assert [f for f in futures if not (f.cancelled() or f.done())] == []
    assert _alive(set(procs) | pids) == set()


def test_stale_temporary_folders_of_dead_processes_are_removed(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f"armimp-fmu-{dead.pid}-x1"
    stale.mkdir()
    (stale / "file").write_bytes(b"1")
    living = tmp_path / f"armimp-fmu-{os.getpid()}-x2"
    living.mkdir()
    other = tmp_path / f"armimp-fmux-{dead.pid}-x3"  # another kind: not touched
    other.mkdir()
    made = workers.own_temp_dir("armimp-fmu", tmp_path)
    assert not stale.exists() and living.exists() and other.exists() and made.exists()
    workers.release_temp_dir(made)
    assert not made.exists()


def test_a_trial_written_as_the_grid_stopped_is_done_and_a_half_written_one_is_removed(tmp_path):
    """Workers ignore SIGINT, so one may finish its trial between Ctrl-C and its end: the
    manifest must then say done (both files there), and interrupted must mean absent."""
    from orchestrator.grid import _unreported

    task = {"name": "fric0_res0_pert3_dof1", "fmu_path": "x.fmu", "seed": 1}
    (tmp_path / f"{task['name']}.csv").write_text("t\n0\n")
    (tmp_path / f"{task['name']}.json").write_text("{}")
    done = _unreported(tmp_path, task)
    assert done["status"] == "done" and "fmu_path" not in done
    half = {**task, "name": "fric3_res0_pert3_dof1"}
    (tmp_path / f"{half['name']}.csv").write_text("t\n0\n")  # killed before its JSON
    (tmp_path / f".{half['name']}.json.123.tmp").write_text("{")
    assert _unreported(tmp_path, half)["status"] == "interrupted"
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{task['name']}.csv",
                                                          f"{task['name']}.json"]
