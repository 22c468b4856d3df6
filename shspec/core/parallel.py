"""One way to run independent jobs: a :class:`concurrent.futures.Executor` that is serial, a process pool or Dask.

:func:`make_executor` is what every parallel loop of shspec uses (many meshes in ``shspec mesh-spectrum``; it is
and the starts of ``shspec fit``), so that a caller writes the loop once against the standard Executor interface
(``submit``, ``map``, ``shutdown``, ``with``) and the user picks where it runs:

* neither ``workers`` nor ``scheduler``: :class:`SerialExecutor`, every job run at ``submit`` in this process
  (debuggers and profilers see everything; exceptions surface from ``Future.result()`` as usual);
* ``workers=N``: a :class:`WorkerPool` (a :class:`~concurrent.futures.ProcessPoolExecutor`) of N processes,
  started with ``spawn`` (no fork of a process that already runs threads) and with one BLAS/OpenMP/numba thread
  each, so that N workers use N cores rather than N × cores threads fighting over them;
* ``scheduler=ADDRESS``: the executor of a Dask distributed cluster (``distributed.Client(ADDRESS).get_executor()``;
  ADDRESS like ``tcp://host:8786``, or a ``LocalCluster``'s ``scheduler_address``).  The workers' thread counts are
  the cluster's business (``dask worker --nthreads 1`` and OMP_NUM_THREADS=1 in their environment); shutting the
  executor down closes the client, not the cluster.  An address that cannot be one (an unknown scheme, a port out of
  range) and a port where nothing listens fail at once, a server that does not answer as a Dask scheduler after
  :data:`CONNECT_TIMEOUT` seconds, all with a :class:`~shspec.errors.SchedulerError`.

Jobs must be picklable: module-level functions with picklable arguments and results.  :func:`stop_executor` shuts an
executor down without waiting for the jobs still running (a fit that stopped at a success no longer needs
them); :func:`usable_cores` is the default size of a local pool.

Interrupts: Ctrl-C reaches every process of the terminal's group, so the workers of a :class:`WorkerPool` ignore it
and leave the decision to the pool's owner, which may end the running jobs with :meth:`WorkerPool.interrupt_workers`
(SIGTERM to each worker).  A job that runs inside :func:`interruptible` then gets a ``KeyboardInterrupt`` and may
return what it has (a fit's start returns its best state), once per job; an idle worker ignores the signal, so that
its death cannot break the pool under the jobs still returning.  :func:`stop_executor` kills the workers.  A worker
whose owner died without stopping it (killed by SIGKILL, or by a SIGTERM it did not handle) ends itself within
:data:`OWNER_POLL` seconds.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import socket
import threading
import time
from concurrent.futures import Executor, Future, ProcessPoolExecutor

from .checks import check_int
from ..errors import InvalidArgumentError, SchedulerError

__all__ = ["SerialExecutor", "DaskExecutor", "WorkerPool", "make_executor", "stop_executor", "interruptible",
           "usable_cores", "THREAD_VARIABLES", "CONNECT_TIMEOUT", "OWNER_POLL"]

#: Environment variables that cap the thread pools of BLAS/OpenMP libraries loaded after they are set.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")

#: Seconds to wait for a Dask scheduler to answer before giving up (distributed's own default is 30).
CONNECT_TIMEOUT = 10.0

# The limiter of a worker process stays alive as long as the process.
_LIMITS = []


def _one_thread_per_worker() -> None:
    """Process-pool initializer: one thread for every BLAS/OpenMP pool, numba included."""
    for name in THREAD_VARIABLES:
        # not numba's: it has run already (unpickling this initializer imports shspec), and once its threads are up
        # every compilation re-reads the environment and raises if NUMBA_NUM_THREADS changed, so a worker with a
        # cold numba cache failed at its first kernel; set_num_threads below is what numba takes at run time
        if name != "NUMBA_NUM_THREADS":
            os.environ[name] = "1"
    import numba
    import numpy  # noqa: F401  (load the BLAS that threadpoolctl then limits)
    import scipy.linalg  # noqa: F401  (SciPy ships its own OpenBLAS)
    from threadpoolctl import threadpool_limits

    _LIMITS.append(threadpool_limits(limits=1))
    numba.set_num_threads(1)


#: Whether this worker process runs a job inside :func:`interruptible` (module notes).
_INTERRUPTIBLE = [False]


def _interrupt_job(signum, frame) -> None:
    """A pool worker's SIGTERM handler: ends an interruptible job by KeyboardInterrupt, once; otherwise nothing."""
    if _INTERRUPTIBLE[0]:
        _INTERRUPTIBLE[0] = False  # once per job: a second signal (the group's and the owner's) must not cut its reply
        raise KeyboardInterrupt


