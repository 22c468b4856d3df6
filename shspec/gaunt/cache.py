"""The on-disk cache of Gaunt tables: HDF5 files written atomically under a lock and validated on load.

Schema (format version 2), one file ``gaunt_Lb{Lb}_La{La}.h5`` per table:

=============================  ==========================================================================
``/values``                    float64 dataset, the stored families in the layout of :mod:`shspec.gaunt.table`
attr ``format``                ``"shspec-gaunt"``
attr ``format_version``        int, 2 (version 1 files hold the same layout, but a value could differ by an ulp
                               between tables of different La, which made results depend on what was cached)
attr ``lmax``                  int, basis band limit Lb
attr ``lmax_factor``           int, factor band limit La
attr ``convention``            :data:`CONVENTION`: real orthonormal harmonics as pyshtools (ortho, csphase=1)
attr ``count``                 int, number of values (must equal the layout's size for (Lb, La))
attr ``checksum``              ``"blake2b:<hex>"`` of the raw little-endian bytes of ``/values``
attr ``shspec_version``        the version that wrote it
attr ``created``               ISO 8601, UTC
attr ``build_seconds``         time the build took
=============================  ==========================================================================

The cache directory is, in order: the ``cache_dir`` argument, the ``SHSPEC_CACHE`` environment variable, the
``cache/`` folder of the shspec checkout the current directory lies in (found as git finds its repository: the
nearest enclosing folder whose ``pyproject.toml`` names the project ``shspec`` and that has a ``cache/`` folder), or
the user cache folder ``$XDG_CACHE_HOME/shspec`` (``~/.cache/shspec``).  The rule depends on where a command runs,
never on how shspec was installed, so ``python -m precompute`` and the installed ``shspec`` run from the same folder
share one cache.

Writes are atomic (:mod:`shspec.core.atomic`) and hold the table's lock file ``<name>.lock``; a temporary file
``<name>.<random>.tmp`` that exists while nobody holds the lock was left by a writer that was killed, and is removed
by the next writer of that table (or :func:`remove_stale_files`).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import filelock
import h5py
import numpy as np

from .._version import __version__
from ..core.atomic import atomic_hdf5, temporary_files, write_failure
from ..errors import (BandLimitError, CacheLocationError, CorruptTableError, OutdatedTableError, TableMismatchError,
                      warn)
from ..core.outputs import ensure_directory
from ..core.resources import check_need
from ..sphere.harmonics import degree_order
from .build import build_table
from .real_gaunt import real_gaunt
from .table import GauntTable, check_limits, table_need, table_size

__all__ = ["CONVENTION", "FORMAT_VERSION", "TableInfo", "TempFileInfo", "cache_dir", "cache_dir_source", "table_path",
           "save_table", "load_table", "get_table", "list_tables", "list_temporary_files", "remove_stale_files",
           "verify_table", "ensure_cache_dir"]

FORMAT_VERSION = 2
CONVENTION = "real-ortho-csphase1-pyshtools; flat i=l*l+l+m; G_ijk=int Y_i Y_j Y_k dOmega"
_PROJECT_NAME = re.compile(r'^name\s*=\s*"shspec"\s*$', re.M)
_NAME = re.compile(r"^gaunt_Lb(\d+)_La(\d+)\.h5$")


def cache_dir(path: str | os.PathLike | None = None) -> Path:
    """The cache directory to use: ``path``, else ``$SHSPEC_CACHE``, else the ``cache/`` folder of the checkout the
    current directory lies in, else ``$XDG_CACHE_HOME/shspec`` (~/.cache/shspec); see the module notes.

    Examples
    --------
    >>> from shspec.gaunt import cache_dir
    >>> cache_dir("tables").name          # created if needed
    'tables'
    """
    return cache_dir_source(path)[0]


def _checkout_cache(start: Path) -> Path | None:
    """``cache/`` of the nearest folder at or above ``start`` holding shspec's pyproject.toml and a cache/ folder."""
    for folder in (start, *start.parents):
        project = folder / "pyproject.toml"
        if (folder / "cache").is_dir() and project.is_file():
            try:
                if _PROJECT_NAME.search(project.read_text(errors="replace")):
                    return folder / "cache"
            except OSError:
                continue
    return None


