"""Target edge lengths of a spherical mesh carrying per-vertex conformal factors.

Choice of the discrete metric
-----------------------------
A conformal factor c = ρ multiplies areas, so lengths scale by √c.  On an edge ij we use the vertex-scaling rule of
discrete conformal equivalence (Luo 2004; Springborn, Schröder, Pinkall, "Conformal equivalence of triangle meshes",
2008):

    ℓ'_ij = ℓ_ij · (c_i c_j)^(1/4) = ℓ_ij · exp((u_i + u_j)/2),    u = ½ log c,

ℓ_ij the chord length on the unit-sphere mesh.  It is symmetric, exact for constant c, a second-order accurate
midpoint rule for ∫ √ρ ds along a smooth edge, and it is the relation for which "the same factors" means "the
same discrete conformal class", so a factor field fitted on the mesh (the PL inverse problem) maps to lengths
without further choices.  The arithmetic alternative ℓ·√((c_i + c_j)/2) agrees to second order but is not a
conformal equivalence.  The factors of :func:`~shspec.mesh.cmcf.cmcf` are area ratios of a map that is only
approximately conformal, so the lengths reproduce the original surface up to that discretization error.

Optional smoothing filters u = ½ log c with the bi-Laplacian of the sphere mesh, (M + α L M⁻¹ L) u_s = M u,
which damps the high-frequency noise of fitted factors and leaves constants (global scale) untouched.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from ..errors import InvalidArgumentError, MeshError, NotPositiveError
from ..mesh.cotan import cotan_stiffness, vertex_areas
from ..mesh.triangle_mesh import TriangleMesh

__all__ = ["mesh_edges", "target_edge_lengths", "smooth_factors", "check_factors", "check_sphere", "MAX_FACTOR_RANGE"]

#: Largest ratio of the largest to the smallest factor an embedding accepts: lengths then span 1e50 and the weights
#: 1/ℓ² of its Gauss–Newton matrix 1e100, inside double precision (a ratio of 1e150 made the matrix singular).
MAX_FACTOR_RANGE = 1e100


def check_sphere(sphere, atol: float = 1e-6) -> TriangleMesh:
    """Return ``sphere`` after checking it is a TriangleMesh with vertices on the unit sphere (to ``atol``).

    Raises
    ------
    InvalidArgumentError
        If it is not a TriangleMesh.
    MeshError
        If a vertex is off the unit sphere by more than ``atol``.
    """
    if not isinstance(sphere, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(sphere).__name__}")
    off = np.max(np.abs(np.linalg.norm(sphere.vertices, axis=1) - 1.0))
    if off > atol:
        raise MeshError(f"the vertices are not on the unit sphere: |x| − 1 reaches {off:.3g}")
    return sphere


def check_factors(factors, n: int) -> np.ndarray:
    """Return per-vertex factors as a float (n,) array after checking they are finite and > 0.

    Raises
    ------
    InvalidArgumentError
        Wrong shape, NaN or inf, or factors spanning more than :data:`MAX_FACTOR_RANGE`.
    NotPositiveError
        A factor ≤ 0 (not a metric).
    """
    try:
        c = np.asarray(factors, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"factors must be numeric: {exc}") from None
    if c.shape != (n,):
        raise InvalidArgumentError(f"factors must have shape ({n},), got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise InvalidArgumentError(f"factor at vertex {int(np.flatnonzero(~np.isfinite(c))[0])} is NaN or inf")
    if np.any(c <= 0):
        bad = np.flatnonzero(c <= 0)
        raise NotPositiveError(f"{bad.size} conformal factors are <= 0 (first: vertex {bad[0]}, c = {c[bad[0]]:.3g})")
    hi, lo = int(np.argmax(c)), int(np.argmin(c))
    if c[hi] / c[lo] > MAX_FACTOR_RANGE:
        raise InvalidArgumentError(
            f"the factors span {c[hi] / c[lo]:.3g} (vertex {lo}: {c[lo]:.3g}, vertex {hi}: {c[hi]:.3g}), more than "
            f"{MAX_FACTOR_RANGE:g}: the weights 1/length^2 of the embedding would overflow double precision")
    return c


def mesh_edges(mesh: TriangleMesh) -> np.ndarray:
    """Unique undirected edges (E, 2), int64, each as (i, j) with i < j, sorted lexicographically.

    Examples
    --------
    >>> from shspec.embed import mesh_edges
    >>> from shspec.mesh import icosphere
    >>> mesh_edges(icosphere(1)).shape          # E = 3F/2 on a closed mesh
    (120, 2)
    """
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    f = mesh.faces
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def smooth_factors(sphere: TriangleMesh, factors, alpha: float) -> np.ndarray:
    """Bi-Laplacian low-pass filter of log-factors on a spherical mesh.

    Parameters
    ----------
    sphere : TriangleMesh
        Unit-sphere mesh, n vertices.
    factors : (n,) array
        Conformal factors c > 0.
    alpha : float
        Filter strength α ≥ 0 in units of (unit-sphere length)⁴; a harmonic of degree l is damped by
        1 / (1 + α (l(l+1))²).  α = 0 returns the factors unchanged.

    Returns
    -------
    (n,) array
        exp(2 u_s) with (M + α L M⁻¹ L) u_s = M u, u = ½ log c.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.embed import smooth_factors
    >>> from shspec.mesh import icosphere
    >>> sphere = icosphere(1)
    >>> smooth_factors(sphere, np.ones(sphere.nvertices), 0.1)[:3]   # constants stay constant
    array([1., 1., 1.])
    """
    sphere = check_sphere(sphere)
    c = check_factors(factors, sphere.nvertices)
    alpha = float(alpha)
    if not np.isfinite(alpha) or alpha < 0:
        raise InvalidArgumentError(f"alpha must be finite and >= 0, got {alpha}")
    if alpha == 0:
        return c.copy()
    L = cotan_stiffness(sphere)
    m = vertex_areas(sphere)
    A = sp.diags(m) + alpha * (L @ sp.diags(1.0 / m) @ L)
    u = spsolve(A.tocsc(), m * 0.5 * np.log(c))
    return np.exp(2.0 * u)


def target_edge_lengths(sphere: TriangleMesh, factors, edges: np.ndarray | None = None) -> np.ndarray:
    """Edge lengths ℓ'_ij = ℓ_ij (c_i c_j)^(1/4) of the metric c·g₀ on a unit-sphere mesh (see module notes).

    Parameters
    ----------
    sphere : TriangleMesh
        Unit-sphere mesh, n vertices.
    factors : (n,) array
        Conformal factors c > 0 (area ratio, target length unit² per unit-sphere area).
    edges : (E, 2) int array, optional
        Edges to measure; default :func:`mesh_edges` of ``sphere``.

    Returns
    -------
    (E,) array
        Target lengths in the target's length unit.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.embed import mesh_edges, target_edge_lengths
    >>> from shspec.mesh import icosphere
    >>> sphere = icosphere(1)
    >>> edges = mesh_edges(sphere)
    >>> doubled = target_edge_lengths(sphere, np.full(sphere.nvertices, 4.0), edges)   # factors 4: lengths x 2
    >>> bool(np.allclose(doubled, 2 * target_edge_lengths(sphere, np.ones(sphere.nvertices), edges)))
    True
    """
    sphere = check_sphere(sphere)
    c = check_factors(factors, sphere.nvertices)
    if edges is None:
        edges = mesh_edges(sphere)
    edges = np.asarray(edges)
    if edges.ndim != 2 or edges.shape[1] != 2 or not np.issubdtype(edges.dtype, np.integer):
        raise InvalidArgumentError(f"edges must be an integer (E, 2) array, got {edges.dtype} {edges.shape}")
    x = sphere.vertices
    chord = np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1)
    return chord * (c[edges[:, 0]] * c[edges[:, 1]]) ** 0.25