#: Seconds between two looks of a :class:`WorkerPool`'s worker at whether its owner still lives.
OWNER_POLL = 1.0


def _watch_owner(owner: int) -> None:
    """End this worker once the process that started it is gone (it was killed, SIGKILL or an unhandled SIGTERM,
    without stopping its pool): nobody waits for its job any more, which could otherwise run on for many minutes
    (a fit's start) on a core of the machine."""
    while True:
        time.sleep(OWNER_POLL)
        if os.getppid() != owner:
            os._exit(1)


def _start_worker(owner: int) -> None:
    """Process-pool initializer of :class:`WorkerPool`: an end with its ``owner`` process (:func:`_watch_owner`;
    given, not read here: the owner may die before a worker has started), one thread per BLAS/numba pool, and the
    interrupts of the module notes."""
    threading.Thread(target=_watch_owner, args=(owner,), name="shspec-owner-watch", daemon=True).start()
    _one_thread_per_worker()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _interrupt_job)


@contextlib.contextmanager
def interruptible():
    """Within the block, in a :class:`WorkerPool`'s worker, :meth:`WorkerPool.interrupt_workers` raises
    ``KeyboardInterrupt`` (module notes); elsewhere it does nothing."""
    _INTERRUPTIBLE[0] = True
    try:
        yield
    finally:
        _INTERRUPTIBLE[0] = False


def _pool_processes(executor: ProcessPoolExecutor) -> list:
    """The worker processes of a process pool (private, but stable since Python 3.9)."""
    return list((getattr(executor, "_processes", None) or {}).values())


class WorkerPool(ProcessPoolExecutor):
    """The local process pool of :func:`make_executor`: ``workers`` processes started with ``spawn``, one thread
    each, whose running jobs its owner can interrupt (module notes).  Leaving its ``with`` block by an exception
    (Ctrl-C included) stops it at once (:func:`stop_executor`), without waiting for its jobs."""

    def __init__(self, workers: int):
        super().__init__(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                         initializer=_start_worker, initargs=(os.getpid(),))

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            return super().__exit__(exc_type, exc, tb)
        # an error or Ctrl-C: the results are no longer wanted, and the workers ignore Ctrl-C, so do not wait
        stop_executor(self)
        return False

    def interrupt_workers(self) -> int:
        """Send SIGTERM to every live worker: a job running inside :func:`interruptible` gets a KeyboardInterrupt.
        Returns the number of workers signalled."""
        count = 0
        for process in _pool_processes(self):
            if process.is_alive():
                with contextlib.suppress(ProcessLookupError):
                    os.kill(process.pid, signal.SIGTERM)
                    count += 1
        return count


class SerialExecutor(Executor):
    """An Executor that runs each job when it is submitted, in the calling process and thread."""

    def __init__(self):
        self._shutdown = False

    def submit(self, fn, /, *args, **kwargs) -> Future:
        if self._shutdown:
            raise RuntimeError("cannot submit to a SerialExecutor after shutdown")
        future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001 - delivered through the future, as every Executor does
            future.set_exception(exc)
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._shutdown = True


def _distributed():
    """The ``distributed`` package, an optional dependency (``pip install "shspec[dask]"``)."""
    try:
        import distributed
    except ImportError:
        raise SchedulerError("running on a Dask cluster needs Dask's distributed package, which is not installed: "
                             'pip install "shspec[dask]"') from None
    return distributed


#: The transports whose location is ``host:port`` (inproc is in-process and has none).
_HOST_PORT = ("tcp", "tls", "ws", "wss", "ucx")


