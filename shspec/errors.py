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
    "ShortSpectrumError",
]


class ShspecError(Exception):
    """Base class of every error shspec raises on purpose.

    Examples
    --------
    >>> import shspec
    >>> try:
    ...     shspec.spectrum([1.0], lmax=-1, k=3)
    ... except shspec.ShspecError as exc:      # every error shspec raises on purpose
    ...     print(type(exc).__name__)
    BandLimitError
    """


class InvalidArgumentError(ShspecError, ValueError):
    """An argument has the wrong shape, type, sign or value (NaN, inf, out of range).

    Examples
    --------
    >>> from shspec import InvalidArgumentError, ncoeffs
    >>> issubclass(InvalidArgumentError, ValueError)
    True
    >>> try:
    ...     ncoeffs(-1)
    ... except ValueError as exc:
    ...     print(type(exc).__name__)
    BandLimitError
    """


class BandLimitError(InvalidArgumentError):
    """A band limit is negative, absurd, or larger than what is available (a table, a basis).

    Examples
    --------
    >>> import shspec
    >>> try:
    ...     shspec.spectrum([1.0], lmax=-1, k=3)
    ... except shspec.BandLimitError as exc:
    ...     print("lmax" in str(exc))
    True
    """


class ConventionError(InvalidArgumentError):
    """Coefficients in another normalization or phase convention than shspec's (ortho, csphase=1).

    Examples
    --------
    >>> from shspec import ConventionError, InvalidArgumentError
    >>> issubclass(ConventionError, InvalidArgumentError)   # catch it as a bad argument, or on its own
    True
    """


class NotPositiveError(InvalidArgumentError):
    """A conformal factor that is not positive everywhere: it is not a metric, and the mass matrix is not SPD.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import ConformalFactor, NotPositiveError
    >>> a = np.zeros(9); a[0], a[6] = 1.0, 1.5    # 1 + 1.5 Y_20 dips below 0 near the equator
    >>> try:
    ...     ConformalFactor(a).check_positive()
    ... except NotPositiveError:
    ...     print("not a metric")
    not a metric
    """


class CacheError(ShspecError, OSError):
    """Reading or writing the table cache failed.

    Examples
    --------
    >>> from shspec import CacheError
    >>> issubclass(CacheError, OSError)     # a cache that cannot be read or written is an OS-level failure
    True
    """


class CorruptTableError(CacheError):
    """A cached table is truncated, fails its checksum, or does not follow the schema.

    Examples
    --------
    >>> from shspec import CacheError, CorruptTableError
    >>> issubclass(CorruptTableError, CacheError)
    True
    """


class TableMismatchError(CacheError):
    """A cached table is valid but not the one asked for (format version, band limits, convention).

    Examples
    --------
    >>> from shspec import CacheError, TableMismatchError
    >>> issubclass(TableMismatchError, CacheError)
    True
    """


class OutdatedTableError(TableMismatchError):
    """A cached table was written in an older format by an older shspec: :func:`~shspec.gaunt.cache.get_table`
    rebuilds it, with a warning.

    Examples
    --------
    >>> from shspec import OutdatedTableError, TableMismatchError
    >>> issubclass(OutdatedTableError, TableMismatchError)
    True
    """


class CacheLocationError(CacheError):
    """The cache directory cannot be used: it is a file, read-only, or the disk is full.

    Examples
    --------
    >>> from shspec import CacheError, CacheLocationError
    >>> issubclass(CacheLocationError, CacheError)
    True
    """


class MeshError(InvalidArgumentError):
    """A triangle mesh that shspec cannot use (open, non-manifold, wrong genus, degenerate, ...).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import MeshError, TriangleMesh
    >>> try:
    ...     TriangleMesh(np.zeros((3, 3)), np.array([[0, 1, 5]]))
    ... except MeshError as exc:
    ...     print(exc)
    face 0 = [0, 1, 5] refers to a vertex outside 0..2
    """


class ConvergenceError(ShspecError, RuntimeError):
    """An iterative method did not reach its tolerance.

    Examples
    --------
    >>> from shspec import ConvergenceError
    >>> issubclass(ConvergenceError, RuntimeError)
    True
    """


class CheckpointError(ShspecError, OSError):
    """A checkpoint or result file cannot be written, read or resumed from.

    Examples
    --------
    >>> from shspec import CheckpointError
    >>> from shspec.inverse import load_result_summary
    >>> try:
    ...     load_result_summary("no_such_result.h5")
    ... except CheckpointError:
    ...     print("refused")
    refused
    """


