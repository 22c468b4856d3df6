"""Reading and writing triangle meshes (OBJ, PLY, OFF, STL) through trimesh."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh

from ..core.atomic import atomic_output
from ..errors import InvalidArgumentError, MeshError
from .builtin import BUILTIN_MESHES, resolve_mesh_path
from .triangle_mesh import TriangleMesh
from .validate import validate_mesh

__all__ = ["load_mesh", "save_mesh", "mesh_format", "MESH_FORMATS"]

#: File suffixes accepted by :func:`load_mesh` and :func:`save_mesh`.
MESH_FORMATS = (".obj", ".ply", ".off", ".stl")


def mesh_format(path, file_type: str | None = None) -> str:
    """The format of the mesh file ``path``: ``file_type`` if given, else its suffix (lower case, with the dot).

    Raises
    ------
    InvalidArgumentError
        If it is not one of :data:`MESH_FORMATS`.

    Examples
    --------
    >>> from shspec.mesh.mesh_files import mesh_format
    >>> mesh_format("Bunny.OBJ"), mesh_format("bunny.obj.tmp", "ply")
    ('.obj', '.ply')
    """
    path = Path(path)
    suffix = path.suffix.lower() if file_type is None else "." + str(file_type).lower().lstrip(".")
    if suffix not in MESH_FORMATS:
        raise InvalidArgumentError(f"{path}: unsupported mesh format {suffix!r}; use one of {MESH_FORMATS}")
    return suffix


def load_mesh(path, *, validate: bool = True, merge_vertices: bool | None = None,
              require_genus0: bool = True) -> TriangleMesh:
    """Read a triangle mesh, keeping the stored vertex order.

    Parameters
    ----------
    path : str or Path
        An ``.obj``, ``.ply``, ``.off`` or ``.stl`` file, or the name of a mesh shipped with shspec
        (:data:`~shspec.mesh.builtin.BUILTIN_MESHES`: ``"bunny_600"``, ``"spot"``, ...).
    validate : bool, default True
        Run :func:`~shspec.mesh.validate.validate_mesh` (closed, manifold, oriented, one component, genus 0).
    merge_vertices : bool or None
        Merge vertices at identical positions (weld a "vertex soup" whose faces do not share vertices).  None
        (default): only for STL, which cannot share vertices.  When validation fails and the file has duplicate
        positions, the error says so and suggests this option.
    require_genus0 : bool, default True
        With ``validate``, also require genus 0; False accepts closed manifold meshes of any genus (for spectra and
        their heat-trace invariants; cMCF and the fits need genus 0).

    Returns
    -------
    TriangleMesh
        n vertices (n, 3) and m faces (m, 3).

    Raises
    ------
    InvalidArgumentError
        If the suffix is not a supported format.
    MeshError
        If the file is missing, unreadable, holds no triangles, or fails validation.

    Notes
    -----
    trimesh is called with ``process=False`` so that vertices are neither merged nor reordered.  STL stores
    triangles without shared vertices, so for STL coincident vertices are merged (trimesh's ``process=True``);
    otherwise every STL file would load as a soup of disconnected triangles.

    Examples
    --------
    >>> from shspec.mesh import load_mesh
    >>> load_mesh("pebble")                 # a shipped mesh by name, or any .obj/.ply/.off/.stl path
    TriangleMesh(642 vertices, 1280 faces)
    """
    if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
        raise InvalidArgumentError(f"a mesh file is a non-empty path, got {path!r}")
    path = resolve_mesh_path(path)
    if not path.suffix:
        raise InvalidArgumentError(f"{path}: neither a mesh file ({', '.join(MESH_FORMATS)}) nor a mesh shipped with "
                                   f"shspec ({', '.join(BUILTIN_MESHES)})")
    mesh_format(path)
    if not path.is_file():
        raise MeshError(f"{path}: no such file")
    process = path.suffix.lower() == ".stl" if merge_vertices is None else bool(merge_vertices)
    try:
        # unprocessed first: trimesh's processing drops faces at NaN vertices, which would then be reported as holes
        loaded = trimesh.load(path, process=False, force="mesh")
    except Exception as exc:  # trimesh raises many unrelated types on malformed input
        raise MeshError(f"{path}: cannot read mesh: {exc}") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshError(f"{path}: holds no triangles")
    vertices = np.asarray(loaded.vertices)
    bad = np.flatnonzero(~np.all(np.isfinite(vertices), axis=1))
    if bad.size:
        raise MeshError(f"{path}: {bad.size} vertices have NaN or inf coordinates (first: vertex {bad[0]} = "
                        f"{vertices[bad[0]].tolist()})")
    if process:
        loaded = trimesh.Trimesh(vertices, np.asarray(loaded.faces), process=True)
    mesh = TriangleMesh(np.asarray(loaded.vertices), np.asarray(loaded.faces))
    if not validate:
        return mesh
    try:
        return validate_mesh(mesh, genus0=require_genus0)
    except MeshError as exc:
        duplicates = mesh.nvertices - np.unique(mesh.vertices, axis=0).shape[0]
        if duplicates and not process:
            raise MeshError(f"{path}: {exc}; {duplicates} of its {mesh.nvertices} vertices repeat the position of "
                            "another (faces that do not share their vertices?): weld them (load_mesh(..., "
                            "merge_vertices=True), 'shspec cmcf --merge-vertices', or save the mesh as STL, which is "
                            "always welded)") from None
        raise


def save_mesh(mesh: TriangleMesh, path, *, file_type: str | None = None) -> Path:
    """Write ``mesh`` to ``path``; the format follows the suffix (``.obj``, ``.ply``, ``.off``, ``.stl``).

    Parameters
    ----------
    mesh : TriangleMesh
    path : path-like
    file_type : str, optional
        The format (one of :data:`MESH_FORMATS`) when the suffix of ``path`` does not say it (a temporary file).

    Returns
    -------
    Path
        The path written.

    Raises
    ------
    InvalidArgumentError
        If ``mesh`` is not a TriangleMesh, ``path`` is not a path or the suffix is unsupported.
    OutputError
        If the file cannot be written (:func:`shspec.core.atomic.atomic_output`: the previous file is then intact).

    Examples
    --------
    >>> from shspec.mesh import icosphere, load_mesh, save_mesh
    >>> path = save_mesh(icosphere(2), "ico.obj")
    >>> load_mesh(path)
    TriangleMesh(162 vertices, 320 faces)
    """
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
        raise InvalidArgumentError(f"a mesh file is a non-empty path, got {path!r}")
    path = Path(path)
    suffix = mesh_format(path, file_type)
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    with atomic_output(path) as tmp:
        # OBJ: positions and faces only, at full double precision, so that a round trip is exact.
        if suffix == ".obj":
            tmp.write_text(trimesh.exchange.obj.export_obj(tm, include_normals=False, include_color=False,
                                                            include_texture=False, digits=17))
        else:
            tm.export(tmp, file_type=suffix.lstrip("."))
    return path