def _check_address(address: str) -> tuple[str, str, int | None]:
    """The scheme, host and port (None for inproc) of a scheduler address, checked before any connection: an unknown
    scheme or a port that cannot exist is named as such, not as a server that refuses or does not answer."""
    from distributed.comm import parse_address, parse_host_port
    from distributed.comm.registry import backends, get_backend

    scheme, location = parse_address(address)
    try:
        get_backend(scheme)
    except ValueError:
        raise SchedulerError(f"{address!r} has the unknown scheme {scheme!r}: Dask schedulers listen at "
                             f"tcp://host:port (Dask knows {', '.join(sorted(backends))})") from None
    if scheme not in _HOST_PORT:
        return scheme, location, None
    try:
        host, port = parse_host_port(location)
    except (ValueError, TypeError) as exc:
        raise SchedulerError(f"{address!r} is not a Dask scheduler address ({scheme}://host:port): {exc}") from None
    if not 0 < port < 65536:
        raise SchedulerError(f"{address!r} names the port {port}, which cannot exist (ports are 1 to 65535)")
    if not host:
        raise SchedulerError(f"{address!r} names no host ({scheme}://host:port)")
    return scheme, host, port


def _handshake(address: str, timeout: float) -> None:
    """Exchange Dask's handshake with the server at ``address``, within ``timeout`` seconds in all.

    distributed bounds the connection by its timeout but then waits for the server's half of the handshake without
    limit, so ``Client()`` hung on a server that accepts connections and never speaks.  The exchange runs in a thread
    of its own, whose event loop cannot clash with one the caller may run (Jupyter's).
    """
    import asyncio

    from distributed.comm import connect

    async def exchange():
        comm = await asyncio.wait_for(connect(address, timeout=timeout), timeout)
        await comm.close()

    outcome = []

    def run():
        try:
            asyncio.run(exchange())
        except Exception as exc:  # noqa: BLE001 - handed to the caller's thread, which names it
            outcome.append(exc)

    thread = threading.Thread(target=run, name="shspec-scheduler-handshake", daemon=True)
    thread.start()
    thread.join(timeout + 5)  # wait_for has ended the exchange by then; the margin is the event loop's
    error = outcome[0] if outcome else TimeoutError() if thread.is_alive() else None
    if isinstance(error, TimeoutError):
        raise SchedulerError(f"the server at {address} accepts connections but does not answer as a Dask scheduler "
                             f"within {timeout:g} s") from None
    if isinstance(error, OSError):  # distributed's CommClosedError is one: the server hung up
        raise SchedulerError(f"cannot reach the Dask scheduler at {address}: {error}") from None
    if error is not None:
        raise SchedulerError(f"the server at {address} does not answer as a Dask scheduler: "
                             f"{type(error).__name__}: {str(error)[:200]}") from None


def _probe(address: str, timeout: float) -> None:
    """Name what is wrong with ``address`` before distributed's client connects: a malformed address at once
    (:func:`_check_address`); for TCP, a port where nothing listens at once (distributed retries a refused connection
    until its timeout, then raises with a traceback of its own), and a server that does not speak Dask within
    ``timeout`` seconds (:func:`_handshake`)."""
    try:
        scheme, host, port = _check_address(address)
    except (ValueError, TypeError) as exc:
        raise SchedulerError(f"{address!r} is not a Dask scheduler address (tcp://host:port): {exc}") from None
    if scheme != "tcp":
        return  # other transports (tls, ws, inproc, ucx) need the client's own connection arguments
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        reason = "no answer" if isinstance(exc, TimeoutError) else exc.strerror or str(exc)
        raise SchedulerError(f"cannot reach the Dask scheduler at {address}: {reason}") from None
    _handshake(address, timeout)


