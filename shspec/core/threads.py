"""What lets many threads of one process share shspec's objects, and a forked child use them after its parent.

* pyshtools' Fortran routines keep state between calls (FFTW plans and tables of Legendre functions sized for the
  last grid) and release the GIL while they run: two threads in them at once corrupted the heap ("double free or
  corruption", "Floating point exception" in ``MakeGridGLQ``) or returned another call's grid.  Every call shspec
  makes into them holds :data:`PYSHTOOLS_LOCK`; they take microseconds to milliseconds.
* numba runs the parallel kernels (table assembly, contractions, the Schur scaling, table builds) on a threading
  layer chosen at their first launch.  Its first choice without TBB, GNU OpenMP, is thread-safe but cannot survive a
  ``fork``: every process forked after a kernel ran (a ``multiprocessing`` pool with the "fork" start method, the
  default on Linux before Python 3.14) printed "fork() called from a process already using GNU OpenMP, this is
  unsafe", and ``Pool.map`` waited for ever.  So shspec asks numba for a fork-safe layer (TBB if installed, else
  an OpenMP that is not GNU's, else numba's own workqueue), unless ``NUMBA_THREADING_LAYER`` chooses one.  The
  workqueue takes one launch at a time per process (a second, concurrent one aborts the process), so every parallel
  kernel is :func:`serialized` by :data:`NUMBA_LOCK`; each launch uses all of numba's threads anyway.  Where GNU
  OpenMP runs all the same (chosen by ``NUMBA_THREADING_LAYER``, or launched before shspec was imported), a forked
  child raises :class:`~shspec.errors.UnsafeForkError` at its first kernel instead of being killed by numba.
* The same input gives the same bits on any number of threads.  LAPACK's solvers and BLAS products round
  differently on one thread and on several (measured: eigenvalues at (Lb, La, K) = (30, 15, 256) differ by 5e-12,
  and a fit of degree 10 took another path through its search, 745 against 809 iterations, from a target written
  on one thread instead of two), and so do numba's reductions split by thread.  So shspec's computations run
  :func:`reproducible`: inside it every BLAS pool of the process has one thread, and the reductions are cut
  into a fixed number of chunks (:data:`REDUCTION_CHUNKS`) whatever numba's thread count.  Processes are the way
  to use more cores (``shspec fit`` runs its starts in a pool).  :func:`set_reproducible` (False) lets BLAS use its
  threads again, for the speed of one large solve on many cores (1.4x at Lb = 49 on two cores), at the price of
  results that depend on the thread count.  Nor does shspec call pyshtools' GLQ transforms, whose FFTW plans are
  chosen by timing them (:mod:`shspec.sphere.grid`).
"""

from __future__ import annotations

import contextlib
import functools
import os
import threading

import numba

from ..errors import InvalidArgumentError, UnsafeForkError

__all__ = ["PYSHTOOLS_LOCK", "NUMBA_LOCK", "serialized", "reproducible", "reproducible_call", "set_reproducible",
           "REDUCTION_CHUNKS"]

#: Held around every call into pyshtools' compiled routines.
PYSHTOOLS_LOCK = threading.RLock()

#: Held around every launch of a numba ``parallel=True`` kernel.
NUMBA_LOCK = threading.RLock()

#: Partial sums of a parallel reduction (numba kernels): fixed, so that the sums are added in the same order on
#: any number of threads; it also caps the threads such a kernel can use.
REDUCTION_CHUNKS = 8

# reproducible(): how many callers are inside it, the limiter they share, and the switch of set_reproducible
_BLAS_LOCK = threading.Lock()
_BLAS = {"depth": 0, "limiter": None, "controller": None, "enabled": True}

if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "forksafe"


def _gnu_openmp_ran() -> bool:
    """Whether numba's parallel kernels have run in this process on GNU OpenMP."""
    try:
        layer = numba.threading_layer()
    except ValueError:  # no parallel kernel has run yet
        return False
    if layer != "omp":
        return False
    from numba.np.ufunc import omppool

    return omppool.openmp_vendor == "GNU"


#: Set in a child forked after GNU OpenMP ran: numba would terminate it at its first parallel launch.
_FORKED_AFTER_GNU_OPENMP = False


def _after_fork_in_child() -> None:
    global _FORKED_AFTER_GNU_OPENMP
    _FORKED_AFTER_GNU_OPENMP = _gnu_openmp_ran()
    # a lock another thread of the parent held at the fork would stay held in the child for ever (as logging does)
    PYSHTOOLS_LOCK._at_fork_reinit()
    NUMBA_LOCK._at_fork_reinit()
    _BLAS_LOCK._at_fork_reinit()


os.register_at_fork(after_in_child=_after_fork_in_child)


def serialized(kernel):
    """``kernel`` (a numba parallel dispatcher) wrapped to run under :data:`NUMBA_LOCK`; called from Python only.

    Raises
    ------
    UnsafeForkError
        In a process forked after its parent ran parallel kernels on GNU OpenMP.
    """

    @functools.wraps(kernel)
    def run(*args):
        if _FORKED_AFTER_GNU_OPENMP:
            raise UnsafeForkError(
                "this process was forked after its parent ran numba's parallel kernels on GNU OpenMP, which cannot "
                "run in a forked child (numba would terminate it): start worker processes with 'spawn' or "
                "'forkserver', or leave NUMBA_THREADING_LAYER unset so that shspec picks a fork-safe layer")
        with NUMBA_LOCK:
            return kernel(*args)

    return run


@contextlib.contextmanager
def reproducible():
    """Run the block with one thread in every BLAS pool of the process (module notes).  OpenMP pools keep theirs:
    numba's kernels add their partial sums in a fixed order on any number of threads.

    Process-wide and counted: the pools get their threads back when the last of the threads inside it leaves, so
    that threads sharing a model all stay on one BLAS thread.  Nested use costs nothing.  Does nothing after
    ``set_reproducible(False)``.
    """
    if not _BLAS["enabled"]:
        yield
        return
    with _BLAS_LOCK:
        if _BLAS["depth"] == 0:
            if _BLAS["controller"] is None:
                from threadpoolctl import ThreadpoolController

                import scipy.linalg  # noqa: F401  (SciPy ships its own OpenBLAS: load it before the scan)

                _BLAS["controller"] = ThreadpoolController()
            _BLAS["limiter"] = _BLAS["controller"].limit(limits=1, user_api="blas")
        _BLAS["depth"] += 1
    try:
        yield
    finally:
        with _BLAS_LOCK:
            _BLAS["depth"] -= 1
            if _BLAS["depth"] == 0:
                _BLAS["limiter"].restore_original_limits()
                _BLAS["limiter"] = None


def reproducible_call(function):
    """``function`` run inside :func:`reproducible`."""

    @functools.wraps(function)
    def run(*args, **kwargs):
        with reproducible():
            return function(*args, **kwargs)

    return run


def set_reproducible(enabled: bool) -> None:
    """Whether shspec's computations run on one BLAS thread (True, the default: the same bits on any machine and
    thread count) or on the BLAS pools' own threads (False: faster single large solves on many cores, results that
    depend on the thread count).

    Raises
    ------
    InvalidArgumentError
        If ``enabled`` is not a bool.
    """
    if not isinstance(enabled, bool):
        raise InvalidArgumentError(f"set_reproducible takes True or False, got {enabled!r}")
    _BLAS["enabled"] = enabled
