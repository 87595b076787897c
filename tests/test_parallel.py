"""Independent pieces of a computation on the machine's cores (contoursim._parallel.fork_map).

The truth is the loop it stands for: ``[function(item) for item in items]``,
result for result and exception for exception, whatever the number of cores.
"""

import os
import sys
from concurrent.futures.process import BrokenProcessPool

import pytest

from contoursim import _parallel
from contoursim._parallel import fork_map

FORKS = sys.platform.startswith("linux") and _parallel._cores() >= 2  # where the map runs in other processes


def test_a_closure_s_results_come_back_in_order_from_other_processes():
    offset = 1000  # a closure over the caller's state, which a pickled task could not carry
    results = fork_map(lambda i: (i + offset, os.getpid()), range(7))
    assert [r for r, _ in results] == list(range(1000, 1007))
    assert any(pid != os.getpid() for _, pid in results) == FORKS


def test_one_core_or_one_item_runs_here(monkeypatch):
    assert fork_map(lambda _: os.getpid(), [0]) == [os.getpid()]
    monkeypatch.setattr(_parallel, "_cores", lambda: 1)
    assert fork_map(lambda _: os.getpid(), range(3)) == [os.getpid()] * 3


def test_a_map_inside_a_worker_runs_in_that_worker():
    def inner(_):
        return os.getpid(), fork_map(lambda _: os.getpid(), range(3))

    for pid, pids in fork_map(inner, range(2)):
        assert pids == [pid] * 3


def test_an_exception_is_raised_here_as_the_loop_would_raise_it():
    def fails(i):
        if i == 3:
            raise FloatingPointError(f"item {i} diverged")
        return i

    with pytest.raises(FloatingPointError, match="item 3 diverged"):
        fork_map(fails, range(5))


@pytest.mark.parametrize("cores", [1, 2])
def test_each_item_finished_is_counted_as_it_finishes(monkeypatch, cores):
    monkeypatch.setattr(_parallel, "_cores", lambda: cores)
    counts = []
    assert fork_map(lambda i: i * i, range(5), done=counts.append) == [0, 1, 4, 9, 16]
    assert counts == [1, 2, 3, 4, 5]


@pytest.mark.skipif(not FORKS, reason="one core, or not Linux: the map runs in this process")
def test_a_worker_that_dies_is_an_error_here_not_a_hang():
    def dies(i):
        if i == 1:
            os._exit(9)  # as the kernel's out-of-memory killer ends a process
        return i

    with pytest.raises(BrokenProcessPool):
        fork_map(dies, range(4))
