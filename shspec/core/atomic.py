"""Atomic file writes: a file either keeps its old content or gets the complete new one, never a half-written one.

The new content goes to a temporary file in the destination's own folder (a rename is only atomic within one file
system), which is flushed and fsynced, renamed over the destination, and then the folder is fsynced so that the
rename itself survives a power cut.  Any exception, ``KeyboardInterrupt`` included, removes the temporary file and
leaves the destination as it was.  A process killed with SIGKILL cannot clean up: its temporary file stays behind,
named ``<destination name>.<random>.tmp`` (:func:`temporary_files` finds them, for whoever owns the lock of the
destination to remove).

Outputs.  :func:`atomic_output` (and its shorthands :func:`write_text` and :func:`save_figure`) is what every command
writes its results through: on a full disk, a read-only folder or a missing permission it raises one
:class:`~shspec.errors.OutputError` that names the file, says why in words, and says that the previous file is
intact (or that none was written), instead of a raw ``OSError`` or a half-written file.

A Ctrl-C (SIGINT) during a write is held back to the next point where the write checks for it, and raised there,
so the temporary file is always removed: raised where Python's handler would raise it, it could land in a weakref
callback or ``__del__`` of h5py's object registry, where Python prints "Exception ignored" and drops it, and the
write then finished and the command exited 0.

A set of files.  :func:`atomic_outputs` writes the outputs of one run (a fit's result.h5, summary.json and figures)
as one unit: every file into a hidden staging folder first, then all of them renamed into place, so that a failure
while writing (a full disk, a file-size limit) leaves every file of the previous run as it was, never a folder whose
files come from two runs.  The few renames run under a marker file, :data:`INCOMPLETE`, which stays only if they
are cut short (a SIGKILL between two of them) and says that the folder mixes two runs; :func:`check_complete` refuses
to read such a folder back.  Files of one run in folders of the user's choosing (a mesh and its summary) go through
:func:`atomic_output_files`: all are written and synced before any is renamed.

Files are created with the mode ``mode & ~umask`` (0644 under the usual umask 022), like any file a program
writes, not with the 0600 of :func:`tempfile.mkstemp`, so that a shared folder stays readable to its users.
"""

from __future__ import annotations

import contextlib
import errno
import glob
import io
import json
import os
import re
import shutil
import signal
import tempfile
import threading
from pathlib import Path
from typing import Iterator

import h5py

from ..errors import InvalidArgumentError, OutputError, ShspecError

__all__ = ["TEMP_SUFFIX", "INCOMPLETE", "MANIFEST", "atomic_path", "atomic_paths", "atomic_hdf5", "atomic_output",
           "atomic_output_files", "atomic_outputs", "OutputSet", "check_complete", "check_writable", "write_text",
           "write_hdf5", "save_figure", "write_failure", "temporary_files", "umask_mode"]

TEMP_SUFFIX = ".tmp"

#: The file that marks a folder whose outputs :func:`atomic_outputs` was replacing when it was stopped: the folder
#: then mixes two runs.
INCOMPLETE = "INCOMPLETE"

#: The file listing the outputs of the last run :func:`atomic_outputs` wrote into a folder (JSON list of names): what
#: the next run replaces, the files it does not write included.
MANIFEST = ".shspec-outputs.json"


def umask_mode(mode: int = 0o644) -> int:
    """``mode`` with the bits of the process umask cleared (the mode ``open()`` would give a new file)."""
    # os.umask can only be read by setting it; /proc avoids the (brief, process-wide) change where it exists.
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return mode & ~int(line.split()[1], 8)
    except OSError:
        pass
    current = os.umask(0o022)
    os.umask(current)
    return mode & ~current


