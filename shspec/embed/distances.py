"""Geometric distances between two surfaces after rigid alignment: Hausdorff and Chamfer.

Alignment uses trimesh's registration: with a vertex correspondence (the re-embedded mesh keeps the target's
connectivity) the optimal orthogonal transform is closed-form (:func:`trimesh.registration.procrustes`, Kabsch);
without one, each of the 8 sign choices of the principal axes starts :func:`trimesh.registration.icp` and the best
is kept.  Reflections are allowed by default: a metric (and a spectrum) cannot tell a surface from its mirror image.

Distances are from dense point samples of each surface (the vertices plus area-uniform samples,
:func:`trimesh.sample.sample_surface`) to the other *surface*: exact point–triangle distances to the faces whose
centroids are among the 12 nearest (SciPy k-d tree).  trimesh's own proximity queries would need rtree, which
shspec does not require.  Sampling can only miss the farthest point, so the Hausdorff distance is a lower bound
accurate to about the sample spacing √(A/s) times the surfaces' slope difference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..core.checks import check_int
from ..errors import InvalidArgumentError
from ..mesh.triangle_mesh import TriangleMesh

__all__ = ["SurfaceDistance", "surface_distance", "rigid_align"]


@dataclass(frozen=True)
class SurfaceDistance:
    """Distances between a surface and a target after rigid alignment.

    Attributes
    ----------
    hausdorff : float
        Symmetric Hausdorff distance max(max_a d(a, B), max_b d(b, A)) (length unit).
    chamfer : float
        Symmetric mean distance ½ (mean_a d(a, B) + mean_b d(b, A)) (length unit).
    diagonal : float
        Bounding-box diagonal of the target (length unit).
    hausdorff_relative, chamfer_relative : float
        The two distances over ``diagonal``.
    transform : (4, 4) array
        Homogeneous transform applied to the surface (orthogonal part: a rotation or a reflection).
    reflected : bool
        The orthogonal part has determinant −1.
    correspondence : bool
        Aligned by Procrustes on corresponding vertices (else by ICP).
    samples : int
        Points sampled per surface.

    Examples
    --------
    >>> from shspec.embed import surface_distance
    >>> from shspec.mesh import blob, icosphere
    >>> d = surface_distance(icosphere(2), blob(2))
    >>> d.transform.shape, d.hausdorff_relative > d.chamfer_relative
    ((4, 4), True)
    """

    hausdorff: float
    chamfer: float
    diagonal: float
    hausdorff_relative: float
    chamfer_relative: float
    transform: np.ndarray
    reflected: bool
    correspondence: bool
    samples: int


def _trimesh(mesh: TriangleMesh) -> trimesh.Trimesh:
    return trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)


def _samples(mesh: TriangleMesh, count: int, seed: int) -> np.ndarray:
    pts, _ = trimesh.sample.sample_surface(_trimesh(mesh), count, seed=seed)
    return np.concatenate([mesh.vertices, np.asarray(pts)])


def rigid_align(surface: TriangleMesh, target: TriangleMesh, *, reflection: bool = True, samples: int = 20000,
                seed: int = 0) -> tuple[np.ndarray, bool]:
    """Orthogonal transform (with translation, no scaling) that best aligns ``surface`` onto ``target``.

    Parameters
    ----------
    surface, target : TriangleMesh
        The surface to move and the reference (same length unit).
    reflection : bool
        Allow improper transforms (mirror images).
    samples : int
        Points per surface for ICP when the meshes have no vertex correspondence.
    seed : int
        Seed of the surface sampling.

    Returns
    -------
    transform : (4, 4) array
        Homogeneous matrix to apply to ``surface``'s vertices.
    correspondence : bool
        True if the meshes have the same faces and the transform is Procrustes on the vertices.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.embed import rigid_align
    >>> from shspec.mesh import blob
    >>> surface = blob(2)
    >>> moved = surface.with_vertices(surface.vertices + [1.0, 2.0, 3.0])
    >>> transform, reflected = rigid_align(moved, surface)   # a 4 x 4 matrix, and whether it mirrors
    >>> bool(np.allclose(transform[:3, 3], [-1.0, -2.0, -3.0], atol=1e-6))
    True
    """
    if not isinstance(surface, TriangleMesh) or not isinstance(target, TriangleMesh):
        raise InvalidArgumentError("surface and target must be TriangleMesh objects")
    if np.array_equal(surface.faces, target.faces):
        T, _, _ = trimesh.registration.procrustes(surface.vertices, target.vertices, reflection=reflection,
                                                  scale=False)
        return np.asarray(T), True
    a = _samples(surface, samples, seed)
    b = _samples(target, samples, seed + 1)

    def frame(p):
        c = p.mean(axis=0)
        _, _, vt = np.linalg.svd(p - c, full_matrices=False)
        return c, vt

    ca, va = frame(a)
    cb, vb = frame(b)
    best, best_cost = None, np.inf
    for signs in np.array(np.meshgrid([1, -1], [1, -1], [1, -1])).T.reshape(-1, 3):
        R = vb.T @ np.diag(signs) @ va
        if not reflection and np.linalg.det(R) < 0:
            continue
        init = np.eye(4)
        init[:3, :3] = R
        init[:3, 3] = cb - R @ ca
        T, _, cost = trimesh.registration.icp(a, b, initial=init, threshold=1e-7, max_iterations=30,
                                              reflection=reflection, scale=False)
        if cost < best_cost:
            best, best_cost = np.asarray(T), cost
    return best, False


def _segment_distance(q, a, b):
    """Distances (P, K) from points q (P, 1, 3) to segments a–b (P, K, 3)."""
    d = b - a
    t = np.clip(np.einsum("pkj,pkj->pk", q - a, d) / np.maximum(np.einsum("pkj,pkj->pk", d, d), 1e-300), 0, 1)
    return np.linalg.norm(q - (a + t[..., None] * d), axis=2)


def _to_surface(points: np.ndarray, mesh: TriangleMesh, candidates: int = 12) -> np.ndarray:
    """Distance (P,) from each point (P, 3) to the mesh: exact to the ``candidates`` faces of nearest centroid."""
    tri = mesh.vertices[mesh.faces]
    k = min(candidates, mesh.nfaces)
    _, idx = cKDTree(tri.mean(axis=1)).query(points, k=k)
    idx = idx.reshape(points.shape[0], k)
    t = tri[idx]  # (P, K, 3, 3)
    q = points[:, None, :]
    n = np.cross(t[:, :, 1] - t[:, :, 0], t[:, :, 2] - t[:, :, 0])
    n /= np.maximum(np.linalg.norm(n, axis=2), 1e-300)[..., None]
    h = np.einsum("pkj,pkj->pk", q - t[:, :, 0], n)
    foot = q - h[..., None] * n
    inside = np.ones(h.shape, dtype=bool)
    for i in range(3):
        e = t[:, :, (i + 1) % 3] - t[:, :, i]
        inside &= np.einsum("pkj,pkj->pk", np.cross(e, foot - t[:, :, i]), n) >= 0
    edge = np.minimum.reduce([_segment_distance(q, t[:, :, i], t[:, :, (i + 1) % 3]) for i in range(3)])
    return np.min(np.where(inside, np.abs(h), edge), axis=1)


def surface_distance(surface: TriangleMesh, target: TriangleMesh, *, reflection: bool = True,
                     samples: int = 20000, seed: int = 0) -> SurfaceDistance:
    """Hausdorff and Chamfer distances from ``surface`` to ``target`` after :func:`rigid_align`.

    Parameters
    ----------
    surface, target : TriangleMesh
        Closed meshes in the same length unit.
    reflection : bool
        Allow mirror-image alignment.
    samples : int
        Area-uniform samples per surface on top of the vertices (≥ 100).
    seed : int
        Seed of the sampling, for reproducible numbers.

    Returns
    -------
    SurfaceDistance

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.embed import surface_distance
    >>> from shspec.mesh import blob
    >>> surface = blob(2)
    >>> turned = surface.with_vertices(surface.vertices @ np.diag([1.0, -1.0, 1.0]) + 5.0)   # mirrored, moved
    >>> surface_distance(turned, surface).hausdorff_relative < 1e-6   # rigid motions and reflections do not count
    True
    """
    samples = check_int(samples, "samples", minimum=100)
    T, corr = rigid_align(surface, target, reflection=reflection, samples=samples, seed=seed)
    moved = surface.with_vertices(surface.vertices @ T[:3, :3].T + T[:3, 3])
    a = _samples(moved, samples, seed)
    b = _samples(target, samples, seed + 1)
    dab = _to_surface(a, target)
    dba = _to_surface(b, moved)
    diag = float(np.linalg.norm(np.ptp(target.vertices, axis=0)))
    h = float(max(dab.max(), dba.max()))
    ch = float(0.5 * (dab.mean() + dba.mean()))
    return SurfaceDistance(hausdorff=h, chamfer=ch, diagonal=diag, hausdorff_relative=h / diag,
                           chamfer_relative=ch / diag, transform=T, reflected=bool(np.linalg.det(T[:3, :3]) < 0),
                           correspondence=corr, samples=int(samples))
