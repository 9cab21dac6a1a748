"""A report's hidden temporary folder (issue 16): named with its process's pid, removed on
error, and one left by a killed run (SIGKILL) removed by the next run."""

import subprocess
import sys

from estimation.labreport import write_lab_report


def _dead_pid():
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_stale_report_folder_of_a_killed_run_is_removed_by_the_next(tmp_path):
    stale = tmp_path / f".lab.tmp-{_dead_pid()}-k1ll3d"
    (stale / "partial").mkdir(parents=True)
    try:
        write_lab_report([], tmp_path / "lab")
    except Exception:  # noqa: BLE001 (an empty report may be refused; the folders are the point)
        pass
    assert not stale.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".lab.tmp")] == []