def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # some platforms and file systems cannot open a folder; the rename is still atomic there
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def _held_interrupts() -> Iterator:
    """Hold SIGINT back while the block runs; yields ``check()``, which hands a held signal to the previous handler
    (Python's raises KeyboardInterrupt) at a point of the caller's choosing.  The exit of the block checks too.

    Only the main thread can set signal handlers (and only it receives them); elsewhere, and when SIGINT is ignored
    or left to the system, nothing is held and ``check()`` does nothing.
    """
    previous = (signal.getsignal(signal.SIGINT) if threading.current_thread() is threading.main_thread() else None)
    if not callable(previous):
        yield lambda: None
        return
    held = []

    def hold(signum, frame):
        held.append((signum, frame))

    def check():
        if held:
            signum, frame = held.pop()
            held.clear()
            previous(signum, frame)

    signal.signal(signal.SIGINT, hold)
    try:
        yield check
    finally:
        signal.signal(signal.SIGINT, previous)
        check()  # also after an error in the block: the user asked to stop


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, mode: int = 0o644) -> Iterator[Path]:
    """Context manager giving a temporary path to write; on success it replaces ``path`` atomically.

    Parameters
    ----------
    path : path-like
        The destination.  Its folder must exist; an existing file there is replaced only when the block succeeds.
    mode : int
        Permission bits of the new file before the umask is applied (default 0o644).

    Yields
    ------
    pathlib.Path
        An empty temporary file ``<path name>.<random>.tmp`` in the same folder.  Write it completely (and close
        it) inside the block; the context manager then fsyncs it, renames it over ``path`` and fsyncs the folder.

    Raises
    ------
    OSError
        Creating, syncing or renaming failed (the temporary file is removed).  Exceptions raised inside the block
        propagate unchanged, after the temporary file is removed.

    Examples
    --------
    >>> with atomic_path(folder / "result.json") as tmp:      # doctest: +SKIP
    ...     tmp.write_text(json.dumps(record))
    """
    with atomic_paths([path], mode=mode) as (tmp,):
        yield tmp


@contextlib.contextmanager
def atomic_paths(paths, *, mode: int = 0o644) -> Iterator[tuple[Path, ...]]:
    """:func:`atomic_path` for several files that belong together, in any folders (a mesh and its summary).

    Every destination gets its temporary file; when the block succeeds all of them are fsynced first and only then
    renamed over their destinations, so that a failure while writing or syncing any of them (a full disk) leaves
    every destination as it was.  Only a SIGKILL between the renames, which follow one another without a write,
    can leave some files new and others old.

    Parameters
    ----------
    paths : sequence of path-like
        Distinct destinations, each in an existing folder.
    mode : int
        As for :func:`atomic_path`.

    Yields
    ------
    tuple of pathlib.Path
        The temporary files, in the order of ``paths``.

    Raises
    ------
    OSError
        As for :func:`atomic_path`; no destination has changed.
    ValueError
        If a destination is given twice.
    """
    paths = [Path(p) for p in paths]
    if len({os.path.abspath(p) for p in paths}) != len(paths):
        raise ValueError(f"a destination is given twice: {[str(p) for p in paths]}")
    with _held_interrupts() as check_interrupt:
        temps: list[Path] = []
        try:
            for path in paths:
                fd, name = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=TEMP_SUFFIX)
                temps.append(Path(name))
                try:
                    os.fchmod(fd, umask_mode(mode))
                finally:
                    os.close(fd)
            check_interrupt()
            yield tuple(temps)
            for tmp in temps:
                with open(tmp, "rb+") as fh:
                    os.fsync(fh.fileno())
            check_interrupt()  # the last moment to give up: after it the new contents replace the old
            for tmp, path in zip(temps, paths):
                os.replace(tmp, path)
        except BaseException:
            for tmp in temps:
                with contextlib.suppress(OSError):
                    tmp.unlink()
            raise
        for folder in dict.fromkeys(path.parent for path in paths):
            _fsync_dir(folder)


@contextlib.contextmanager
def atomic_hdf5(path: str | os.PathLike, *, mode: int = 0o644, **h5py_options) -> Iterator[h5py.File]:
    """Context manager giving a new ``h5py.File`` to fill; on success it replaces ``path`` atomically.

    The file is opened in mode ``"w"`` on a temporary path (see :func:`atomic_path`), closed at the end of the block,
    then fsynced and renamed over ``path``.  ``h5py_options`` go to :class:`h5py.File` (e.g. ``libver``).

    Examples
    --------
    >>> with atomic_hdf5(folder / "table.h5") as f:           # doctest: +SKIP
    ...     f.create_dataset("values", data=values)
    ...     f.attrs["checksum"] = checksum
    """
    with atomic_path(path, mode=mode) as tmp:
        with h5py.File(tmp, "w", **h5py_options) as f:
            yield f


