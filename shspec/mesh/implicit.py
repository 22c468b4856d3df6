"""Closed surfaces of any genus as level sets: marching cubes, then relaxation on the exact level set.

:func:`implicit_surface` meshes {f = 0} of a vectorized implicit function with scikit-image's marching cubes and then
improves the triangles: marching cubes leaves slivers wherever the surface grazes a grid vertex, and slivers give
the cotan Laplacian huge weights.  A few rounds of tangential Laplacian smoothing, each followed by a Newton
projection back onto f = 0, even out the triangles while keeping every vertex on the exact surface.

:func:`ring_chain` is the test family of genus g: g tubes of radius r around unit circles in the plane z = 0,
neighbours bridged where their tubes overlap, joined by a smooth (log-sum-exp) minimum of the distances to the
circles, so the surface is C^∞.  Two rings whose circles do not meet but whose tubes overlap form one handle each:
the genus is the number of rings as long as the bridges form a tree (a chain or an L, never a cycle).

scikit-image is an optional dependency (the ``test`` and ``bench`` extras); it is imported when a surface is made.
"""

from __future__ import annotations

import numpy as np

from ..core.checks import check_int
from ..errors import InvalidArgumentError, MeshError
from .triangle_mesh import TriangleMesh

__all__ = ["implicit_surface", "ring_chain", "euler_characteristic"]


def euler_characteristic(mesh: TriangleMesh) -> int:
    """V − E + F of a triangle mesh (2 − 2g for a closed connected orientable surface of genus g).

    Examples
    --------
    >>> from shspec.mesh import euler_characteristic, icosphere, ring_chain
    >>> euler_characteristic(icosphere(1)), euler_characteristic(ring_chain([(0, 0)], spacing=0.12))
    (2, 0)
    """
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    f = mesh.faces
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    nedges = np.unique(edges[:, 0] * mesh.nvertices + edges[:, 1]).size
    return int(mesh.nvertices - nedges + mesh.nfaces)


def _gradient(func, x: np.ndarray, h: float) -> np.ndarray:
    # Central differences: f is analytic, so h³-accurate gradients are plenty for a Newton projection.
    g = np.empty_like(x)
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        g[:, k] = (func(x + e) - func(x - e)) / (2 * h)
    return g


def _project(func, x: np.ndarray, h: float, steps: int = 3) -> np.ndarray:
    for _ in range(steps):
        g = _gradient(func, x, h)
        x = x - (func(x) / np.maximum(np.einsum("ij,ij->i", g, g), 1e-300))[:, None] * g
    return x


