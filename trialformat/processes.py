"""Local worker processes that stop with their parent, and temporary folders that go with
the process that made them.

Ctrl-C and a killed parent (issue 16):

- :func:`process_pool` is a ``ProcessPoolExecutor`` whose workers ignore SIGINT (the parent
  alone handles Ctrl-C), die with their parent (Linux ``prctl(PR_SET_PDEATHSIG, SIGTERM)``
  through ctypes, and on every platform a thread that polls the parent's pid once a
  second) and remove their temporary folders when terminated. Leaving the ``with`` block by
  an exception (KeyboardInterrupt included) cancels the pending tasks and terminates the
  workers at once (:func:`stop_pool`) instead of waiting for every submitted task.
- temporary folders (:mod:`trialformat.tempdirs`, re-exported here) carry the pid of their
  owner; a worker terminated by SIGTERM removes its own before it exits.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from multiprocessing import get_context

from trialformat.tempdirs import (own_temp_dir, pid_alive, release_temp_dir,  # noqa: F401
                                  remove_owned, remove_stale)

#: seconds between two checks of the parent's pid in a worker
PARENT_POLL_S = 1.0
#: seconds a terminated worker gets before it is killed
TERMINATE_GRACE_S = 2.0


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
    # the executor's manager thread marks the futures of the killed tasks broken: wait for
    # it, so that on return no future is left running
    manager = getattr(ex, "_executor_manager_thread", None)
    if manager is not None and manager.is_alive():
        manager.join(TERMINATE_GRACE_S)


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
