"""Spectrum and descriptor files: text that ``numpy.loadtxt`` and ``shspec fit --target spectrum:FILE`` read.

Writing.  Every file is plain text with '#' comment lines on top (what it holds, units, the source): the eigenvalue
and Shape-DNA files hold one value per line (what :func:`shspec.spectrum_file.read_spectrum` reads), the heat
trace two columns t, Z(t), the heat kernel signature one row per vertex and one column per time (the times in the
header).

Reading.  :func:`read_eigenvalues` is :func:`shspec.spectrum_file.read_spectrum`, the one reader of every
command: text (one or more columns, with or without a header, CSV), ``.npy`` and ``.json``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.atomic import atomic_output
from ..errors import InvalidArgumentError
from ..spectrum_file import read_spectrum as read_eigenvalues
from .descriptors import heat_kernel_signature, hks_times, shape_dna
from .heat import heat_trace

__all__ = ["read_eigenvalues", "write_values", "write_descriptors", "DESCRIPTOR_SUFFIXES"]

#: File name suffixes of :func:`write_descriptors`, after the stem.
DESCRIPTOR_SUFFIXES = {"eigenvalues": ".eigenvalues.txt", "shapedna": ".shapedna.txt",
                       "heat_trace": ".heat_trace.txt", "hks": ".hks.txt"}


def write_values(path, values, header: str) -> Path:
    """Write (k,) values one per line at full precision under '#' ``header`` lines; returns the path.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import write_values
    >>> write_values("values.txt", np.array([1.0, 2.0]), "two values").name
    'values.txt'
    """
    path = Path(path)
    with atomic_output(path) as tmp:
        np.savetxt(tmp, np.asarray(values, dtype=float).reshape(-1), fmt="%.17g", header=header)
    return path


def write_descriptors(directory, stem: str, eigenvalues, area: float, *, eigenvectors=None, times=None,
                      source: str = "") -> dict:
    """Write the eigenvalues, Shape-DNA, heat trace and (with eigenvectors) HKS of one surface to ``directory``.

    Parameters
    ----------
    directory : str or Path
        An existing folder.
    stem : str
        File name stem; the files are stem + :data:`DESCRIPTOR_SUFFIXES`.
    eigenvalues : (k,) array_like
        λ₀ = 0 first.
    area : float
        Surface area (Shape-DNA's normalization).
    eigenvectors : (n, k) array_like, optional
        M-orthonormal eigenfunctions; without them no HKS file is written.
    times : (p,) array_like, optional
        Times of the heat trace and HKS (default :func:`~shspec.spectral.descriptors.hks_times`).
    source : str
        Where the spectrum came from, for the headers.

    Returns
    -------
    dict
        Descriptor name -> Path written.

    Examples
    --------
    >>> import os
    >>> from shspec.mesh import icosphere, mesh_spectrum
    >>> from shspec.spectral import write_descriptors
    >>> mesh = icosphere(1)
    >>> spec = mesh_spectrum(mesh, 4)
    >>> os.makedirs("descriptors", exist_ok=True)
    >>> sorted(write_descriptors("descriptors", "ico", spec.eigenvalues, mesh.area(), eigenvectors=spec.eigenvectors))
    ['eigenvalues', 'heat_trace', 'hks', 'shapedna']
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise InvalidArgumentError(f"{directory} is not a directory")
    t = hks_times(eigenvalues) if times is None else np.asarray(times, dtype=float)
    k = np.asarray(eigenvalues).size
    origin = f" of {source}" if source else ""
    paths = {
        "eigenvalues": write_values(directory / f"{stem}{DESCRIPTOR_SUFFIXES['eigenvalues']}", eigenvalues,
                                    f"first {k} Laplace-Beltrami eigenvalues{origin}, ascending, 1/area; "
                                    f"area {area:.17g}"),
        "shapedna": write_values(directory / f"{stem}{DESCRIPTOR_SUFFIXES['shapedna']}",
                                 shape_dna(eigenvalues, area),
                                 f"Shape-DNA{origin}: eigenvalue * area (unit-area normalization of Reuter et al. "
                                 f"2006, LaPy normalize_ev 'geometry'); area {area:.17g}"),
    }
    trace = np.stack([t, heat_trace(eigenvalues, t)], axis=1)
    path = directory / f"{stem}{DESCRIPTOR_SUFFIXES['heat_trace']}"
    with atomic_output(path) as tmp:
        np.savetxt(tmp, trace, fmt="%.17g", header=f"heat trace{origin} of the first {k} eigenvalues (no tail): "
                   "t [area units], Z(t) = sum exp(-lambda t)")
    paths["heat_trace"] = path
    if eigenvectors is not None:
        hks = heat_kernel_signature(eigenvalues, eigenvectors, t)
        path = directory / f"{stem}{DESCRIPTOR_SUFFIXES['hks']}"
        with atomic_output(path) as tmp:
            np.savetxt(tmp, hks, fmt="%.10g", header=f"heat kernel signature{origin}: one row per vertex, one "
                       f"column per time t [1/area]; times: {' '.join(f'{x:.10g}' for x in t)}")
        paths["hks"] = path
    return paths