#: Plain words for the errno values a full or protected output location gives.
_REASONS = {errno.ENOSPC: "the disk is full (no space left on device)",
            errno.EDQUOT: "the disk quota is exceeded",
            errno.EROFS: "the file system is read-only",
            errno.EACCES: "permission denied",
            errno.EPERM: "permission denied",
            errno.EFBIG: "the file would exceed the largest file this process may write (ulimit -f)"}

#: h5py reports a failed write of the HDF5 library as a RuntimeError whose text holds the errno.
_HDF5_ERRNO = re.compile(r"errno = (\d+)")


def _errno(exc: BaseException) -> int | None:
    """The errno of a failed write: an OSError's own, or the one h5py puts into the text of its RuntimeError."""
    number = getattr(exc, "errno", None)
    if number is None and isinstance(exc, RuntimeError):
        match = _HDF5_ERRNO.search(str(exc))
        number = int(match.group(1)) if match else None
    return number


def _reason(exc: BaseException) -> str:
    """Why a write failed, in words."""
    number = _errno(exc)
    return (_REASONS.get(number) or getattr(exc, "strerror", None) or (os.strerror(number) if number else None)
            or str(exc) or type(exc).__name__)


def write_failure(path: str | os.PathLike, exc: BaseException, *, existed: bool,
                  error: type[OSError] = OutputError, left: str | None = None) -> OSError:
    """The error to raise when an atomic write of ``path`` failed with ``exc``: it names the file, the reason in
    words and what is left (the previous file intact, or nothing written; or ``left``, in words).  ``existed`` says
    whether ``path`` held a file before the write."""
    if left is None:
        left = f"the previous {Path(path).name} is intact" if existed else "nothing was written"
    out = error(f"cannot write {path}: {_reason(exc)}; {left}")
    # not OSError.filename, which would change the message
    out.errno, out.output_path = _errno(exc), Path(path)
    return out


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, *, mode: int = 0o644, error: type[OSError] = OutputError,
                  hdf5: bool = False) -> Iterator[Path]:
    """:func:`atomic_path` for a command's output: a failure of the file system becomes one ``error``.

    Parameters
    ----------
    path : path-like
        The destination; its folder must exist.
    mode : int
        As for :func:`atomic_path`.
    error : OSError subclass
        What to raise (default :class:`~shspec.errors.OutputError`; checkpoints raise ``CheckpointError``).
    hdf5 : bool
        The block writes HDF5 through h5py, which reports a failed flush (a full disk) as ``RuntimeError``; treat
        that as a write failure too.

    Raises
    ------
    OutputError (or ``error``)
        If the temporary file cannot be created, written, synced or renamed (:func:`write_failure`).  Errors of
        shspec raised inside the block propagate unchanged.
    """
    with atomic_output_files([path], mode=mode, error=error, hdf5=hdf5) as (tmp,):
        yield tmp


@contextlib.contextmanager
def atomic_output_files(paths, *, mode: int = 0o644, error: type[OSError] = OutputError,
                        hdf5: bool = False) -> Iterator[tuple[Path, ...]]:
    """:func:`atomic_paths` for the outputs of a command that writes files in folders of the user's choosing (a
    mesh and its summary): all new, or all as they were, and a failure of the file system becomes one ``error``.

    Parameters
    ----------
    paths : sequence of path-like
        Distinct destinations, each in an existing folder.
    mode, error, hdf5
        As for :func:`atomic_output`.

    Yields
    ------
    tuple of pathlib.Path
        The temporary files, in the order of ``paths``.

    Raises
    ------
    OutputError (or ``error``)
        If a file cannot be created, written, synced or renamed: it names the file and the reason, and says that
        no destination has changed.  Errors of shspec raised inside the block propagate unchanged.
    """
    paths = [Path(p) for p in paths]
    existed = [p.exists() for p in paths]
    caught = (OSError, RuntimeError) if hdf5 else (OSError,)
    temps: tuple[Path, ...] = ()
    try:
        with atomic_paths(paths, mode=mode) as temps:
            yield temps
        return
    except ShspecError as exc:
        # a writer that writes atomically itself (save_mesh) failed on a temporary file: name the destination
        if getattr(exc, "output_path", None) not in temps:
            raise
        failure = exc.__cause__ or exc
    except caught as exc:
        failure = exc
    failed = _failed_destination(failure, paths)
    left = None
    if len(paths) > 1:
        left = f"none of {', '.join(map(str, paths))} has changed" if any(existed) else "nothing was written"
    raise write_failure(failed, failure, existed=existed[paths.index(failed)], error=error, left=left) from failure


