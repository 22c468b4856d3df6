"""The one reader of spectrum files, used by every command (``fit``, ``topology``, ``validate``, ...).

Formats, chosen by the file's suffix:

* ``.npy``: a real 1-D array of eigenvalues, or a 2-D array read by the column rules below.
* ``.json``: a list of numbers, or an object with an ``"eigenvalues"`` list and optionally an ``"errors"`` list of
  the same length (``shspec mesh-spectrum --json`` writes such an object).
* anything else is text (``.txt``, ``.csv``, ``.dat``, what ``shspec mesh-spectrum`` prints or writes), UTF-8 with
  or without a byte-order mark.  ``#`` starts a comment; blank lines are skipped; fields are separated by commas
  (CSV) or white space.  All values on one line are one spectrum.  Otherwise the columns say what they hold:

  - one column: the eigenvalues;
  - two: index, eigenvalue (what ``shspec mesh-spectrum MESH`` prints, and what many tools write);
  - three: index, eigenvalue, error;
  - with a header line (its first line with a field that is not a number), the columns are found by name:
    ``eigenvalue`` (or ``eigenvalues``, ``lambda``, ``value``), optionally ``error`` (or ``sigma``,
    ``uncertainty``, ``std``); a header of a single column names the eigenvalues whatever its name.

The *error* column, when there is one, is the absolute uncertainty of each eigenvalue; ``shspec topology`` propagates
it (as its largest relative error, unless ``--noise`` is given) and fits weigh each eigenvalue by it.  The reader
checks it once for every command: after λ₀ each error must be finite, > 0 and below its eigenvalue.

λ₀ = 0 is prepended when the file starts above 0 (relative to its largest value, 1e-8).  A negative value, a value
that is not a finite number, or a descent is refused: the error names the file and, for text, the line and column.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .core.atomic import atomic_output, write_text
from .errors import InvalidArgumentError

__all__ = ["SpectrumFile", "check_spectrum_path", "read_spectrum_file", "read_spectrum", "write_spectrum",
           "SPECTRUM_SUFFIXES"]

#: Suffixes :func:`write_spectrum` writes (and the reader reads; any other suffix is read as text).
SPECTRUM_SUFFIXES = (".txt", ".csv", ".json", ".npy")

#: Header names of the eigenvalue and error columns (lower case).
VALUE_NAMES = ("eigenvalue", "eigenvalues", "lambda", "value")
ERROR_NAMES = ("error", "errors", "sigma", "uncertainty", "std")

#: A first value at most this fraction of the largest (in magnitude) is λ₀ = 0 written with rounding.
ZERO_TOL = 1e-8


@dataclass(frozen=True)
class SpectrumFile:
    """A spectrum read from a file.

    Attributes
    ----------
    path : Path
    eigenvalues : (k,) ndarray
        λ₀ = 0 first, ascending.
    errors : (k,) ndarray or None
        Absolute uncertainty of each eigenvalue, when the file has an error column (0 for a prepended λ₀).
    """

    path: Path
    eigenvalues: np.ndarray
    errors: np.ndarray | None = None


class _Cell:
    """Where a value came from, for messages: line and column in a text file, or the entry of an array."""

    def __init__(self, line: int | None = None, column: int | None = None, entry: int | None = None):
        self.line, self.column, self.entry = line, column, entry

    def __str__(self) -> str:
        if self.line is not None:
            return f"line {self.line}, column {self.column}"
        return f"entry {self.entry}"


def _fail(path: Path, text: str) -> InvalidArgumentError:
    return InvalidArgumentError(f"{path}: {text}")


def _number(path: Path, field: str, cell: _Cell) -> float:
    try:
        return float(field)
    except ValueError:
        raise _fail(path, f"{cell}: {field!r} is not a number") from None


def _split(line: str) -> list[str]:
    return [f.strip() for f in line.split(",")] if "," in line else line.split()


def _is_number(field: str) -> bool:
    try:
        float(field)
    except ValueError:
        return False
    return True


def _text_columns(path: Path):
    """(values, errors, cells of the values, cells of the errors) of a text file (module notes)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise _fail(path, f"not a text spectrum file (not UTF-8: {exc.reason} at byte {exc.start}); a NumPy "
                    "array must be named .npy") from None
    except OSError as exc:
        raise InvalidArgumentError(f"cannot read a spectrum from {path}: {exc.strerror or exc}") from None
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        fields = _split(line.split("#", 1)[0])
        if fields:
            rows.append((number, fields))
    if not rows:
        return [], None, [], None
    header = None
    if not all(_is_number(f) for f in rows[0][1]):
        header_line, header = rows[0][0], [f.strip().strip('"').lower() for f in rows[0][1]]
        rows = rows[1:]
    if header is not None:
        value_col = next((header.index(n) for n in VALUE_NAMES if n in header), 0 if len(header) == 1 else None)
        if value_col is None:
            if "lambda_max" in header or "nvertices" in header:
                raise _fail(path, "a table of meshes (the spectra.csv of 'shspec mesh-spectrum --out') lists "
                            "lambda_1 and lambda_max only; read a mesh's NAME.eigenvalues.txt instead")
            raise _fail(path, f"line {header_line}: no eigenvalue column among {', '.join(header)} (name it one of "
                        f"{', '.join(VALUE_NAMES)})")
        error_col = next((header.index(n) for n in ERROR_NAMES if n in header), None)
        width = len(header)
    elif len(rows) == 1:  # every value on one line
        number, fields = rows[0]
        cells = [_Cell(number, c + 1) for c in range(len(fields))]
        return [_number(path, f, c) for f, c in zip(fields, cells)], None, cells, None
    else:
        width = len(rows[0][1])
        if width > 3:
            raise _fail(path, f"{width} columns on line {rows[0][0]}; a spectrum file has one value per line, two "
                        "columns (index, eigenvalue) or three (index, eigenvalue, error), or a header naming them")
        value_col, error_col = (0, None) if width == 1 else (1, 2 if width == 3 else None)
    values, errors, cells, error_cells, index = [], [], [], [], []
    for number, fields in rows:
        if len(fields) != width:
            raise _fail(path, f"line {number} has {len(fields)} columns, the lines before it {width}")
        cell = _Cell(number, value_col + 1)
        values.append(_number(path, fields[value_col], cell))
        cells.append(cell)
        if error_col is not None:
            ecell = _Cell(number, error_col + 1)
            errors.append(_number(path, fields[error_col], ecell))
            error_cells.append(ecell)
        if header is None and width > 1:
            index.append((_number(path, fields[0], _Cell(number, 1)), f"line {number}"))
    if index:
        _check_index(path, index, width)
    return values, errors if error_col is not None else None, cells, error_cells if error_col is not None else None


