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
"""

from __future__ import annotations

import functools
import os
import threading

import numba

from .errors import UnsafeForkError

__all__ = ["PYSHTOOLS_LOCK", "NUMBA_LOCK", "serialized"]

#: Held around every call into pyshtools' compiled routines.
PYSHTOOLS_LOCK = threading.RLock()

#: Held around every launch of a numba ``parallel=True`` kernel.
NUMBA_LOCK = threading.RLock()

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