def _failed_destination(exc: BaseException, paths: list[Path]) -> Path:
    """The destination whose write failed with ``exc``: the one its file name (a temporary file's) belongs to, or
    the first."""
    name = Path(getattr(exc, "filename", None) or "").name
    for path in paths:
        if name == path.name or name.startswith(path.name + ".") and name.endswith(TEMP_SUFFIX):
            return path
    return paths[0]


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`atomic_output`); returns the path."""
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_hdf5(path: str | os.PathLike, fill, *, error: type[OSError] = OutputError) -> Path:
    """Write the HDF5 file that ``fill(f)`` fills (an ``h5py.File`` open for writing) to ``path`` atomically
    (:func:`atomic_output`); returns the path.

    The file is built in memory and written by Python: HDF5 itself never writes to the disk, where a failed write (a
    full disk, a file-size limit) leaves the library in a state that crashes the process when it closes the file (a
    segmentation fault after h5py's "Exception ignored" messages, under ``prlimit --fsize``).  For files that fit in
    memory twice: results, checkpoints, spectra; not the Gaunt tables (:func:`atomic_hdf5`).
    """
    with atomic_output(path, error=error, hdf5=True) as tmp:
        image = io.BytesIO()
        with h5py.File(image, "w") as f:
            fill(f)
        tmp.write_bytes(image.getbuffer())
    return Path(path)


def save_figure(fig, path: str | os.PathLike, **savefig_options) -> Path:
    """Save a matplotlib figure to ``path`` atomically (:func:`atomic_output`), in the format of its suffix."""
    path = Path(path)
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format=path.suffix.lstrip(".") or "png", **savefig_options)
    return path


class OutputSet:
    """The files of one run being written by :func:`atomic_outputs`: :meth:`path` gives where to write each, and
    :attr:`folder` is where a writer that names its own files (an experiment's figures) puts them."""

    def __init__(self, directory: Path, staging: Path):
        self.directory, self.staging = directory, staging
        self.names: list[str] = []

    @property
    def folder(self) -> Path:
        """The staging folder: every plain file written into it is an output of the run, as if named by
        :meth:`path`."""
        return self.staging

    def _collect(self) -> None:
        """Add the files written straight into :attr:`folder` to :attr:`names`."""
        written = sorted(p.name for p in self.staging.iterdir() if p.name not in self.names and p.name != MANIFEST)
        for name in written:
            if not (self.staging / name).is_file() or name == INCOMPLETE:
                raise ValueError(f"an output is a plain file other than {INCOMPLETE}; {name!r} is not")
        self.names += written

    def path(self, name: str) -> Path:
        """Where to write the output ``name`` (a file name in the folder, written completely inside the block)."""
        if Path(name).name != name or name in (INCOMPLETE, MANIFEST):
            raise ValueError(f"an output is a plain file name other than {INCOMPLETE} and {MANIFEST}, got {name!r}")
        if name not in self.names:
            self.names.append(name)
        return self.staging / name


@contextlib.contextmanager
def atomic_outputs(directory: str | os.PathLike, *, replaces=()) -> Iterator[OutputSet]:
    """Write the outputs of one run into the existing folder ``directory`` as one unit: all of them new, or all as
    they were.

    The block writes each file at ``outputs.path(name)``, in a hidden staging folder inside ``directory``.  When it
    succeeds, the outputs of the previous run there that this one does not write (those :data:`MANIFEST` lists, and
    the names in ``replaces``, which folders written before the manifest existed may hold) are removed, and the new
    ones renamed into place under the marker :data:`INCOMPLETE` (module notes).  Other files of the folder (a
    checkpoint, say) are left alone.

    Raises
    ------
    OutputError
        If a file cannot be written (a full disk, a file-size limit, a read-only folder): it names the file and the
        reason, and nothing of the folder has changed.  Errors of shspec that are no write failure propagate
        unchanged, and so does Ctrl-C; the staging folder is removed either way.
    """
    directory = Path(directory)
    try:
        staging = Path(tempfile.mkdtemp(dir=directory, prefix=".outputs.", suffix=TEMP_SUFFIX))
    except OSError as exc:
        raise OutputError(f"cannot write into {directory}: {_reason(exc)}; nothing was written") from exc
    outputs = OutputSet(directory, staging)
    try:
        try:
            yield outputs
            outputs._collect()
            with open(staging / MANIFEST, "w", encoding="utf-8") as fh:
                fh.write(json.dumps(outputs.names) + "\n")
        except (OSError, RuntimeError) as exc:  # h5py reports a failed write as a RuntimeError
            # the file the block was writing, in the words of the failure under shspec's own error if there is one
            failed = getattr(exc, "output_path", None) or getattr(exc, "filename", None)
            name = Path(failed).name if failed else outputs.names[-1] if outputs.names else None
            what = directory / name if name else f"the outputs of this run into {directory}"
            cause = exc.__cause__ if isinstance(exc, ShspecError) and exc.__cause__ is not None else exc
            raise OutputError(f"cannot write {what}: {_reason(cause)}; the outputs of this run were not "
                              f"written, and those of {directory} are as they were") from exc
        _swap_in(outputs, set(replaces))
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _swap_in(outputs: OutputSet, replaces: set) -> None:
    """Replace the previous run's outputs in ``outputs.directory`` by the staged ones (:func:`atomic_outputs`)."""
    directory = outputs.directory
    try:
        old = set(json.loads((directory / MANIFEST).read_text(encoding="utf-8")))
    except (OSError, ValueError, TypeError):  # none yet, or not one of ours: the names given
        old = set()
    stale = sorted((old | replaces) - set(outputs.names))
    try:
        write_text(directory / INCOMPLETE, f"shspec was replacing the outputs of a run in this folder and was "
                   f"stopped: its files may come from two runs ({', '.join(outputs.names)}). Run it again.\n")
    except OutputError as exc:
        raise OutputError(f"{exc}; the outputs of this run were not written, and those of {directory} are as they "
                          "were") from exc
    try:
        for name in stale:
            with contextlib.suppress(FileNotFoundError):
                (directory / name).unlink()
        for name in [*outputs.names, MANIFEST]:
            os.replace(outputs.staging / name, directory / name)
        _fsync_dir(directory)
        (directory / INCOMPLETE).unlink()
    except OSError as exc:
        raise OutputError(f"cannot put the outputs of this run into {directory}: {_reason(exc)}; the folder now "
                          f"mixes two runs, as its file {INCOMPLETE} says: run again") from exc
    _fsync_dir(directory)


def check_writable(path: str | os.PathLike, *, error: type[OSError] = OutputError) -> None:
    """Fail now if no file can be created beside ``path`` (a missing, read-only or full folder), before a
    computation whose result would otherwise be lost at the write.

    Raises
    ------
    OutputError (or ``error``)
        Naming ``path`` and the reason, as a failed write would (:func:`write_failure`).
    """
    path = Path(path)
    try:
        with tempfile.TemporaryFile(dir=path.parent):
            pass
    except OSError as exc:
        raise write_failure(path, exc, existed=path.exists(), error=error) from exc


def check_complete(path: str | os.PathLike) -> None:
    """Refuse to read the outputs of a run from a folder whose last :func:`atomic_outputs` was cut short.

    Parameters
    ----------
    path : path-like
        A folder of outputs, or one of its files.

    Raises
    ------
    InvalidArgumentError
        If the folder holds the marker :data:`INCOMPLETE`: its files may come from two runs.
    """
    path = Path(path)
    folder = path if path.is_dir() else path.parent
    if (folder / INCOMPLETE).exists():
        raise InvalidArgumentError(f"cannot read {path}: the folder {folder} is marked {INCOMPLETE} (a run was "
                                   "stopped while it replaced its outputs), so its files may come from two runs; run "
                                   "it again")


def temporary_files(path: str | os.PathLike) -> list[Path]:
    """Temporary files left by writes of ``path`` that never finished (or are still running), oldest first."""
    path = Path(path)
    if not path.parent.is_dir():
        return []
    found = []
    for p in path.parent.glob(f"{glob.escape(path.name)}.*{TEMP_SUFFIX}"):
        with contextlib.suppress(OSError):  # a writer may rename or remove it meanwhile
            found.append((p.stat().st_mtime, p))
    return [p for _, p in sorted(found)]
