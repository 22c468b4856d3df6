"""Writing results: output directories and CSV tables, one way for every command and experiment."""

from __future__ import annotations

import csv
import os
from pathlib import Path

from .atomic import atomic_output
from ..errors import OutputError

__all__ = ["ensure_directory", "write_csv"]


def ensure_directory(path: str | os.PathLike, *, error: type[OSError] = OutputError,
                     what: str = "output directory") -> Path:
    """Create the directory ``path`` (and its parents) if needed and return it.

    Parameters
    ----------
    path : path-like
    error : OSError subclass
        What to raise (an :class:`OutputError` unless the caller's domain has its own, such as the cache's).
    what : str
        How the message names the directory.

    Raises
    ------
    OutputError (or ``error``)
        If a file stands in the way or the directory cannot be created.
    """
    out = Path(path)
    if out.is_symlink() and not out.exists():  # mkdir would say only "File exists"
        raise error(f"the {what} {out} is a symbolic link to {os.readlink(out)}, which does not exist; create that "
                    "folder or remove the link")
    if out.exists() and not out.is_dir():
        raise error(f"the {what} {out} is a file, not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise error(f"cannot create the {what} {out}: {exc.strerror or exc}") from exc
    return out


def write_csv(path: str | os.PathLike, rows: list[dict], fields: list[str] | None = None) -> Path:
    """Write rows (dicts) as a CSV file with a header line: the columns ``fields`` (default: the keys of the first
    row, in order); a row without a column leaves it empty.

    Raises
    ------
    OutputError
        If there are no rows or the file cannot be written.
    """
    path = Path(path)
    if not rows:
        raise OutputError(f"no rows to write to {path}")
    with atomic_output(path) as tmp, open(tmp, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]) if fields is None else fields, restval="")
        writer.writeheader()
        writer.writerows(rows)
    return path
