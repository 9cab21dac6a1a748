"""Local worker processes that stop with their parent, and temporary folders that go with
the process that made them.

Ctrl-C and a killed parent (issue 16):

- :func:`process_pool` is a ``ProcessPoolExecutor`` whose workers ignore SIGINT (the parent
  alone handles Ctrl-C), die with their parent (Linux ``prctl(PR_SET_PDEATHSIG, SIGTERM)``
  through ctypes, and on every platform a thread that polls the parent's pid once a
  second) and remove their temporary folders when terminated. Leaving the ``with`` block by
  an exception (KeyboardInterrupt included) cancels the pending tasks and terminates the
  workers at once (:func:`stop_pool`) instead of waiting for every submitted task.
- :func:`own_temp_dir` makes a temporary folder whose name carries the pid of its owner; it
  is removed when the owner exits (normally, by an exception, or by SIGTERM in a worker),
  and one left by a killed process (SIGKILL) is removed by the next process that makes one
  of the same kind (:func:`remove_stale`).
"""

from __future__ import annotations

import atexit
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from multiprocessing import get_context
from pathlib import Path

#: temporary folders of this process: path -> pid of the process that made it (a forked
#: child inherits the table but must not remove its parent's folders)
_OWNED: dict = {}
#: seconds between two checks of the parent's pid in a worker
PARENT_POLL_S = 1.0
#: seconds a terminated worker gets before it is killed
TERMINATE_GRACE_S = 2.0


# ----------------------------------------------------------------------------- temp folders
def own_temp_dir(kind: str, parent=None) -> Path:
    """A new folder ``{kind}-{pid}-XXXXXX`` in ``parent`` (default: the system temporary
    folder), removed when this process exits; stale ones of dead processes are removed
    first.

    Parameters
    ----------
    kind : str
        Letters, digits, ``_``, ``.`` (the name prefix, e.g. ``armimp-fmu``).
    parent : path, optional
    """
    if not re.fullmatch(r"[A-Za-z0-9_.]+(-[A-Za-z0-9_.]+)*", kind):
        raise ValueError(f"temporary folder kind {kind!r}: letters, digits, '_', '.', '-'")
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


# ----------------------------------------------------------------------------- workers
def _on_sigterm(signum, frame):
    remove_owned()
    os._exit(128 + signum)


def _set_parent_death_signal() -> None:
    """Linux: SIGTERM to this process when its parent dies (no-op elsewhere)."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGTERM), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _watch_parent(parent_pid: int) -> None:
    while True:
        time.sleep(PARENT_POLL_S)
        if os.getppid() != parent_pid:
            remove_owned()
            os._exit(1)


def _worker_start(parent_pid, initializer, initargs) -> None:
    """Pool initializer: Ctrl-C is the parent's; die with the parent; then the user's."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _on_sigterm)
    _set_parent_death_signal()
    if os.getppid() != parent_pid:  # the parent died before prctl
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True,
                     name="watch-parent").start()
    if initializer is not None:
        initializer(*initargs)


def new_pool(workers: int, *, initializer=None, initargs=(), context: str = "spawn",
             max_tasks_per_child: int | None = None):
    """A ``ProcessPoolExecutor`` of ``workers`` processes that die with this one (see the
    module docstring); stop it with :func:`stop_pool` on an error or Ctrl-C.
    ``max_tasks_per_child=1``: every task in a fresh process (a plant that can be
    instantiated only once per process)."""
    extra = {} if max_tasks_per_child is None else {"max_tasks_per_child": max_tasks_per_child}
    return ProcessPoolExecutor(max_workers=workers, mp_context=get_context(context),
                               initializer=_worker_start,
                               initargs=(os.getpid(), initializer, tuple(initargs)), **extra)


def stop_pool(ex) -> None:
    """Cancel the pending tasks and terminate the workers now (SIGTERM, then SIGKILL after
    :data:`TERMINATE_GRACE_S`); returns when every worker is gone."""
    procs = list((getattr(ex, "_processes", None) or {}).values())
    ex.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        try:
            p.terminate()
        except (OSError, ValueError, AttributeError):
            pass
    deadline = time.monotonic() + TERMINATE_GRACE_S
    for p in procs:
        try:
            p.join(max(0.0, deadline - time.monotonic()))
            if p.is_alive():
                p.kill()
                p.join(1.0)
        except (OSError, ValueError, AssertionError, AttributeError):
            pass


@contextmanager
def process_pool(workers: int, *, initializer=None, initargs=(), context: str = "spawn",
                 max_tasks_per_child: int | None = None):
    """``with process_pool(n) as ex:`` -- :func:`new_pool`; an exception (KeyboardInterrupt,
    GeneratorExit of a closed generator) inside the block stops the pool at once."""
    ex = new_pool(workers, initializer=initializer, initargs=initargs, context=context,
                  max_tasks_per_child=max_tasks_per_child)
    try:
        yield ex
    except BaseException:
        stop_pool(ex)
        raise
    ex.shutdown(wait=True)