def _check_index(path: Path, index: list, width: int) -> None:
    """The first of two or three columns must count 0, 1, 2, ... (or from 1): else the columns mean something else."""
    start = index[0][0]
    for k, (value, where) in enumerate(index):
        if start not in (0.0, 1.0) or value != start + k:
            raise _fail(path, f"{width} columns, read as index, eigenvalue{', error' if width == 3 else ''}; but "
                        f"column 1 is not an index counting from 0 or 1 ({where} holds {value:g}); give one "
                        "eigenvalue per line, or a header naming the columns")


def _array_columns(path: Path, data: np.ndarray):
    """(values, errors, cells, error cells) of an array (the column rules of text without a header)."""
    if np.iscomplexobj(data):
        raise _fail(path, f"complex values (dtype {data.dtype}); eigenvalues are real: save the real part "
                    "explicitly if it is what you mean")
    if data.dtype.kind not in "biuf":
        raise _fail(path, f"an array of {data.dtype} ({data.dtype.kind!r}), not of numbers")
    data = np.asarray(data, dtype=float)
    if data.ndim == 1 or (data.ndim == 2 and 1 in data.shape and data.shape[1] > 3):
        flat = data.ravel()
        return list(flat), None, [_Cell(entry=i) for i in range(flat.size)], None
    if data.ndim != 2 or data.shape[1] > 3:
        raise _fail(path, f"an array of shape {data.shape}; expected (k,), or (k, 1), (k, 2) index and eigenvalue, "
                    "(k, 3) index, eigenvalue and error")
    width = data.shape[1]
    if width > 1:
        _check_index(path, [(v, f"row {i}") for i, v in enumerate(data[:, 0])], width)
    cells = [_Cell(entry=i) for i in range(data.shape[0])]
    values = list(data[:, 0 if width == 1 else 1])
    return values, (list(data[:, 2]) if width == 3 else None), cells, (cells if width == 3 else None)