class OutputError(ShspecError, OSError):
    """An output directory or file cannot be created or written (a file in the way, no permission, disk full).

    Examples
    --------
    >>> from shspec import OutputError
    >>> issubclass(OutputError, OSError)
    True
    """


class SchedulerError(ShspecError, OSError):
    """A Dask scheduler cannot be reached (nothing listens at the address, or it does not answer in time).

    Examples
    --------
    >>> from shspec import SchedulerError
    >>> from shspec.core.parallel import make_executor
    >>> try:
    ...     make_executor(scheduler="nonsense://host:1")
    ... except SchedulerError as exc:
    ...     print("scheme" in str(exc))
    True
    """


class UnsafeForkError(ShspecError, RuntimeError):
    """A forked process cannot run numba's parallel kernels: its parent ran them on GNU OpenMP, which dies on fork.

    Examples
    --------
    >>> from shspec import UnsafeForkError
    >>> issubclass(UnsafeForkError, RuntimeError)
    True
    """


class ResourceLimitError(BandLimitError):
    """A computation would need more memory or disk than the machine has (the message gives both and what fits).

    Examples
    --------
    >>> from shspec import BandLimitError, ResourceLimitError
    >>> issubclass(ResourceLimitError, BandLimitError)    # ask for a smaller band limit
    True
    """


class BeyondBasisError(ShspecError, ValueError):
    """The discretization asked for cannot represent the target to the accuracy asked (a harmonic basis and
    conformal factors spanning decades): the message says what it would take.

    Examples
    --------
    >>> from shspec import BeyondBasisError
    >>> issubclass(BeyondBasisError, ValueError)
    True
    """


class ShortSpectrumError(InvalidArgumentError):
    """A target with fewer eigenvalues than a fit of the degree asked needs: the message names the degree they
    support (:attr:`supported_degree`) and how to fit either.

    Examples
    --------
    >>> from shspec import ShortSpectrumError
    >>> from shspec.fitting import prepare_fit
    >>> try:
    ...     prepare_fit([0.0, 2.0, 2.0, 2.0, 6.0, 6.0], lmax_factor=6, progress=False)
    ... except ShortSpectrumError as exc:
    ...     print(exc.supported_degree)
    0
    """

    def __init__(self, message: str, supported_degree: int):
        super().__init__(message)
        self.supported_degree = supported_degree

    def __reduce__(self):  # the default pickles the message only, which __init__ cannot take alone
        return type(self), (str(self), self.supported_degree)


class ShspecWarning(UserWarning):
    """Base class of the warnings shspec emits on purpose (filter them with ``warnings.simplefilter``).

    Examples
    --------
    >>> import warnings
    >>> from shspec import ShspecWarning
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore", ShspecWarning)   # silence shspec's own warnings only
    ...     warnings.warn("a truncation", ShspecWarning)      # (nothing is shown)
    """


class TruncationWarning(ShspecWarning):
    """A spectrum whose estimated truncation error (band limit of ρ or of the basis) exceeds the tolerance.

    Examples
    --------
    >>> from shspec import ShspecWarning, TruncationWarning
    >>> issubclass(TruncationWarning, ShspecWarning)
    True
    """
class TopologyError(ShspecError, ValueError):
    """A spectrum whose heat trace says, confidently, that the surface has a topology the operation cannot handle
    (a genus-0 fit of a torus's spectrum, say).

    Examples
    --------
    >>> from shspec import TopologyError
    >>> issubclass(TopologyError, ValueError)
    True
    """


#: The folder of the package: frames whose file lies in it are shspec's own.
_PACKAGE = str(Path(__file__).resolve().parent / "_")[:-1]  # with the separator: not shspec_launcher's files


def warn(message: str, category: type[Warning] = ShspecWarning) -> None:
    """Issue a warning attributed to the first frame outside shspec (the user's call), however deep in shspec its
    cause lies: a fixed ``stacklevel`` pointed at the wrapper of :func:`~shspec.core.threads.reproducible_call`
    ("threads.py:150") or at another of shspec's own lines.  In a thread that runs shspec's code from its start, the
    thread's own frames outside shspec.  (Python 3.12's ``skip_file_prefixes`` does the same; shspec supports 3.11.)
    """
    frame, level = sys._getframe(1), 2  # stacklevel 2 is warn's caller
    while frame.f_back is not None and frame.f_code.co_filename.startswith(_PACKAGE):
        frame, level = frame.f_back, level + 1
    warnings.warn(message, category, stacklevel=level)