def cache_dir_source(path: str | os.PathLike | None = None) -> tuple[Path, str]:
    """The cache directory and why it is that one (``"--cache-dir"``, ``"$SHSPEC_CACHE"``, ``"checkout <folder>"``
    or ``"user cache"``)."""
    if path is not None:
        if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
            # '' would put the tables into the current folder, unasked
            raise CacheLocationError(f"the cache directory must be a non-empty path, got {path!r}")
        return Path(path), "--cache-dir"
    env = os.environ.get("SHSPEC_CACHE")
    if env:
        return Path(env), "$SHSPEC_CACHE"
    checkout = _checkout_cache(Path.cwd())
    if checkout is not None:
        return checkout, f"checkout {checkout.parent}"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "shspec", "user cache"


def table_path(lmax: int, lmax_factor: int, directory: str | os.PathLike | None = None) -> Path:
    """Path of the file holding the table (Lb, La) in the cache directory.

    Examples
    --------
    >>> from shspec.gaunt import table_path
    >>> table_path(4, 2, "tables").name
    'gaunt_Lb4_La2.h5'
    """
    lmax, lmax_factor = check_limits(lmax, lmax_factor)
    return cache_dir(directory) / f"gaunt_Lb{lmax}_La{lmax_factor}.h5"


def ensure_cache_dir(directory: Path) -> Path:
    """Create the cache directory if needed; raise CacheLocationError if it is a file or not writable."""
    ensure_directory(directory, error=CacheLocationError, what="cache location")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise CacheLocationError(f"the cache directory {directory} is not writable (set SHSPEC_CACHE or cache_dir)")
    return directory


def _lock_path(path: Path) -> Path:
    return path.with_name(path.name + ".lock")


@contextlib.contextmanager
def _locked(path: Path):
    """Exclusive lock on ``path.lock`` (filelock: flock on POSIX, msvcrt on Windows) so that concurrent builders of
    one table wait for each other.

    Every writer of ``path`` holds this lock, so once we have it any temporary file of ``path`` belongs to a writer
    that died (SIGKILL, power cut) and is removed here.
    """
    lock = _lock_path(path)
    try:
        held = filelock.FileLock(lock, mode=0o644, thread_local=False).acquire()
    except OSError as exc:
        raise CacheLocationError(f"cannot create the lock file {lock}: {exc.strerror}") from exc
    with held:
        for tmp in temporary_files(path):
            with contextlib.suppress(OSError):
                tmp.unlink()
        yield


def _writer_active(path: Path) -> bool:
    """True when some process holds the lock of ``path`` (is building or writing it) right now."""
    lock = _lock_path(path)
    if not lock.exists():
        return False
    try:
        with filelock.FileLock(lock, thread_local=False).acquire(timeout=0):
            return False
    except filelock.Timeout:
        return True
    except OSError:
        return False


def _checksum(values: np.ndarray) -> str:
    h = hashlib.blake2b(digest_size=32)
    h.update(np.ascontiguousarray(values, dtype="<f8").data)
    return "blake2b:" + h.hexdigest()


def save_table(table: GauntTable, directory: str | os.PathLike | None = None, *, build_seconds: float = float("nan"),
               ) -> Path:
    """Write ``table`` to the cache atomically, under the table's lock; returns the path.

    An existing file is replaced only once the new one is complete and synced (see :mod:`shspec.core.atomic`).

    Examples
    --------
    >>> from shspec.gaunt import build_table, save_table, table_path
    >>> path = save_table(build_table(4, 2), "tables")    # atomically, with a checksum
    >>> path == table_path(4, 2, "tables")
    True
    """
    directory = ensure_cache_dir(cache_dir(directory))
    path = table_path(table.lmax, table.lmax_factor, directory)
    with _locked(path):
        return _write(table, path, build_seconds)