def implicit_surface(func, bounds, spacing: float, *, relax: int = 10) -> TriangleMesh:
    """Triangle mesh of the closed level set {func = 0} inside a box, outward oriented (func < 0 inside).

    Parameters
    ----------
    func : callable
        ``func(x)`` for points x of shape (p, 3) returns (p,) values, negative inside the surface, smooth.
    bounds : (2, 3) array_like
        Lower and upper corner of a box that holds the surface with at least one grid cell to spare.
    spacing : float
        Grid step of marching cubes (length unit); the mesh has about area / (0.35·spacing²) vertices.
    relax : int, default 10
        Rounds of tangential smoothing + projection onto func = 0 (0: the raw marching-cubes mesh).

    Returns
    -------
    TriangleMesh
        Welded vertices (shared between faces), faces counter-clockwise seen from outside.

    Raises
    ------
    InvalidArgumentError
        If the bounds or spacing are not usable.
    MeshError
        If func is not negative somewhere and positive on the box's boundary (the surface would be open or empty).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.mesh import euler_characteristic, implicit_surface
    >>> ball = implicit_surface(lambda p: np.linalg.norm(p, axis=1) - 1.0, ((-1.3,) * 3, (1.3,) * 3), 0.2)
    >>> euler_characteristic(ball)
    2
    """
    from skimage.measure import marching_cubes

    lo, hi = np.asarray(bounds, dtype=float)
    spacing = float(spacing)
    if lo.shape != (3,) or not np.all(hi > lo) or not np.isfinite(spacing) or spacing <= 0:
        raise InvalidArgumentError(f"need bounds (2, 3) with upper > lower and spacing > 0, got {bounds}, {spacing}")
    relax = check_int(relax, "relax", minimum=0)
    axes = [np.arange(lo[k], hi[k] + spacing, spacing) for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    values = func(grid.reshape(-1, 3)).reshape(grid.shape[:3])
    border = np.concatenate([values[[0, -1]].ravel(), values[:, [0, -1]].ravel(), values[:, :, [0, -1]].ravel()])
    if not (values.min() < 0 and border.min() > 0):
        raise MeshError("the implicit surface must be inside the box: func < 0 somewhere and > 0 on the boundary")
    verts, faces, _, _ = marching_cubes(values, 0.0, spacing=(spacing,) * 3, allow_degenerate=False)
    x = verts + lo
    faces = np.asarray(faces, dtype=np.int64)
    h = 1e-5 * spacing
    if relax:
        n = x.shape[0]
        i = faces.ravel()
        j = faces[:, [1, 2, 0]].ravel()
        deg = np.bincount(i, minlength=n).astype(float)
        for _ in range(int(relax)):
            # Each directed edge i->j appears once per face and its reverse once in the neighbour: the mean of the
            # heads is the mean of the one-ring.
            mean = np.stack([np.bincount(i, weights=x[j, k], minlength=n) for k in range(3)], 1) / deg[:, None]
            d = mean - x
            normal = _gradient(func, x, h)
            normal /= np.linalg.norm(normal, axis=1)[:, None]
            d -= np.einsum("ij,ij->i", d, normal)[:, None] * normal
            x = _project(func, x + 0.5 * d, h)
    mesh = TriangleMesh(x, faces)
    if mesh.signed_volume() < 0:
        mesh = TriangleMesh(x, faces[:, ::-1])
    return mesh


def ring_chain(centers, major: float = 1.0, minor: float = 0.4, spacing: float = 0.06, *, sharpness: float = 12.0,
               relax: int = 10) -> TriangleMesh:
    """Tubes of radius ``minor`` around circles of radius ``major`` in z = 0, smoothly joined: genus = len(centers).

    Parameters
    ----------
    centers : (g, 2) array_like
        Circle centres in the xy plane.  Neighbours bridged into one surface must be closer than
        2·major + 2·minor and farther than 2·major (so the circles do not cross); the bridges must form a tree.
    major, minor : float
        Circle radius and tube radius, minor < major.
    spacing : float
        Marching-cubes grid step (see :func:`implicit_surface`); 0.06 gives about 4500 vertices per ring at the
        default radii.
    sharpness : float
        k of the smooth minimum −log Σ exp(−k d_i)/k of the distances d_i to the circles (larger: sharper creases).
    relax : int
        Relaxation rounds (see :func:`implicit_surface`).

    Returns
    -------
    TriangleMesh
        A closed outward-oriented surface of genus len(centers) (check it with :func:`euler_characteristic`).

    Examples
    --------
    >>> from shspec.mesh import euler_characteristic, ring_chain
    >>> euler_characteristic(ring_chain([(0, 0), (2.2, 0)], spacing=0.12))   # two fused rings: genus 2
    -2
    """
    c = np.asarray(centers, dtype=float)
    if c.ndim != 2 or c.shape[1] != 2 or c.shape[0] < 1 or not np.all(np.isfinite(c)):
        raise InvalidArgumentError(f"centers must be a finite (g, 2) array with g >= 1, got shape {c.shape}")
    major, minor, sharpness = float(major), float(minor), float(sharpness)
    if not (0 < minor < major) or not sharpness > 0:
        raise InvalidArgumentError(f"need 0 < minor < major and sharpness > 0, got {minor}, {major}, {sharpness}")

    def func(x):
        rho = np.hypot(x[:, None, 0] - c[None, :, 0], x[:, None, 1] - c[None, :, 1])
        d = np.hypot(rho - major, x[:, None, 2])
        dmin = d.min(axis=1)
        return dmin - np.log(np.exp(-sharpness * (d - dmin[:, None])).sum(axis=1)) / sharpness - minor

    pad = minor + 3 * spacing
    lo = np.concatenate([c.min(axis=0) - major - pad, [-pad]])
    hi = np.concatenate([c.max(axis=0) + major + pad, [pad]])
    return implicit_surface(func, np.stack([lo, hi]), spacing, relax=relax)