class DaskExecutor(Executor):
    """The Executor of a Dask distributed client; ``shutdown`` also closes the client it owns.

    Parameters
    ----------
    address : str
        Scheduler address (``tcp://host:port``).
    timeout : float
        Seconds to wait for the scheduler to answer.

    Raises
    ------
    SchedulerError
        Nothing answers at ``address`` within ``timeout`` seconds, the address cannot be parsed, or Dask's
        distributed package is not installed (the extra ``shspec[dask]``).
    """

    def __init__(self, address: str, *, timeout: float = CONNECT_TIMEOUT):
        distributed = _distributed()
        _probe(address, timeout)
        try:
            self.client = distributed.Client(address, timeout=timeout)
        except OSError as exc:  # distributed's TimeoutError is one
            raise SchedulerError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
        except Exception as exc:  # noqa: BLE001 - whatever answered there does not speak Dask (seen: MemoryError)
            raise SchedulerError(f"the server at {address} does not answer as a Dask scheduler: "
                                 f"{type(exc).__name__}: {str(exc)[:200]}") from None
        self._executor = self.client.get_executor()

    def submit(self, fn, /, *args, **kwargs) -> Future:
        return self._executor.submit(fn, *args, **kwargs)

    def map(self, fn, *iterables, timeout=None, chunksize=1):
        return self._executor.map(fn, *iterables, timeout=timeout)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._executor.shutdown(wait=wait)
        self.client.close()


def make_executor(workers: int | None = None, scheduler: str | None = None, *,
                  connect_timeout: float = CONNECT_TIMEOUT) -> Executor:
    """An Executor for independent jobs: serial, a process pool of ``workers``, or a Dask cluster (module notes).

    Parameters
    ----------
    workers : int, optional
        Number of worker processes (≥ 1; 1 is serial).  Not together with ``scheduler``.
    scheduler : str, optional
        Address of a Dask distributed scheduler.
    connect_timeout : float
        Seconds to wait for the scheduler to answer.

    Returns
    -------
    concurrent.futures.Executor
        Use it as a context manager so that it is shut down.

    Raises
    ------
    InvalidArgumentError
        If ``workers`` is not a positive integer, ``scheduler`` not a non-empty string, or both are given.
    SchedulerError
        If nothing answers at ``scheduler`` within ``connect_timeout`` seconds.
    """
    if workers is not None:
        workers = check_int(workers, "workers", minimum=1, maximum=4096)
    if scheduler is not None:
        if not isinstance(scheduler, str) or not scheduler.strip():
            raise InvalidArgumentError(f"scheduler must be an address string, got {scheduler!r}")
        if workers is not None:
            raise InvalidArgumentError("give workers (a local process pool) or scheduler (a Dask cluster), not both")
        return DaskExecutor(scheduler.strip(), timeout=connect_timeout)
    if workers is None or workers == 1:
        return SerialExecutor()
    return WorkerPool(workers)


def usable_cores() -> int:
    """The cores this process may run on: its CPU affinity where the system has one (a container's or a batch job's
    share), else every core of the machine."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # macOS and Windows have no affinity call
        return os.cpu_count() or 1


def stop_executor(executor: Executor) -> None:
    """Shut ``executor`` down without waiting for its jobs: the pending ones are cancelled, and the running ones end
    too, their results lost.

    A process pool's workers are killed (a running job cannot be cancelled otherwise: a plain ``shutdown``
    waits for it, and so does the interpreter at exit; SIGTERM would only interrupt a :class:`WorkerPool`'s job,
    whose worker could then take the next one queued); a Dask executor cancels its futures and closes its
    client (the cluster's workers drop the tasks); a :class:`SerialExecutor` has nothing running.  Use it on an
    executor of your own, once its results are in: on a shared one it ends the other jobs too.
    """
    if isinstance(executor, ProcessPoolExecutor):
        kill = getattr(executor, "kill_workers", None)  # Python >= 3.14
        if kill is not None:
            kill()
            executor.shutdown(wait=True)
            return
        # earlier Pythons: the pool's own processes and manager thread
        processes = _pool_processes(executor)
        manager = getattr(executor, "_executor_manager_thread", None)
        executor.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            if process.is_alive():
                process.kill()
        for process in processes:
            process.join()
        if manager is not None:
            manager.join()  # it sees the workers gone and ends
        return
    try:
        executor.shutdown(wait=False, cancel_futures=True)
    except TypeError:  # an Executor whose shutdown predates cancel_futures (distributed's own)
        executor.shutdown(wait=False)
