"""Running a diagnosis's simulations in parallel: local processes or a Dask cluster.

The diagnosis's work is independent tasks once the measured trials are read and the arm
is estimated: the nominal run of each trial, the fit of each catalogue effect (with its
held-out gap), the second effect of each pair, the named model's run of each trial. A
:class:`Runner` ships the read-only state (trials, declared set-up, arm, options) to each
worker once and then maps task functions over arguments:

- ``workers=1``: in this process (no pool);
- ``workers=N``: N local processes (``spawn``: they start clean, with no inherited FMU
  instance), the state sent once by the pool initializer;
- ``scheduler="tcp://HOST:8786"`` (or a ``distributed.Client``): a Dask cluster, the
  state scattered to every worker once (the same option as ``armimp grid``).

Every worker keeps its own cache of simulations (runs are causal, a longer run serves a
shorter unit), so the tasks of one worker reuse each other's runs as the single-process
diagnosis did.
"""

from __future__ import annotations

import os
import pickle
import time
from concurrent.futures import as_completed

from tqdm.auto import tqdm

#: the state of this process when it is a local worker (set by the pool initializer)
_LOCAL_STATE = None
#: per-state worker objects (evaluators and their simulation cache), built on first use
_WORKER_CACHE: dict = {}


def default_workers() -> int:
    """Local processes by default: one per core."""
    return max(1, os.cpu_count() or 1)


def _init_worker(state) -> None:
    global _LOCAL_STATE
    _LOCAL_STATE = state


def _init_worker_pickled(blob: bytes) -> None:
    """Pool initializer: the state, pickled once by the parent, unpickled here (the
    imports it needs run in the worker, side by side with the other workers')."""
    _init_worker(pickle.loads(blob))


def _ready() -> None:
    """A no-op task: makes the pool start a worker."""


def _call(fn, state, args):
    """Run ``fn(state, *args)`` with the worker's state (the local one when None)."""
    return fn(_LOCAL_STATE if state is None else state, *args)


class Runner:
    """Maps task functions ``fn(state, *args)`` over argument tuples.

    Parameters
    ----------
    state : object
        Read-only state every task needs (picklable); sent to each worker once.
    workers : int, optional
        Local processes (default: one per core; 1 runs in this process).
    scheduler : str or distributed.Client, optional
        Dask scheduler address; overrides ``workers``.
    progress : bool
        A tqdm bar per :meth:`map`.
    """

    def __init__(self, state, *, workers: int | None = None, scheduler=None,
                 progress: bool = False):
        self.state, self.progress = state, progress
        self.timings: list = []  # wall time of each map (reported)
        t0 = time.perf_counter()
        self.workers = default_workers() if workers is None else int(workers)
        if self.workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers!r}")
        self._pool = self._client = self._scattered = None
        self._own_client = False
        if scheduler is not None:
            from distributed import Client
            self._client = scheduler if isinstance(scheduler, Client) else Client(scheduler)
            self._own_client = self._client is not scheduler
            self._scattered = self._client.scatter(state, broadcast=True)
        elif self.workers > 1:
            from trialformat.processes import new_pool

            # spawn workers that ignore Ctrl-C and die with this process
            # the state goes as bytes: a spawned worker reads its start-up data while this
            # process waits, and unpickling the state there imports numpy, scipy and the
            # diagnosis (seconds): as bytes, the workers import in their initializer, side
            # by side, while this process goes on
            blob = pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)
            self._pool = new_pool(self.workers, initializer=_init_worker_pickled,
                                  initargs=(blob,))
            # start every worker now (the pool spawns one per submitted task), instead of
            # the second only when a map first has two tasks
            for _ in range(self.workers):
                self._pool.submit(_ready)
        self.timings.append({"phase": "start workers", "tasks": 0,
                             "wall_s": round(time.perf_counter() - t0, 3)})

    @property
    def description(self) -> str:
        if self._client is not None:
            return f"dask {getattr(self._client, 'scheduler_info', lambda: {})().get('address', '')}"
        return f"{self.workers} local process{'es' if self.workers > 1 else ''}"

    def map(self, fn, arg_tuples, *, desc: str = "", done=None) -> list:
        """``[fn(state, *args) for args in arg_tuples]``, run on the workers, in order.

        ``done(i, result)``, when given, is called as each task finishes (e.g. to store
        it for a resumed run)."""
        arg_tuples = list(arg_tuples)
        t0 = time.perf_counter()
        bar = tqdm(total=len(arg_tuples), desc=desc, disable=None if self.progress else True, unit="task")
        results = [None] * len(arg_tuples)
        try:
            if self._client is not None:
                from distributed import as_completed as dask_completed
                futures = {self._client.submit(_call, fn, self._scattered, args, pure=False): i
                           for i, args in enumerate(arg_tuples)}
                for fut in dask_completed(list(futures)):
                    results[futures[fut]] = fut.result()
                    if done is not None:
                        done(futures[fut], results[futures[fut]])
                    bar.update()
            elif self._pool is not None:
                futures = {self._pool.submit(_call, fn, None, args): i
                           for i, args in enumerate(arg_tuples)}
                for fut in as_completed(futures):
                    results[futures[fut]] = fut.result()
                    if done is not None:
                        done(futures[fut], results[futures[fut]])
                    bar.update()
            else:
                for i, args in enumerate(arg_tuples):
                    results[i] = fn(self.state, *args)
                    if done is not None:
                        done(i, results[i])
                    bar.update()
        finally:
            bar.close()
        self.timings.append({"phase": desc or getattr(fn, "__name__", "map"),
                             "tasks": len(arg_tuples),
                             "wall_s": round(time.perf_counter() - t0, 3)})
        return results

    def close(self, *, now: bool = False) -> None:
        """Shut the workers down; ``now``: cancel pending tasks and terminate running ones
        (an error or Ctrl-C)."""
        if self._pool is not None:
            if now:
                from trialformat.processes import stop_pool

                stop_pool(self._pool)
            else:
                self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self._client is not None and self._own_client:
            self._client.close()
        self._client = None

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(now=exc_type is not None)


def worker_cache(state, key, build):
    """An object built once per worker and state (``build()``), e.g. the evaluators with
    their simulation cache."""
    token = (getattr(state, "token", id(state)), key)
    if token not in _WORKER_CACHE:
        if len(_WORKER_CACHE) > 16:  # states of finished diagnoses
            _WORKER_CACHE.clear()
        _WORKER_CACHE[token] = build()
    return _WORKER_CACHE[token]
