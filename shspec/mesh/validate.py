"""Checks that a triangle mesh is a closed, oriented, manifold, connected surface, of genus 0 unless told otherwise.

Every check raises :class:`~shspec.errors.MeshError` whose message names the offending count or element, in this
order: finite coordinates, repeated indices, unreferenced vertices, at least 4 vertices, no two faces on the same
three vertices (a back-to-back "pillow"), coordinates whose areas neither overflow nor underflow, zero-area faces,
non-manifold edges, boundary loops, orientation, components, non-manifold vertices, genus.  The order matters: a later check assumes the earlier
ones passed (e.g. counting boundary loops needs every edge to have at most two faces).

The genus check is on by default because cMCF, the harmonic bridge, the fits and the re-embedding all need a
sphere-like surface; cotan spectra and their heat-trace invariants do not, and pass ``genus0=False``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..errors import MeshError
from .triangle_mesh import TriangleMesh

__all__ = ["validate_mesh", "checked_face_areas", "ZERO_AREA_RTOL"]

#: A face whose area is below this fraction of the mean face area counts as degenerate.
ZERO_AREA_RTOL = 1e-12

#: Coordinates are kept within [1e-100, 1e100] in magnitude: the cotan weights, areas and eigenvalues (∝ 1/area) of
#: a mesh then stay far from the overflow and underflow of double precision.
_LARGEST_COORDINATE = 1e100
_SMALLEST_COORDINATE = 1e-100


def checked_face_areas(mesh: TriangleMesh) -> np.ndarray:
    """The (m,) face areas of ``mesh``, once its coordinates are known to be finite and of a size whose squares
    neither overflow nor underflow: the checks of :func:`validate_mesh` that anything computing on a mesh needs.

    Raises
    ------
    MeshError
        A coordinate is NaN or inf, or their largest magnitude is above 1e100 (or below 1e-100 and not zero).
    """
    v = mesh.vertices
    bad = np.flatnonzero(~np.all(np.isfinite(v), axis=1))
    if bad.size:
        raise MeshError(f"{bad.size} vertices have NaN or inf coordinates (first: vertex {bad[0]})")
    extent = float(np.max(np.abs(v), initial=0.0))
    with np.errstate(over="ignore", invalid="ignore", under="ignore"):
        areas = mesh.face_areas()
    if not np.all(np.isfinite(areas)) or extent > _LARGEST_COORDINATE:
        raise MeshError(f"coordinates up to {extent:.3g} are too large: squared lengths and face areas overflow "
                        f"double precision (keep them below {_LARGEST_COORDINATE:g}); rescale the mesh")
    if 0 < extent < _SMALLEST_COORDINATE:
        raise MeshError(f"coordinates of at most {extent:.3g} are too small: squared lengths and face areas "
                        f"underflow double precision (keep them above {_SMALLEST_COORDINATE:g}); rescale the mesh")
    return areas


def validate_mesh(mesh: TriangleMesh, *, genus0: bool = True) -> TriangleMesh:
    """Check that ``mesh`` is a closed, consistently oriented, manifold, connected triangle mesh of genus 0.

    Parameters
    ----------
    mesh : TriangleMesh
        The mesh, n vertices and m faces.
    genus0 : bool, default True
        Also require genus 0 (Euler characteristic V − E + F = 2).  False accepts closed surfaces of any genus.

    Returns
    -------
    TriangleMesh
        ``mesh`` itself, so that calls can be chained.

    Raises
    ------
    MeshError
        On the first failed check, with the offending vertex, face, edge or count in the message.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import MeshError
    >>> from shspec.mesh import TriangleMesh, icosphere, validate_mesh
    >>> sphere = icosphere(1)
    >>> validate_mesh(sphere) is sphere
    True
    >>> try:
    ...     validate_mesh(TriangleMesh(sphere.vertices, sphere.faces[1:]))   # a hole
    ... except MeshError:
    ...     print("refused")
    refused
    """
    if not isinstance(mesh, TriangleMesh):
        raise MeshError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    _check_faces(mesh)
    f, n = mesh.faces, mesh.nvertices
    heads, tails, dkey, nedges = _check_edges(f, n)
    _check_fans(f, n, heads, tails, dkey)
    chi = n - nedges + f.shape[0]
    if genus0 and chi != 2:
        genus = (2 - chi) / 2
        raise MeshError(f"the mesh has Euler characteristic {chi} (genus {genus:g}); shspec needs genus 0 (chi = 2)")
    return mesh


def _check_faces(mesh: TriangleMesh) -> None:
    """Finite vertices, each in a face, at least four; faces of three distinct vertices, no two alike, none flat."""
    v, f = mesh.vertices, mesh.faces
    n = v.shape[0]
    if f.shape[0] == 0:
        raise MeshError("the mesh has no faces")
    bad = np.flatnonzero(~np.all(np.isfinite(v), axis=1))
    if bad.size:
        raise MeshError(f"{bad.size} vertices have NaN or inf coordinates (first: vertex {bad[0]})")
    rep = np.flatnonzero((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0]))
    if rep.size:
        raise MeshError(f"{rep.size} faces repeat a vertex (first: face {rep[0]} = {f[rep[0]].tolist()})")
    used = np.zeros(n, dtype=bool)
    used[f.ravel()] = True
    if not used.all():
        free = np.flatnonzero(~used)
        raise MeshError(f"{free.size} vertices belong to no face (first: vertex {free[0]})")
    if n < 4:
        raise MeshError(f"the mesh has {n} vertices; a closed surface needs at least 4 (a tetrahedron): with fewer, "
                        "its faces lie back to back and enclose nothing")
    triples = np.unique(np.sort(f, axis=1), axis=0, return_inverse=True, return_counts=True)
    if np.any(triples[2] > 1):
        twin = np.flatnonzero(triples[2][triples[1].ravel()] > 1)[:2]
        raise MeshError(f"faces {twin[0]} and {twin[1]} use the same three vertices {f[twin[0]].tolist()} (back to "
                        "back, a zero-volume 'pillow'); the surface is degenerate there")
    areas = checked_face_areas(mesh)
    zero = np.flatnonzero(areas <= ZERO_AREA_RTOL * areas.mean())
    if zero.size:
        raise MeshError(f"{zero.size} faces have zero area (first: face {zero[0]} = {f[zero[0]].tolist()})")


def _check_edges(f: np.ndarray, n: int) -> tuple:
    """Every edge in two faces, once each way, and one connected component; returns the half-edges' heads, tails,
    directed keys and the number of edges."""
    # Half-edges a->b of every face; the undirected edge is (min, max).
    heads = f.ravel()
    tails = f[:, [1, 2, 0]].ravel()
    lo, hi = np.minimum(heads, tails), np.maximum(heads, tails)
    key = lo * n + hi
    ukey, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    over = np.flatnonzero(counts > 2)
    if over.size:
        a, b = divmod(int(ukey[over[0]]), n)
        raise MeshError(f"{over.size} edges are shared by more than two faces (first: edge ({a}, {b}) "
                        f"with {counts[over[0]]} faces): the mesh is not edge-manifold")
    border = np.flatnonzero(counts == 1)
    if border.size:
        a, b = np.divmod(ukey[border], n)
        graph = sp.coo_matrix((np.ones(a.size), (a, b)), shape=(n, n))
        ncomp, labels = connected_components(graph, directed=False)
        loops = np.unique(labels[np.concatenate([a, b])]).size
        raise MeshError(f"the mesh is not closed: {border.size} boundary edges forming {loops} boundary "
                        f"loop{'s' if loops != 1 else ''} (holes)")
    dkey = heads * n + tails
    duk, dcounts = np.unique(dkey, return_counts=True)
    twice = np.flatnonzero(dcounts > 1)
    if twice.size:
        a, b = divmod(int(duk[twice[0]]), n)
        raise MeshError(f"the faces are not consistently oriented: {twice.size} edges are traversed twice in the "
                        f"same direction (first: {a} -> {b})")
    nedges = ukey.size
    graph = sp.coo_matrix((np.ones(lo.size), (lo, hi)), shape=(n, n))
    ncomp, _ = connected_components(graph, directed=False)
    if ncomp != 1:
        raise MeshError(f"the mesh has {ncomp} connected components; shspec needs one")
    return heads, tails, dkey, nedges


def _check_fans(f: np.ndarray, n: int, heads, tails, dkey) -> None:
    """Vertex-manifold: the corners at each vertex form one fan."""
    # Corner (face t, vertex a) and the corner of the face across edge a->b at the same vertex a are joined; a vertex
    # whose corners fall into two or more groups is a pinch point (e.g. two cones touching at their tips).
    corner = np.arange(3 * f.shape[0])
    order = np.argsort(dkey)
    twin_key = tails * n + heads
    twin = order[np.searchsorted(dkey[order], twin_key)]
    # corner of half-edge h = (a -> b) sits at a; the twin (b -> a) starts at b, so its "next" corner sits at a.
    twin_next = 3 * (twin // 3) + (twin % 3 + 1) % 3
    cg = sp.coo_matrix((np.ones(corner.size), (corner, twin_next)), shape=(corner.size, corner.size))
    _, clabels = connected_components(cg, directed=False)
    fans = np.zeros(n, dtype=np.int64)
    uniq = np.unique(np.stack([heads, clabels]), axis=1)
    np.add.at(fans, uniq[0], 1)
    pinch = np.flatnonzero(fans > 1)
    if pinch.size:
        raise MeshError(f"{pinch.size} vertices are not manifold (first: vertex {pinch[0]} joins "
                        f"{fans[pinch[0]]} separate fans of faces)")