def _write(table: GauntTable, path: Path, build_seconds: float) -> Path:
    """Write ``table`` to ``path`` atomically; the caller holds the lock."""
    checksum = _checksum(table.values)
    created = datetime.now(timezone.utc).isoformat(timespec="seconds")
    existed = path.exists()
    try:
        with atomic_hdf5(path) as f:
            f.create_dataset("values", data=table.values)
            attrs = {"format": "shspec-gaunt", "format_version": FORMAT_VERSION, "lmax": table.lmax,
                     "lmax_factor": table.lmax_factor, "convention": CONVENTION, "count": table.values.size,
                     "checksum": checksum, "shspec_version": __version__, "created": created,
                     "build_seconds": build_seconds}
            f.attrs.update(attrs)
    except (OSError, RuntimeError) as exc:  # h5py reports a failed flush (a full disk, a file-size limit) as the latter
        failure = write_failure(path, exc, existed=existed, error=CacheLocationError)
        if failure.errno in (errno.ENOSPC, errno.EDQUOT):
            raise CacheLocationError(f"no space left in {path.parent} to write {path.name} "
                                     f"({table.values.nbytes / 2**20:.0f} MiB)") from exc
        raise failure from exc
    table.path = path
    table.metadata = dict(checksum=checksum, created=created, shspec_version=__version__,
                          build_seconds=build_seconds)
    return path


#: Tables read in this process, by (path, modification time, size): a file is read and validated once until it
#: changes; the few most recent are kept (with their assembly plans and restrictions, which cost as much as the read).
_MEMORY: "OrderedDict[tuple, GauntTable]" = OrderedDict()
_MEMORY_ENTRIES = 4
_MEMORY_LOCK = threading.Lock()
os.register_at_fork(after_in_child=_MEMORY_LOCK._at_fork_reinit)  # a thread of the parent may have held it
#: The file whose restriction served a table that has no file of its own, by that missing file's path: a repeated
#: load skips the scan of the cache directory (most of the cost of a small forward solve from a covering table).
_COVERED: dict[str, Path] = {}


