"""Temporary folders that go with the process that made them (issue 16).

:func:`own_temp_dir` makes a folder whose name carries the pid of its owner; it is removed
when the owner exits (normally or by an exception; :mod:`trialformat.processes` makes a
worker terminated by SIGTERM remove its own), and one left by a killed process (SIGKILL)
is removed by the next process that makes one of the same kind (:func:`remove_stale`).
A pid reused by a living process keeps its folder (kept, never lost).
"""

from __future__ import annotations

import atexit
import os
import re
import shutil
import tempfile
from pathlib import Path

#: temporary folders of this process: path -> pid of the process that made it (a forked
#: child inherits the table but must not remove its parent's folders)
_OWNED: dict = {}


def own_temp_dir(kind: str, parent=None) -> Path:
    """A new folder ``{kind}-{pid}-XXXXXX`` in ``parent`` (default: the system temporary
    folder), removed when this process exits; stale ones of dead processes are removed
    first.

    Parameters
    ----------
    kind : str
        The name prefix, e.g. ``armimp-fmu`` (no path separator).
    parent : path, optional
    """
    if not kind or re.search(r"[/\\\x00]", kind):
        raise ValueError(f"temporary folder kind {kind!r}: a name without path separators")
    parent = Path(parent if parent is not None else tempfile.gettempdir())
    remove_stale(kind, parent)
    path = Path(tempfile.mkdtemp(prefix=f"{kind}-{os.getpid()}-", dir=parent))
    _OWNED[str(path)] = os.getpid()
    return path


def release_temp_dir(path) -> None:
    """Remove a folder made by :func:`own_temp_dir` (nothing if already gone)."""
    path = str(path)
    if _OWNED.get(path) == os.getpid():
        _OWNED.pop(path, None)
    shutil.rmtree(path, ignore_errors=True)


def disown_temp_dir(path) -> None:
    """Forget a folder made by :func:`own_temp_dir` that was moved into place (a report
    renamed to its final name): it is no longer removed at exit."""
    _OWNED.pop(str(path), None)


def remove_owned() -> None:
    """Remove every temporary folder this process made and still holds."""
    me = os.getpid()
    for path, pid in list(_OWNED.items()):
        if pid == me:
            shutil.rmtree(path, ignore_errors=True)
            _OWNED.pop(path, None)


atexit.register(remove_owned)


def pid_alive(pid: int) -> bool:
    """True when a process ``pid`` exists (a reused pid counts as alive: kept, not lost)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return True
    return True


def remove_stale(kind: str, parent) -> list:
    """Remove the folders ``{kind}-{pid}-*`` in ``parent`` whose process is gone; returns
    their paths. Folders of living processes (other runs) are kept."""
    removed = []
    pattern = re.compile(re.escape(kind) + r"-(\d+)-[^/\\]*$")
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return removed
    for entry in entries:
        m = pattern.match(entry.name)
        if not m or not entry.is_dir(follow_symlinks=False):
            continue
        if not pid_alive(int(m.group(1))):
            shutil.rmtree(entry.path, ignore_errors=True)
            removed.append(entry.path)
    return removed
