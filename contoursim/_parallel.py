"""Independent pieces of one computation on the machine's cores: ``fork_map``.

A diagnosis without a model identifies the servo loops many times over, each
fit independent of the others (an effect held in place, a drive structure)
and each mostly Python around short compiled batches, so one core runs them
one after the other. :func:`fork_map` runs them in forked processes, which
inherit what the caller built (closures over a trace, compiled numba code)
without pickling or compiling it again; only the results travel back.

It runs in this process instead where forking cannot help or is not safe:
one item or one core, inside one of its own workers (no pool within a pool),
in a daemonic process (a dask worker: its cores are the cluster's), and
outside Linux (Windows has no ``fork``; macOS's system libraries are not
safe to use in a forked child, which is why Python starts processes there
by ``spawn``).
"""

import multiprocessing
import os
import signal
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed

__all__ = ["fork_map"]

_WORK = []  # (function, items) of the map being run, inherited by its forked workers
_IN_WORKER = [False]


def _cores():
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _start_worker():
    import numba

    _IN_WORKER[0] = True
    numba.set_num_threads(1)  # a worker a core: the compiled batches step on this worker's core alone
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's, which stops the workers


def _call(i):
    function, items = _WORK[-1]
    return i, function(items[i])


def fork_map(function, items, done=None):
    """``[function(item) for item in items]``, in forked worker processes, one a core, where that can help.

    `function` may be any callable (a closure): the workers inherit it; its
    results are pickled back. An exception it raises is raised here, as in
    the loop. `done`, if given, is called here with the number of items
    finished as each one finishes.
    """
    items = list(items)
    workers = min(len(items), _cores())
    if workers < 2 or _IN_WORKER[0] or multiprocessing.current_process().daemon or not sys.platform.startswith("linux"):
        finished = ((i, function(item)) for i, item in enumerate(items))
        return _gathered(finished, len(items), done)
    _WORK.append((function, items))
    try:  # an executor, not a Pool: a worker that dies (killed, out of memory) raises BrokenProcessPool, not a hang
        with ProcessPoolExecutor(workers, multiprocessing.get_context("fork"), initializer=_start_worker) as pool:
            futures = [pool.submit(_call, i) for i in range(len(items))]
            return _gathered((future.result() for future in as_completed(futures)), len(items), done)
    finally:
        _WORK.pop()


def _gathered(finished, n, done):
    """The results of `finished`, ``(index, result)`` pairs as they finish, in the order of their index; `done`
    called with the count after each."""
    results = [None] * n
    for count, (i, result) in enumerate(finished, start=1):
        results[i] = result
        if done is not None:
            done(count)
    return results