def _read(path: Path, lmax: int | None = None, lmax_factor: int | None = None) -> GauntTable:
    """The validated table in ``path``, from memory when the file has not changed since it was read."""
    stat = path.stat()
    key = (str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    with _MEMORY_LOCK:  # threads share the memory (and read a file once between them)
        table = _MEMORY.get(key)
        if table is None:
            table = _read_file(path)
            _MEMORY[key] = table
            while len(_MEMORY) > _MEMORY_ENTRIES:
                _MEMORY.popitem(last=False)
        _MEMORY.move_to_end(key)
    if lmax is not None and (table.lmax, table.lmax_factor) != (lmax, lmax_factor):
        raise TableMismatchError(f"{path} holds the table ({table.lmax},{table.lmax_factor}), not "
                                 f"({lmax},{lmax_factor})")
    return table


def _read_file(path: Path) -> GauntTable:
    """Read and fully validate one table file; raise CorruptTableError / TableMismatchError on any defect."""
    try:
        f = h5py.File(path, "r")
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise CorruptTableError(f"{path} is not a readable HDF5 file (truncated or corrupt): {exc}") from exc
    with f:
        attrs = dict(f.attrs)
        if attrs.get("format") != "shspec-gaunt":
            raise CorruptTableError(f"{path} is not an shspec Gaunt table (format attribute {attrs.get('format')!r})")
        version = attrs.get("format_version")
        if isinstance(version, (int, np.integer)) and 0 < version < FORMAT_VERSION:
            raise OutdatedTableError(f"{path} was written by an older shspec (format version {version}; this one "
                                     f"writes {FORMAT_VERSION})")
        if version != FORMAT_VERSION:
            raise TableMismatchError(f"{path} has format version {version}; this shspec reads version "
                                     f"{FORMAT_VERSION}: rebuild it (precompute --force)")
        if attrs.get("convention") != CONVENTION:
            raise TableMismatchError(f"{path} was built for the convention {attrs.get('convention')!r}, "
                                     f"not {CONVENTION!r}")
        try:
            have_b, have_a = int(attrs["lmax"]), int(attrs["lmax_factor"])
            count, checksum = int(attrs["count"]), str(attrs["checksum"])
        except (KeyError, TypeError, ValueError) as exc:
            raise CorruptTableError(f"{path} lacks a required attribute: {exc}") from exc
        expected = table_size(have_b, have_a)
        stored = _values_dataset(f)
        if count != expected or not isinstance(stored, h5py.Dataset) or stored.shape != (expected,):
            raise CorruptTableError(f"{path} should hold {expected} values for ({have_b},{have_a}); "
                                    f"it says {count} and stores {_describe_values(stored)}")
        try:
            values = stored[...]
        except OSError as exc:
            raise CorruptTableError(f"{path}: the values cannot be read (truncated file?): {exc}") from exc
    if values.dtype != np.float64:
        raise CorruptTableError(f"{path}: values have dtype {values.dtype}, expected float64")
    if _checksum(values) != checksum:
        raise CorruptTableError(f"{path} fails its checksum: the file is corrupt; rebuild it (precompute --force)")
    finite = np.isfinite(values)
    if not finite.all():
        # a checksum only says the file is as written; a table written with NaN in it is as unusable
        bad = np.flatnonzero(~finite)
        raise CorruptTableError(f"{path} holds {bad.size} values that are NaN or inf (first at position {bad[0]}): "
                                "rebuild it (precompute --force)")
    meta = {k: (v.item() if hasattr(v, "item") else v) for k, v in attrs.items()}
    values.setflags(write=False)  # shared by every caller that loads this file
    return GauntTable(have_b, have_a, values, path=path, metadata=meta)


def _values_dataset(f: h5py.File):
    """The object at ``/values`` (a dataset in a sound file), or None; a dangling link counts as missing."""
    try:
        return f.get("values")
    except (KeyError, OSError):
        return None


def _describe_values(stored) -> str:
    """What ``/values`` is, for a message: its shape, or the kind of object that stands where a dataset should."""
    if stored is None:
        return "none"
    if isinstance(stored, h5py.Dataset):
        return str(stored.shape)
    return f"a {type(stored).__name__.lower()} instead of a dataset"


@dataclass(frozen=True)
class TableInfo:
    """One file of the cache, as listed by :func:`list_tables` (read from its attributes only)."""

    path: Path
    lmax: int
    lmax_factor: int
    count: int
    nbytes: int
    created: str
    problem: str | None  # why the file is unusable, or None


def list_tables(directory: str | os.PathLike | None = None, *, verify: bool = False) -> list[TableInfo]:
    """The tables in the cache directory, smallest first, with a note on any that cannot be used.

    Parameters
    ----------
    directory : path-like, optional
        Cache directory (default: :func:`cache_dir`).  A missing folder holds no tables.
    verify : bool
        Read every table in full and check its checksum (seconds per GiB); otherwise only the attributes and the
        shape of the values are checked.

    Raises
    ------
    CacheLocationError
        The location exists and is not a directory.

    Examples
    --------
    >>> from shspec.gaunt import build_table, list_tables, save_table
    >>> _ = save_table(build_table(4, 2), "tables")
    >>> [(info.lmax, info.lmax_factor) for info in list_tables("tables")]
    [(4, 2)]
    """
    directory = cache_dir(directory)
    out = []
    if directory.exists() and not directory.is_dir():
        raise CacheLocationError(f"the cache location {directory} is a file, not a directory")
    if not directory.is_dir():
        return out
    for path in sorted(directory.iterdir()):
        match = _NAME.match(path.name)
        if not match:
            continue
        lb, la = int(match.group(1)), int(match.group(2))
        problem, count, created = None, 0, ""
        if path.is_symlink() and not path.exists():
            # no file to read or size: say where it points, which is what the user has to fix (or a build replaces)
            problem = f"a symbolic link to {os.readlink(path)}, which does not exist"
            out.append(TableInfo(path, lb, la, count, 0, created, problem))
            continue
        try:
            with h5py.File(path, "r") as f:
                count = int(f.attrs.get("count", -1))
                created = str(f.attrs.get("created", ""))
                if f.attrs.get("format_version") != FORMAT_VERSION:
                    problem = (f"format version {f.attrs.get('format_version')}, this shspec reads {FORMAT_VERSION}: "
                               "rebuild it (precompute --force)")
                elif (int(f.attrs.get("lmax", -1)), int(f.attrs.get("lmax_factor", -1))) != (lb, la):
                    problem = "band limits in the file do not match its name"
                else:
                    stored = _values_dataset(f)
                    if not isinstance(stored, h5py.Dataset) or stored.shape != (table_size(lb, la),):
                        problem = f"stores {_describe_values(stored)} as its values, not ({table_size(lb, la)},)"
        except (OSError, ValueError, BandLimitError) as exc:
            problem = f"unreadable: {exc}"
        if problem is None and verify:
            try:
                _read(path, lb, la)
            except (CorruptTableError, TableMismatchError) as exc:
                problem = str(exc).replace(f"{path} ", "", 1)
        out.append(TableInfo(path, lb, la, count, path.stat().st_size, created, problem))
    return sorted(out, key=lambda t: (t.count, t.lmax, t.lmax_factor))


@dataclass(frozen=True)
class TempFileInfo:
    """A temporary file of an unfinished table write: ``stale`` when no writer holds the table's lock."""

    path: Path
    table: Path
    nbytes: int
    stale: bool


def list_temporary_files(directory: str | os.PathLike | None = None) -> list[TempFileInfo]:
    """Temporary files of table writes in the cache directory (a killed writer leaves its file behind)."""
    directory = cache_dir(directory)
    if not directory.is_dir():
        return []
    tables = {directory / p.name.split(".h5.", 1)[0] for p in directory.glob("gaunt_*.h5.*.tmp")}
    out = []
    for table in sorted(tables):
        table = table.with_name(table.name + ".h5")
        active = _writer_active(table)
        for tmp in temporary_files(table):
            with contextlib.suppress(OSError):
                out.append(TempFileInfo(tmp, table, tmp.stat().st_size, not active))
    return out


def remove_stale_files(directory: str | os.PathLike | None = None) -> list[TempFileInfo]:
    """Remove the temporary files that no running writer owns; returns what was removed."""
    removed = []
    for info in list_temporary_files(directory):
        if info.stale:
            with _locked(info.table):  # removes every temporary file of that table, now that we own its lock
                removed.append(info)
    return removed


def load_table(lmax: int, lmax_factor: int, directory: str | os.PathLike | None = None) -> GauntTable:
    """Load the table (Lb, La) from the cache, or restrict the smallest cached table that covers it.

    Raises
    ------
    FileNotFoundError
        No cached table covers (Lb, La).
    CorruptTableError, TableMismatchError
        The exact file exists but is damaged or of another format; it is never used silently.

    Examples
    --------
    >>> from shspec.gaunt import build_table, load_table, save_table
    >>> _ = save_table(build_table(4, 2), "tables")
    >>> load_table(4, 2, "tables").lmax      # validated on load: a damaged file is refused
    4
    """
    lmax, lmax_factor = check_limits(lmax, lmax_factor)
    path = table_path(lmax, lmax_factor, directory)
    if path.exists():
        return _read(path, lmax, lmax_factor)
    missing = str(path.resolve())
    source = _COVERED.get(missing)  # one lookup: another thread may forget the entry between two
    if source is not None:
        try:
            return _read(source).restrict(lmax, lmax_factor)
        except (OSError, CorruptTableError, TableMismatchError):
            _COVERED.pop(missing, None)  # removed or changed since: the scan below finds what covers it now
    for info in list_tables(directory):
        if info.problem is None and info.lmax >= lmax and info.lmax_factor >= lmax_factor:
            try:
                table = _read(info.path).restrict(lmax, lmax_factor)
            except (CorruptTableError, TableMismatchError) as exc:
                warn(f"skipping a damaged cached table: {exc}")
                continue
            _COVERED[missing] = info.path
            return table
    raise FileNotFoundError(f"no cached Gaunt table covers ({lmax},{lmax_factor}) in {cache_dir(directory)}")


#: Values per second a table build reaches on one core of a 2020s machine (measured 0.8-1.5e7 on two cores);
#: used only to decide whether a build is long enough for a progress bar.
_BUILD_RATE = 5e6


def get_table(lmax: int, lmax_factor: int, *, cache_dir: str | os.PathLike | None = None, build: bool = True,
              rebuild_corrupt: bool = False, force: bool = False, progress: bool | None = None) -> GauntTable:
    """The Gaunt table (Lb, La): from the cache if there, otherwise built (and saved) when ``build`` is True.

    Parameters
    ----------
    lmax, lmax_factor : int
        Basis band limit Lb and factor band limit La.
    cache_dir : path-like, optional
        Cache directory (default: see :func:`cache_dir`).
    build : bool
        Build and save a missing table; when False a missing table raises :class:`BandLimitError`.
    rebuild_corrupt : bool
        Replace a corrupt or mismatched file by a fresh build, with a warning, instead of raising.  A table of an
        older format (:class:`~shspec.errors.OutdatedTableError`) is always rebuilt, with a warning, when ``build``.
    force : bool
        Build the table again even if a valid one is cached.  The cached file stays in place (and usable by
        others) until the new one is complete and renamed over it; an interrupted rebuild leaves it untouched.
    progress : bool or None
        Progress bar (stderr) while building; None (default): only for a build expected to take over a second.

    Raises
    ------
    ResourceLimitError
        Building the table would need more memory than is available or more disk than is free (checked first;
        the message says which band limits fit).

    Examples
    --------
    >>> from shspec import get_table
    >>> table = get_table(4, 2)
    >>> (table.lmax, table.lmax_factor)
    (4, 2)
    """
    directory = cache_dir
    lmax, lmax_factor = check_limits(lmax, lmax_factor)
    try:
        if not force:
            return load_table(lmax, lmax_factor, directory)
    except FileNotFoundError:
        if not build:
            raise BandLimitError(f"no cached Gaunt table covers (lmax={lmax}, lmax_factor={lmax_factor}) and "
                                 f"building is not allowed; run: python -m precompute --lmax {lmax} "
                                 f"--lmax-factor {lmax_factor}") from None
    except (CorruptTableError, TableMismatchError) as exc:
        if not (rebuild_corrupt or build and isinstance(exc, OutdatedTableError)):
            raise
        warn(f"rebuilding the Gaunt table: {exc}")
    path = table_path(lmax, lmax_factor, directory)
    ensure_cache_dir(path.parent)
    need = table_need(lmax, lmax_factor)
    check_need(need, disk_path=path.parent, limits=(lmax, lmax_factor), estimate=table_need)
    if progress is None:
        progress = need.memory / 8 > _BUILD_RATE
    with _locked(path):
        # another process may have built it while we waited for the lock
        if path.exists() and not force:
            try:
                return _read(path, lmax, lmax_factor)
            except (CorruptTableError, TableMismatchError) as exc:
                if not (rebuild_corrupt or isinstance(exc, OutdatedTableError)):
                    raise
        start = time.perf_counter()
        table = build_table(lmax, lmax_factor, progress=progress)
        _write(table, path, time.perf_counter() - start)
    return table


def verify_table(table: GauntTable, samples: int = 2000, seed: int = 0) -> float:
    """Largest absolute difference between ``samples`` random table entries and a fresh scalar computation.

    Each sample is one plan entry (a real pair i <= j and an order m3) and one degree l3 of its family, recomputed
    with :func:`shspec.real_gaunt`.

    Examples
    --------
    >>> from shspec.gaunt import build_table, verify_table
    >>> verify_table(build_table(4, 2), samples=100) < 1e-13   # largest error against an independent quadrature
    True
    """
    plan = table.plan
    n = plan.i.size
    if n == 0:
        return 0.0
    rng = np.random.default_rng(seed)
    l, m = degree_order(table.lmax)
    diffs = []
    for e in rng.integers(0, n, size=samples):
        t = int(rng.integers(0, plan.count[e]))
        l3 = int(plan.l3min[e]) + 2 * t
        i, j = int(plan.i[e]), int(plan.j[e])
        stored = plan.factor[e] * table.values[plan.offset[e] + t]
        fresh = real_gaunt(int(l[i]), int(m[i]), int(l[j]), int(m[j]), l3, int(plan.m3[e]))
        diffs.append(abs(stored - fresh))
    return float(np.max(diffs, initial=0.0))  # NaN when a sampled value is NaN (max() would skip it)
