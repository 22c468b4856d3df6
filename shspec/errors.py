"""The exception hierarchy of shspec.

Every error raised on purpose by shspec is a subclass of :class:`ShspecError`, so that a caller can catch the
library's complaints without catching programming errors (``TypeError`` from a typo, say).  Each subclass also
derives from the built-in exception a Python user would expect (``ValueError`` for bad values, ``OSError`` for
the file system), so existing ``except ValueError`` code keeps working.

Warnings: shspec emits its own through :func:`warn`, which attributes them to the caller's line, not to a line of
shspec.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

__all__ = [
    "ShspecError",
    "InvalidArgumentError",
    "BandLimitError",
    "ConventionError",
    "NotPositiveError",
    "CacheError",
    "CorruptTableError",
    "TableMismatchError",
    "OutdatedTableError",
    "CacheLocationError",
    "MeshError",
    "ConvergenceError",
    "CheckpointError",
    "OutputError",
    "SchedulerError",
    "UnsafeForkError",
    "ResourceLimitError",
    "ShspecWarning",
    "TruncationWarning",
    "TopologyError",
    "BeyondBasisError",
]


class ShspecError(Exception):
    """Base class of every error shspec raises on purpose."""


class InvalidArgumentError(ShspecError, ValueError):
    """An argument has the wrong shape, type, sign or value (NaN, inf, out of range)."""


class BandLimitError(InvalidArgumentError):
    """A band limit is negative, absurd, or larger than what is available (a table, a basis)."""


class ConventionError(InvalidArgumentError):
    """Coefficients in another normalization or phase convention than shspec's (ortho, csphase=1)."""


class NotPositiveError(InvalidArgumentError):
    """A conformal factor that is not positive everywhere: it is not a metric, and the mass matrix is not SPD."""


class CacheError(ShspecError, OSError):
    """Reading or writing the table cache failed."""


class CorruptTableError(CacheError):
    """A cached table is truncated, fails its checksum, or does not follow the schema."""


class TableMismatchError(CacheError):
    """A cached table is valid but not the one asked for (format version, band limits, convention)."""


class OutdatedTableError(TableMismatchError):
    """A cached table was written in an older format by an older shspec: :func:`~shspec.gaunt.cache.get_table`
    rebuilds it, with a warning."""


class CacheLocationError(CacheError):
    """The cache directory cannot be used: it is a file, read-only, or the disk is full."""


class MeshError(InvalidArgumentError):
    """A triangle mesh that shspec cannot use (open, non-manifold, wrong genus, degenerate, ...)."""


class ConvergenceError(ShspecError, RuntimeError):
    """An iterative method did not reach its tolerance."""


class CheckpointError(ShspecError, OSError):
    """A checkpoint or result file cannot be written, read or resumed from."""


class OutputError(ShspecError, OSError):
    """An output directory or file cannot be created or written (a file in the way, no permission, disk full)."""


class SchedulerError(ShspecError, OSError):
    """A Dask scheduler cannot be reached (nothing listens at the address, or it does not answer in time)."""


class UnsafeForkError(ShspecError, RuntimeError):
    """A forked process cannot run numba's parallel kernels: its parent ran them on GNU OpenMP, which dies on fork."""


class ResourceLimitError(BandLimitError):
    """A computation would need more memory or disk than the machine has (the message gives both and what fits)."""


class BeyondBasisError(ShspecError, ValueError):
    """The discretization asked for cannot represent the target to the accuracy asked (a harmonic basis and
    conformal factors spanning decades): the message says what it would take."""


class ShspecWarning(UserWarning):
    """Base class of the warnings shspec emits on purpose (filter them with ``warnings.simplefilter``)."""


class TruncationWarning(ShspecWarning):
    """A spectrum whose estimated truncation error (band limit of ρ or of the basis) exceeds the tolerance."""
class TopologyError(ShspecError, ValueError):
    """A spectrum whose heat trace says, confidently, that the surface has a topology the operation cannot handle
    (a genus-0 fit of a torus's spectrum, say)."""


#: The folder of the package: frames whose file lies in it are shspec's own.
_PACKAGE = str(Path(__file__).resolve().parent / "_")[:-1]  # with the separator: not shspec_launcher's files


def warn(message: str, category: type[Warning] = ShspecWarning) -> None:
    """Issue a warning attributed to the first frame outside shspec (the user's call), however deep in shspec its
    cause lies: a fixed ``stacklevel`` pointed at the wrapper of :func:`~shspec.threads.reproducible_call`
    ("threads.py:150") or at another of shspec's own lines.  In a thread that runs shspec's code from its start, the
    thread's own frames outside shspec.  (Python 3.12's ``skip_file_prefixes`` does the same; shspec supports 3.11.)
    """
    frame, level = sys._getframe(1), 2  # stacklevel 2 is warn's caller
    while frame.f_back is not None and frame.f_code.co_filename.startswith(_PACKAGE):
        frame, level = frame.f_back, level + 1
    warnings.warn(message, category, stacklevel=level)
