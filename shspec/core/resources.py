"""Memory and disk a computation needs, checked against what the machine has before anything is allocated.

Each computation states its own :class:`Need` beside what it measures: a table's in
:func:`~shspec.gaunt.table.table_need`, a forward solve's in :func:`~shspec.galerkin.model.forward_need`.  The machine's available memory is ``MemAvailable`` of /proc/meminfo (what the kernel
can give without swapping), else ``os.sysconf('SC_AVPHYS_PAGES')``; when neither exists nothing is checked.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from ..errors import ResourceLimitError

__all__ = ["Need", "available_memory", "free_disk", "file_size_limit", "load_average", "check_need", "human_bytes"]

#: Fraction of the available memory a computation may plan to use (the rest: Python, BLAS workspaces, the OS).
MEMORY_FRACTION = 0.9


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation without swapping, or None if unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def load_average() -> list[float] | None:
    """The machine's 1, 5 and 15 minute load averages (rounded to 0.01), or None where the system has none: recorded
    beside every timing, since a time from a shared machine cannot be judged without it."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def free_disk(path: str | os.PathLike) -> int | None:
    """Free bytes on the file system of ``path`` (or of its nearest existing parent), or None if unknown."""
    p = Path(path).absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        return shutil.disk_usage(p).free
    except OSError:
        return None


def file_size_limit() -> int | None:
    """The largest file this process may write, in bytes (the soft ``RLIMIT_FSIZE``, ``ulimit -f``), or None when
    there is no limit or the system has none."""
    try:
        import resource
    except ImportError:  # Windows
        return None
    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    return None if soft == resource.RLIM_INFINITY else soft


def human_bytes(n: float) -> str:
    """``n`` bytes as '3.2 MiB', '11.7 GiB', ..."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.0f} B" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return ""


@dataclass(frozen=True)
class Need:
    """Resources of one computation, in bytes."""

    what: str
    memory: int
    disk: int = 0  # written to one file


def _largest_fitting(lmax: int, lmax_factor: int, memory: int, estimate) -> tuple[int, int] | None:
    """The largest (Lb', La') with La'/Lb' as La/Lb whose ``estimate`` fits ``memory``, by bisection."""
    ratio = lmax_factor / lmax if lmax else 0.0
    lo, hi = 0, lmax
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if estimate(mid, min(round(ratio * mid), 2 * mid)).memory <= memory:
            lo = mid
        else:
            hi = mid - 1
    return (lo, min(round(ratio * lo), 2 * lo)) if lo >= 1 else None


def check_need(need: Need, *, disk_path: str | os.PathLike | None = None, limits: tuple[int, int] | None = None,
               estimate=None) -> None:
    """Raise :class:`ResourceLimitError` when ``need`` exceeds the available memory, or the free disk at ``disk_path``
    or the largest file the process may write (:func:`file_size_limit`).

    ``limits`` (Lb, La) and ``estimate`` (a function (Lb, La) -> Need) let the message say which band limits fit.
    """
    memory = available_memory()
    if memory is not None and need.memory > MEMORY_FRACTION * memory:
        hint = ""
        if limits is not None and estimate is not None:
            fits = _largest_fitting(*limits, int(MEMORY_FRACTION * memory), estimate)
            hint = (f"; at the same ratio La/Lb the largest that fits is Lb = {fits[0]}, La = {fits[1]}"
                    if fits else "; nothing of that ratio fits")
        raise ResourceLimitError(f"{need.what} needs {human_bytes(need.memory)} of memory; this machine has "
                                 f"{human_bytes(memory)} available{hint}")
    if need.disk and disk_path is not None:
        free = free_disk(disk_path)
        if free is not None and need.disk > free:
            raise ResourceLimitError(f"{need.what} needs {human_bytes(need.disk)} on disk; {disk_path} has "
                                     f"{human_bytes(free)} free")
        largest = file_size_limit()
        if largest is not None and need.disk > largest:
            # a write past the limit fails with EFBIG, which h5py turns into errors at the close of the file
            raise ResourceLimitError(f"{need.what} needs a file of {human_bytes(need.disk)}; this process may write "
                                     f"files of at most {human_bytes(largest)} (ulimit -f)")