def _json_columns(path: Path):
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except json.JSONDecodeError as exc:
        raise _fail(path, f"line {exc.lineno}, column {exc.colno}: not valid JSON ({exc.msg})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InvalidArgumentError(f"cannot read a spectrum from {path}: {getattr(exc, 'strerror', None) or exc}") \
            from None
    errors = None
    if isinstance(data, dict):
        if "eigenvalues" not in data:
            keys = ", ".join(repr(k) for k in data) or "none"
            raise _fail(path, f"a JSON object needs an 'eigenvalues' list (and optionally 'errors'); its keys: {keys}")
        errors = data.get("errors")
        data = data["eigenvalues"]
    if not isinstance(data, list):
        raise _fail(path, f"the eigenvalues must be a JSON list of numbers, got {type(data).__name__}")
    if errors is not None and (not isinstance(errors, list) or len(errors) != len(data)):
        raise _fail(path, f"'errors' must be a list as long as 'eigenvalues' ({len(data)})")

    def numbers(items, what):
        out = []
        for i, v in enumerate(items):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise _fail(path, f"{what} {i} is {v!r}, not a number")
            out.append(float(v))
        return out

    cells = [_Cell(entry=i) for i in range(len(data))]
    return (numbers(data, "eigenvalue"), None if errors is None else numbers(errors, "error"), cells,
            None if errors is None else cells)


def check_spectrum_path(path) -> Path:
    """``path`` as a spectrum file to read: the checks of :func:`read_spectrum_file` that need not open it, for a
    command to make before any long work.

    Raises
    ------
    InvalidArgumentError
        ``path`` is not a path, names nothing (or a link to nothing), or a directory.
    """
    if not isinstance(path, (str, Path)) or not str(path):
        raise InvalidArgumentError(f"a spectrum file is a path, got {path!r}")
    path = Path(path)
    if path.is_dir():
        raise InvalidArgumentError(f"{path} is a directory, not a spectrum file")
    if not path.exists():
        gone = f" (a symbolic link to {path.readlink()}, which does not exist)" if path.is_symlink() else ""
        raise InvalidArgumentError(f"{path}: no such spectrum file{gone}")
    return path


def read_spectrum_file(path) -> SpectrumFile:
    """Read a spectrum file in any of the formats of the module notes.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    SpectrumFile
        Eigenvalues (λ₀ = 0 first) and, when the file has them, their errors.

    Raises
    ------
    InvalidArgumentError
        If the file cannot be read or its content is not a spectrum; the message names the file and, in text files,
        the line and column of the first bad value.
    """
    path = check_spectrum_path(path)
    suffix = path.suffix.lower()
    if suffix == ".npy":
        try:
            data = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:
            raise InvalidArgumentError(f"cannot read a spectrum from {path}: {exc}") from None
        values, errors, cells, error_cells = _array_columns(path, data)
    elif suffix == ".json":
        values, errors, cells, error_cells = _json_columns(path)
    else:
        values, errors, cells, error_cells = _text_columns(path)
    if not values:
        raise InvalidArgumentError(f"{path} holds no eigenvalues")
    lam = np.array(values, dtype=float)
    for i in np.flatnonzero(~np.isfinite(lam))[:1]:
        raise _fail(path, f"eigenvalue {i} is {lam[i]} ({cells[i]}); every value must be finite")
    scale = np.max(np.abs(lam))
    for i in np.flatnonzero(lam < -ZERO_TOL * scale)[:1]:
        raise _fail(path, f"eigenvalue {i} is {lam[i]:g} ({cells[i]}); Laplace-Beltrami eigenvalues are never "
                    "negative (lambda_0 = 0 belongs to the constants)")
    drop = np.flatnonzero(np.diff(lam) < -1e-12 * scale)
    if drop.size:
        i = int(drop[0])
        raise InvalidArgumentError(f"{path} is not ascending: eigenvalue {i + 1} ({lam[i + 1]:.6g}) is below "
                                   f"eigenvalue {i} ({lam[i]:.6g}) ({cells[i + 1]})")
    err = None
    if errors is not None:
        err = np.array(errors, dtype=float)
        for i in np.flatnonzero(~(np.isfinite(err) & (err >= 0)))[:1]:
            raise _fail(path, f"error {i} is {err[i]} ({error_cells[i]}); errors must be finite and >= 0")
        first = 0 if lam[0] > ZERO_TOL * lam[-1] else 1  # λ₀ = 0 is exact whatever the file says its error is
        for i in first + np.flatnonzero(~((err[first:] > 0) & (err[first:] < lam[first:])))[:1]:
            raise _fail(path, f"error {i} is {err[i]:g} ({error_cells[i]}) for the eigenvalue {lam[i]:g}; the error "
                        "of every eigenvalue after lambda_0 must be > 0 (a fit divides by it; leave the column out "
                        "for exact values) and below the eigenvalue (a relative error of 1 or more leaves nothing of "
                        "it)")
    if lam[0] > ZERO_TOL * lam[-1]:
        lam = np.concatenate([[0.0], lam])
        err = None if err is None else np.concatenate([[0.0], err])
    lam[0] = 0.0
    return SpectrumFile(path, lam, err)


def read_spectrum(path) -> np.ndarray:
    """The eigenvalues of a spectrum file (:func:`read_spectrum_file`): (k,) array, λ₀ = 0 first, ascending.

    Raises
    ------
    InvalidArgumentError
        As :func:`read_spectrum_file`.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.fitting import read_spectrum
    >>> np.savetxt("round.txt", [0.0, 2.0, 2.0, 2.0, 6.0])
    >>> read_spectrum("round.txt")
    array([0., 2., 2., 2., 6.])
    """
    return read_spectrum_file(path).eigenvalues


def write_spectrum(path, eigenvalues, header: str = "") -> Path:
    """Write eigenvalues at full precision in the format of ``path``'s suffix, atomically, so that
    :func:`read_spectrum` gives them back exactly: ``.txt`` one per line under '#' ``header`` lines, ``.csv`` an
    ``index,eigenvalue`` table, ``.json`` ``{"eigenvalues": [...]}`` (with ``"header"``), ``.npy`` the array.

    Raises
    ------
    InvalidArgumentError
        If the suffix is none of :data:`SPECTRUM_SUFFIXES`.
    OutputError
        If the file cannot be written (the previous one is then intact).
    """
    path = Path(path)
    lam = np.asarray(eigenvalues, dtype=float).reshape(-1)
    suffix = path.suffix.lower()
    if suffix == ".txt":
        with atomic_output(path) as tmp:
            np.savetxt(tmp, lam, fmt="%.17g", header=header)
    elif suffix == ".csv":
        comment = "".join(f"# {line}\n" for line in header.splitlines())
        write_text(path, comment + "index,eigenvalue\n" + "".join(f"{i},{v!r}\n" for i, v in enumerate(lam.tolist())))
    elif suffix == ".json":
        write_text(path, json.dumps({"header": header, "eigenvalues": lam.tolist()}, indent=1) + "\n")
    elif suffix == ".npy":
        with atomic_output(path) as tmp, open(tmp, "wb") as fh:
            np.save(fh, lam)
    else:
        raise InvalidArgumentError(f"{path}: a spectrum file ends in one of {', '.join(SPECTRUM_SUFFIXES)}")
    return path
