"""The parallel runner: the same results in this process, in local processes, on Dask."""

import pytest

from diagnosis.parallel import Runner, worker_cache


class State:
    token = "test-state"
    offset = 10


def add(state, x, y):
    # built once per worker and state, then reused
    base = worker_cache(state, "base", lambda: state.offset)
    return base + x * y


ARGS = [(i, i + 1) for i in range(7)]
EXPECTED = [10 + i * (i + 1) for i in range(7)]


@pytest.mark.parametrize("workers", [1, 2])
def test_local_runner_maps_in_order(workers):
    with Runner(State(), workers=workers) as runner:
        assert runner.map(add, ARGS) == EXPECTED


def test_dask_runner_maps_in_order():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, processes=False, dashboard_address=None) as c, \
            distributed.Client(c) as client:
        with Runner(State(), scheduler=client) as runner:
            assert runner.map(add, ARGS) == EXPECTED


def test_workers_must_be_positive():
    with pytest.raises(ValueError, match="workers"):
        Runner(State(), workers=0)
