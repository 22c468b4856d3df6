"""Quality measures of an embedded mesh: edge-length error, folded faces and self-intersections.

trimesh 5 counts self-intersections only through python-fcl, which is not a dependency of shspec, so
:func:`self_intersections` does it here: a k-d tree on the face centroids (SciPy) proposes the pairs of faces that
can touch, and an exact, vectorized segment–triangle test decides them.  Cost O(m log m) for m faces of similar size.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InvalidArgumentError
from ..mesh.triangle_mesh import TriangleMesh

__all__ = ["edge_length_error", "folded_faces", "self_intersections", "face_adjacency"]


def _mesh(mesh) -> TriangleMesh:
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    return mesh


def edge_length_error(mesh: TriangleMesh, edges: np.ndarray, lengths: np.ndarray) -> tuple[float, float]:
    """Relative edge-length errors of a mesh against target lengths.

    Parameters
    ----------
    mesh : TriangleMesh
        n vertices.
    edges : (E, 2) int array
        Vertex pairs.
    lengths : (E,) array
        Target lengths ℓ' > 0, same unit as the vertices.

    Returns
    -------
    rms, max : float
        √(mean_e r_e²) and max_e |r_e| with r_e = |x_i − x_j| / ℓ'_e − 1 (dimensionless).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.embed import edge_length_error, mesh_edges
    >>> from shspec.mesh import icosphere
    >>> sphere = icosphere(1)
    >>> edges = mesh_edges(sphere)
    >>> lengths = np.linalg.norm(sphere.vertices[edges[:, 0]] - sphere.vertices[edges[:, 1]], axis=1)
    >>> edge_length_error(sphere, edges, 1.1 * lengths)     # (rms, max) relative strain
    (0.0909..., 0.0909...)
    """
    mesh = _mesh(mesh)
    edges = np.asarray(edges)
    lengths = np.asarray(lengths, dtype=float)
    if edges.ndim != 2 or edges.shape[1] != 2 or lengths.shape != (edges.shape[0],):
        raise InvalidArgumentError(f"need edges (E, 2) and lengths (E,), got {edges.shape} and {lengths.shape}")
    if np.any(~np.isfinite(lengths)) or np.any(lengths <= 0):
        raise InvalidArgumentError("target lengths must be finite and > 0")
    x = mesh.vertices
    r = np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1) / lengths - 1.0
    return float(np.sqrt(np.mean(r * r))), float(np.max(np.abs(r)))


def face_adjacency(mesh: TriangleMesh) -> np.ndarray:
    """Pairs of faces sharing an edge, (m·3/2, 2) int64, for a closed manifold mesh."""
    f = _mesh(mesh).faces
    he = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = np.sort(he, axis=1)
    face = np.tile(np.arange(f.shape[0]), 3)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, face = key[order], face[order]
    same = np.all(key[1:] == key[:-1], axis=1)
    return np.stack([face[:-1][same], face[1:][same]], axis=1)


def folded_faces(mesh: TriangleMesh) -> int:
    """Number of faces whose normal points against the normal of an edge-neighbour (dihedral fold > 90° of turn).

    A smooth, finely sampled surface has none; each fold of a crumpled re-embedding adds at least two.  This is
    the embedding analogue of a flipped triangle: a closed surface has no global "outward" to flip against.

    Examples
    --------
    >>> from shspec.embed import folded_faces
    >>> from shspec.mesh import icosphere
    >>> folded_faces(icosphere(2))
    0
    """
    mesh = _mesh(mesh)
    nrm = mesh.face_normals_unnormalized()
    adj = face_adjacency(mesh)
    bad = np.einsum("ij,ij->i", nrm[adj[:, 0]], nrm[adj[:, 1]]) < 0
    return int(np.unique(adj[bad].ravel()).size)


def self_intersections(mesh: TriangleMesh) -> int:
    """Number of pairs of faces without a common vertex that intersect (exact predicate up to rounding).

    Parameters
    ----------
    mesh : TriangleMesh
        m faces.

    Returns
    -------
    int
        Intersecting face pairs; 0 for an embedded surface.

    Examples
    --------
    >>> from shspec.embed import self_intersections
    >>> from shspec.mesh import icosphere
    >>> self_intersections(icosphere(2))
    0
    """
    mesh = _mesh(mesh)
    p = mesh.vertices[mesh.faces]
    cen = p.mean(axis=1)
    rad = np.max(np.linalg.norm(p - cen[:, None], axis=2), axis=1)
    tree = cKDTree(cen)
    # Two faces can only touch if their centroids are closer than the sum of their circumradii ≤ 2·max radius.
    pairs = tree.query_pairs(2.0 * float(rad.max()), output_type="ndarray")
    if pairs.size == 0:
        return 0
    a, b = pairs[:, 0], pairs[:, 1]
    close = np.linalg.norm(cen[a] - cen[b], axis=1) <= rad[a] + rad[b]
    a, b = a[close], b[close]
    f = mesh.faces
    shared = (f[a][:, :, None] == f[b][:, None, :]).any(axis=(1, 2))
    a, b = a[~shared], b[~shared]
    hit = _edges_hit(p[a], p[b]) | _edges_hit(p[b], p[a])
    return int(np.count_nonzero(hit))


def _edges_hit(s: np.ndarray, t: np.ndarray) -> np.ndarray:
    """For K triangle pairs, whether an edge of triangle s[k] (K, 3, 3) crosses triangle t[k] (Möller–Trumbore)."""
    hit = np.zeros(s.shape[0], dtype=bool)
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    for k in range(3):
        o, d = s[:, k], s[:, (k + 1) % 3] - s[:, k]
        h = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, h)
        ok = np.abs(det) > 1e-14 * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1) * np.linalg.norm(d, axis=1)
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        q = o - t[:, 0]
        u = np.einsum("ij,ij->i", q, h) * inv
        qe = np.cross(q, e1)
        v = np.einsum("ij,ij->i", d, qe) * inv
        w = np.einsum("ij,ij->i", e2, qe) * inv
        hit |= ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (w >= 0) & (w <= 1)
    return hit
