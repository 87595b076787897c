"""Running tasks on a dask.distributed cluster: connecting, numba threads per worker, results as they finish.

dask.distributed is an optional extra (``pip install "contoursim[distributed]"``).
A task is a module-level function of plain data (texts, numbers, lists), so
nothing a worker receives depends on the pickled form of contoursim's
objects: the worker rebuilds its models from the data.
"""

import os
import secrets
import signal
import threading
from contextlib import contextmanager

from . import _memory

__all__ = ["CONNECT_TIMEOUT_S", "DISTRIBUTED_MISSING", "connected", "numba_threads", "run_tasks", "task_threads"]

#: The message when dask.distributed is not installed.
DISTRIBUTED_MISSING = 'dask.distributed is not installed: pip install "contoursim[distributed]"'

#: How long a scheduler's address has to answer, as a dask scheduler, before it is said not to [s].
CONNECT_TIMEOUT_S = 10.0
_ADDRESS = "give its address as tcp://host:8786, or local:N for N worker processes on this machine"

_THREADS = [0]  # numba threads of each task in this process (set on a worker by numba_threads; 0: numba's default)


@contextmanager
def connected(scheduler):
    """A ``distributed.Client`` of `scheduler`, closed afterwards along with a cluster made here.

    Parameters
    ----------
    scheduler : str or distributed.Client
        ``"local:N"``: a ``LocalCluster`` of N single-threaded worker
        processes on the loopback interface (127.0.0.1) only, without a
        dashboard, each with ``NUMBA_NUM_THREADS`` = cores // N. Another
        string: a scheduler's address (``tcp://host:8786``). A client: used
        as it is (and left open).

    Raises
    ------
    ValueError
        dask.distributed is not installed (saying how to get it), or a bad ``local:N``.
    """
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ValueError(DISTRIBUTED_MISSING) from None
    if isinstance(scheduler, Client):
        yield scheduler
        return
    text = str(scheduler)
    if not text.startswith("local:"):
        _check_port(text)
        _answers(text)
        try:
            client = Client(text, timeout=f"{CONNECT_TIMEOUT_S}s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise ValueError(f"cannot reach a dask scheduler at {text!r} ({exc}); {_ADDRESS}") from None
        with client:
            yield client
        return
    try:
        n = int(text[len("local:") :])
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"--scheduler local:N needs a whole number of workers, at least 1; got {text!r}")
    _memory.check_workers(n)  # before a process starts: local:1000 would take the machine's memory, then hang
    threads = max(1, (os.cpu_count() or 1) // n)
    with _uninterrupted_children():
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, env={"NUMBA_NUM_THREADS": str(threads)})
    with cluster, Client(cluster) as client:
        yield client


@contextmanager
def _uninterrupted_children():
    """Start processes that ignore SIGINT: a Ctrl-C in a terminal, sent to every process of the command, is the
    command's to handle (it closes the cluster); a worker that took it too ended in a traceback of its own.

    SIGINT is ignored in this process meanwhile (the main thread's disposition, which the children inherit and
    Python keeps); elsewhere than in the main thread it cannot be set, and the children are started as they are.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _check_port(address):
    """Refuse an address whose port is missing or not one (``tcp://host``, ``tcp://host:abc``, ``host:99999``) at
    once: dask said "invalid literal for int()", or waited for a port that cannot be."""
    scheme, _, rest = address.rpartition("://")
    if scheme not in ("", "tcp", "tls", "ws", "wss"):
        return  # dask's other schemes (inproc, ucx) and unknown ones: its own message
    host, colon, port = rest.rpartition(":")
    if not colon or not host:
        raise ValueError(f"--scheduler {address!r} lacks a host and port; {_ADDRESS}")
    if not (port.isascii() and port.isdigit() and 1 <= int(port) <= 65535):
        raise ValueError(f"--scheduler {address!r}: its port {port!r} is not a port number (1 to 65535); {_ADDRESS}")


def _answers(address):
    """Refuse, within :data:`CONNECT_TIMEOUT_S`, an address that does not answer as a dask scheduler does.

    ``Client`` bounds the connection's making, not the greeting that
    follows: a server that takes the connection and does not greet in dask's
    protocol (a dashboard's port, 8787, a web server) would keep it waiting
    forever, or answer with bytes it reads as a length of exabytes.
    """
    import asyncio

    from distributed.comm import connect
    from distributed.security import Security

    async def greet():  # as Client connects: tls:// with the dask configuration's certificates
        comm = await connect(address, timeout=CONNECT_TIMEOUT_S, **Security().get_connection_args("client"))
        await comm.close()

    try:
        asyncio.run(asyncio.wait_for(greet(), CONNECT_TIMEOUT_S))
    except Exception as exc:  # noqa: BLE001 -- refused, unknown, silent, or bytes that are not dask's greeting
        why = (f"no dask scheduler answered in {CONNECT_TIMEOUT_S:g} s" if isinstance(exc, asyncio.TimeoutError)
               else (str(exc).splitlines() or [type(exc).__name__])[0][:200])
        raise ValueError(f"cannot reach a dask scheduler at {address!r} ({why}); {_ADDRESS} (the scheduler's port, "
                         "8786 by default, not its dashboard's, 8787)") from None


def numba_threads(client):
    """Set each worker's numba threads so that its tasks share the host's cores (``client.run``).

    Parameters
    ----------
    client : distributed.Client

    Returns
    -------
    dict
        Worker address -> numba threads of each of its tasks.
    """
    per_host = {}  # dask threads per host: each task's numba threads share the host's cores with the others
    for w in client.scheduler_info()["workers"].values():
        per_host[w["host"]] = per_host.get(w["host"], 0) + w["nthreads"]
    return client.run(_set_threads, per_host)


def _set_threads(per_host, dask_worker=None):
    import numba
    from distributed.comm import get_address_host

    dask_threads = per_host.get(get_address_host(dask_worker.address), 1)
    _THREADS[0] = min(max(1, (os.cpu_count() or 1) // dask_threads), numba.config.NUMBA_NUM_THREADS)
    return _THREADS[0]


def task_threads():
    """In a task: apply the worker's numba thread count (numba's setting is per calling thread)."""
    if _THREADS[0]:
        import numba

        numba.set_num_threads(_THREADS[0])


def run_tasks(client, function, tasks, name):
    """Submit ``function(*args)`` for each args of `tasks`; yield ``(i, result)`` as each finishes.

    A task whose worker is lost runs again on another (the scheduler's
    doing); one that raises is retried twice, then its error is raised here.

    Parameters
    ----------
    client : distributed.Client
    function : callable
        A module-level function of plain data.
    tasks : sequence of tuple
        The arguments of each task.
    name : str
        Prefix of the tasks' keys (shown on the dashboard).
    """
    from distributed import as_completed

    run = secrets.token_hex(4)  # keys unique to this call, on a client that may run others
    futures = [client.submit(function, *args, key=f"{name}-{run}-{i}", retries=2, pure=False)
               for i, args in enumerate(tasks)]
    index = {f.key: i for i, f in enumerate(futures)}
    for future in as_completed(futures):
        yield index[future.key], future.result()
