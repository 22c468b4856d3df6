"""Spectra, descriptors and topology of many meshes at once, one job per mesh on any Executor.

:func:`mesh_job` is the unit of work (load, validate as a closed manifold of any genus, cotan spectrum, and on
request the heat kernel signature and the heat-trace topology); it returns arrays instead of writing files, so that
workers of a remote Dask cluster need no access to the output folder (they do read the mesh files: give paths
they can see).  :func:`run_batch` submits one job per mesh
to an executor (:func:`shspec.core.parallel.make_executor`), writes each mesh's files as its result arrives (tqdm
progress) into a staging folder, and one CSV table with a row per mesh in the order given; the files of the batch
replace those of the previous one in the output folder when all are written (one unit: a failure leaves it as it was).
"""

from __future__ import annotations

import json
import time
from concurrent.futures import as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..core.atomic import atomic_outputs, write_text
from ..core.checks import check_int
from ..errors import InvalidArgumentError
from ..core.outputs import ensure_directory, write_csv
from ..mesh.cotan import MASS_KINDS
from ..mesh.eigen import mesh_spectrum
from ..mesh.builtin import resolve_mesh_path
from ..mesh.mesh_files import MESH_FORMATS, load_mesh
from ..core.parallel import SerialExecutor
from .descriptors import hks_times
from .descriptor_files import write_descriptors, write_values
from .topology import TopologyEstimate, estimate_topology

__all__ = ["MeshJobResult", "mesh_job", "collect_meshes", "run_batch", "TABLE_NAME"]

#: Name of the table :func:`run_batch` writes into the output folder.
TABLE_NAME = "spectra.csv"


@dataclass(frozen=True)
class MeshJobResult:
    """What one mesh job computed.

    Attributes
    ----------
    name : str
        File stem (the output files' stem).
    path : str
    nvertices, nfaces : int
    area : float
        Mesh area (length unit²).
    eigenvalues : (k,) ndarray
        Cotan eigenvalues, λ₀ = 0 first (a degenerate group cut at K is completed, so k ≥ K).
    eigenvectors : (n, k) ndarray or None
        M-orthonormal, kept only when descriptors were asked for.
    topology : TopologyEstimate or None
    seconds : float
        Wall time of the job.

    Examples
    --------
    >>> from shspec.mesh import icosphere, save_mesh
    >>> from shspec.spectral import mesh_job
    >>> result = mesh_job(save_mesh(icosphere(1), "a.obj"), 5)
    >>> type(result).__name__, result.name, result.topology is None
    ('MeshJobResult', 'a', True)
    """

    name: str
    path: str
    nvertices: int
    nfaces: int
    area: float
    eigenvalues: np.ndarray
    eigenvectors: np.ndarray | None
    topology: TopologyEstimate | None
    seconds: float


def mesh_job(path, numeig: int, mass: str = "lumped", *, descriptors: bool = False,
             topology: bool = False) -> MeshJobResult:
    """Cotan spectrum (and eigenvectors, topology) of one mesh file; picklable for process pools and Dask.

    Parameters
    ----------
    path : str or Path
        Mesh file; validated as closed, manifold, oriented and connected, of any genus.
    numeig : int
        Number of eigenvalues K.
    mass : {"lumped", "consistent"}
    descriptors : bool
        Keep the eigenvectors (for the heat kernel signature).
    topology : bool
        Estimate χ and the genus from the heat trace, with the mesh's area known.

    Examples
    --------
    >>> from shspec.mesh import icosphere, save_mesh
    >>> from shspec.spectral import mesh_job
    >>> result = mesh_job(save_mesh(icosphere(1), "a.obj"), 5)
    >>> result.nvertices, result.eigenvalues.size       # whole multiplets: 9, not 5
    (42, 9)
    """
    start = time.perf_counter()
    path = Path(path)
    mesh = load_mesh(path, require_genus0=False)
    spec = mesh_spectrum(mesh, numeig, mass)
    lam = spec.eigenvalues.copy()
    lam[0] = 0.0  # the solver's λ₀ is 0 to rounding; files and estimators want exactly 0
    area = mesh.area()
    est = estimate_topology(lam, area) if topology else None
    return MeshJobResult(path.stem, str(path), mesh.nvertices, mesh.nfaces, area, lam,
                         spec.eigenvectors if descriptors else None, est, time.perf_counter() - start)


