"""Size estimates and progress bars for long computations on large meshes.

A 163k-vertex mesh keeps ``shspec topology`` or ``shspec fit --model mesh`` busy for about a minute in the cotan
eigensolver and the cMCF.  Within :func:`mesh_progress` (the command line opens it unless ``--quiet``), those two
print, for meshes of at least :data:`LARGE_MESH` vertices, what they are about to do and how large it is (memory of
the Krylov basis, a rough time) and show a tqdm bar on stderr.  That is the default, in Python too (a refined mesh
target solves a mesh 16 times larger, tens of seconds that should not pass in silence); ``mesh_progress(False)``
silences a block, as ``--quiet`` does.

The time estimate of the shift-invert Lanczos solver, t ≈ n·m·log₂(n)·2.2e-7/13.3 s + 2·n·m²/1e10 s for n vertices
and a basis of m ≈ 2.8 K + 60 vectors, is a fit to one core of the development machine (icospheres of 10k and 41k
vertices, K = 100..400: the triangular solves dominate there, the orthogonalization at large K); it says whether to
expect seconds or minutes, not more.
"""

from __future__ import annotations

import contextlib
import contextvars
import sys
from typing import Iterator

import numpy as np
from tqdm import tqdm

from ..errors import ResourceLimitError
from ..core.resources import available_memory, human_bytes

__all__ = ["LARGE_MESH", "mesh_progress", "shown", "lanczos_estimate", "announce", "bar"]

#: Meshes with at least this many vertices get an estimate and a progress bar (below, the work takes seconds).
LARGE_MESH = 20000

_SHOWN = contextvars.ContextVar("shspec_mesh_progress", default=True)


@contextlib.contextmanager
def mesh_progress(enabled: bool = True) -> Iterator[None]:
    """Within the block, long mesh computations print their size and show a progress bar (module notes)."""
    token = _SHOWN.set(bool(enabled))
    try:
        yield
    finally:
        _SHOWN.reset(token)


def shown(nvertices: int) -> bool:
    """Whether work on a mesh of ``nvertices`` shows its estimate and progress here."""
    return _SHOWN.get() and nvertices >= LARGE_MESH


def lanczos_estimate(n: int, k: int, columns: int) -> tuple[int, int, float]:
    """(expected basis vectors, bytes of the basis allocated, rough seconds) of :func:`~shspec.mesh.eigen.eigenpairs`
    for ``k`` pairs of an ``n``-vertex mesh with room for ``columns`` basis vectors (module notes)."""
    m = min(columns, int(2.8 * k) + 60)
    seconds = n * m * np.log2(max(n, 2)) * 2.2e-7 / 13.3 + 2.0 * n * m * m / 1e10
    return m, 8 * n * columns, float(seconds)


def announce(text: str, memory: int = 0) -> None:
    """Print ``text`` on stderr; refuse (ResourceLimitError) when ``memory`` bytes exceed what is available."""
    available = available_memory()
    if available is not None and memory > available:
        raise ResourceLimitError(f"{text}: needs {human_bytes(memory)}, but {human_bytes(available)} of memory is "
                                 "available; ask for fewer eigenvalues or use a coarser mesh")
    tqdm.write(text, file=sys.stderr)


def bar(nvertices: int, total: int, desc: str, unit: str, iterable=None) -> tqdm:
    """A tqdm bar on stderr, disabled unless :func:`shown` for this mesh size: a context manager, or the wrapper of
    ``iterable``."""
    return tqdm(iterable, total=total, desc=desc, unit=unit, file=sys.stderr, leave=False,
                disable=not shown(nvertices))