def collect_meshes(items) -> list[Path]:
    """Mesh files from files, folders (a folder gives its files with a mesh suffix, sorted by name) and the names of
    meshes shipped with shspec (``bunny_600``).

    Raises
    ------
    InvalidArgumentError
        If an item does not exist, a folder holds no mesh, a file is not a mesh format, or two meshes share a
        stem (their output files would collide).

    Examples
    --------
    >>> import os
    >>> from shspec.mesh import icosphere, save_mesh
    >>> from shspec.spectral import collect_meshes
    >>> os.makedirs("meshes", exist_ok=True)
    >>> _ = save_mesh(icosphere(1), "meshes/a.obj"), save_mesh(icosphere(2), "meshes/b.obj")
    >>> [path.name for path in collect_meshes(["meshes"])]     # folders are searched for mesh files
    ['a.obj', 'b.obj']
    """
    paths = []
    for item in items:
        item = resolve_mesh_path(item)
        if item.is_dir():
            found = sorted(p for p in item.iterdir() if p.is_file() and p.suffix.lower() in MESH_FORMATS)
            if not found:
                raise InvalidArgumentError(f"{item}: a folder without mesh files ({', '.join(MESH_FORMATS)})")
            paths += found
        elif item.is_file():
            if item.suffix.lower() not in MESH_FORMATS:
                raise InvalidArgumentError(f"{item}: unsupported mesh format {item.suffix!r}")
            paths.append(item)
        else:
            raise InvalidArgumentError(f"{item}: no such file or folder")
    if not paths:
        raise InvalidArgumentError("no meshes given")
    seen = {}
    for p in paths:
        if p.stem in seen:
            raise InvalidArgumentError(f"{seen[p.stem]} and {p} share the name {p.stem!r}: their outputs would "
                                       "collide")
        seen[p.stem] = p
    return paths


def _write(out: Path, res: MeshJobResult, descriptors: bool) -> None:
    if descriptors:
        times = hks_times(res.eigenvalues)
        write_descriptors(out, res.name, res.eigenvalues, res.area, eigenvectors=res.eigenvectors, times=times,
                          source=res.path)
    else:
        write_values(out / f"{res.name}.eigenvalues.txt", res.eigenvalues,
                     f"first {res.eigenvalues.size} cotan Laplace-Beltrami eigenvalues of {res.path}, ascending, "
                     f"1/area; area {res.area:.17g}")
    if res.topology is not None:
        write_text(out / f"{res.name}.topology.json", json.dumps(res.topology.to_dict(), indent=1) + "\n")


def _row(res: MeshJobResult) -> dict:
    row = {"name": res.name, "path": res.path, "nvertices": res.nvertices, "nfaces": res.nfaces,
           "area": repr(res.area), "numeig": res.eigenvalues.size, "lambda_1": repr(float(res.eigenvalues[1])),
           "lambda_max": repr(float(res.eigenvalues[-1])), "seconds": f"{res.seconds:.3f}"}
    if res.topology is not None:
        t = res.topology
        row.update({"euler_characteristic": f"{t.euler_characteristic:.4f}",
                    "euler_characteristic_error": f"{t.euler_characteristic_error:.4f}", "genus": t.genus,
                    "confident": t.confident})
    return row


def run_batch(paths, out, numeig: int, *, mass: str = "lumped", descriptors: bool = False, topology: bool = False,
              executor=None, progress: bool = True) -> list[MeshJobResult]:
    """Spectra of many meshes: one job each on ``executor``, files per mesh and a CSV table in ``out``.

    Parameters
    ----------
    paths : sequence of str or Path
        Mesh files and folders (:func:`collect_meshes`).
    out : str or Path
        Output folder (created): STEM.eigenvalues.txt per mesh (and with ``descriptors`` STEM.shapedna.txt,
        STEM.heat_trace.txt, STEM.hks.txt; with ``topology`` STEM.topology.json) and :data:`TABLE_NAME`.  The files
        are one unit (:func:`shspec.core.atomic.atomic_outputs`): they replace those of an earlier batch in ``out``
        only when every mesh is done and written, so that a failure leaves ``out`` as it was.
    numeig : int
        Eigenvalues per mesh.
    mass, descriptors, topology
        As for :func:`mesh_job`.
    executor : concurrent.futures.Executor, optional
        Where the jobs run (default: serially, here).
    progress : bool
        Show a tqdm bar.

    Returns
    -------
    list of MeshJobResult
        In the order of the meshes (not of completion).

    Examples
    --------
    >>> import os
    >>> from shspec.mesh import icosphere, save_mesh
    >>> from shspec.spectral import run_batch
    >>> os.makedirs("batch_in", exist_ok=True)
    >>> _ = save_mesh(icosphere(1), "batch_in/a.obj"), save_mesh(icosphere(2), "batch_in/b.obj")
    >>> results = run_batch(["batch_in"], "batch_out", 5, progress=False)
    >>> len(results), sorted(os.listdir("batch_out"))       # with the list of the run's outputs
    (2, ['.shspec-outputs.json', 'a.eigenvalues.txt', 'b.eigenvalues.txt', 'spectra.csv'])
    """
    meshes = collect_meshes(paths)
    numeig = check_int(numeig, "numeig", minimum=1)
    if mass not in MASS_KINDS:
        raise InvalidArgumentError(f"mass kind must be one of {MASS_KINDS}, got {mass!r}")
    out = ensure_directory(out)
    executor = executor if executor is not None else SerialExecutor()
    futures = {executor.submit(mesh_job, str(p), numeig, mass, descriptors=descriptors, topology=topology): i
               for i, p in enumerate(meshes)}
    results = [None] * len(meshes)
    with atomic_outputs(out) as files, tqdm(total=len(meshes), desc="mesh spectra", unit="mesh",
                                            disable=not progress) as bar:
        for future in as_completed(futures):
            res = future.result()
            _write(files.folder, res, descriptors)
            results[futures[future]] = res
            bar.update()
        rows = [_row(r) for r in results]
        write_csv(files.folder / TABLE_NAME, rows, list(max(rows, key=len).keys()))
    return results
