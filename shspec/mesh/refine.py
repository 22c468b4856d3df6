"""Sphere meshes adapted to a metric, vertex fields carried along, and what a mesh's spectrum can be trusted for.

Adaptive refinement (the study's A.5).  A per-vertex fit on a fixed sphere mesh can only express metrics that the
mesh resolves: a generic icosphere gives every vertex the same share of the *sphere*, whereas a surface whose ears
hold a large part of the area on a small part of the sphere needs many vertices there.  :func:`refine_sphere`
splits the edges that are long in the fitted metric, so that each vertex ends up carrying a comparable share of the
fitted area: the metric length of edge ij is |x_i − x_j|·exp((s_i + s_j)/4) for log factors s = log c (c scales
areas, √c lengths), and an edge across which s changes fast counts longer by the factor 1 + |s_i − s_j|.  New
vertices sit at the great-circle midpoints and take the mean of the two end values (linear interpolation of s along
the edge).  The mesh is then re-triangulated as the convex hull of its vertices, which for points on a sphere *is*
their Delaunay triangulation: no slivers beyond what the point set forces, and no flips to bookkeep.

Alignment.  A fit on another sphere mesh (adaptive, or a recursive pass) can be compared with a truth only up to
what the spectrum cannot see: :func:`align_vertex_field` Möbius-centres the fitted mesh with the fitted area as
weights (the truth's cMCF sphere is centred the same way; moving the vertices, the factors take the change of the
sphere's vertex areas, so that the surface stays), ranks the elements of the octahedral group and their mirrors on
a harmonic expansion of the fitted log factors, and from the best refines a rotation and a Möbius translation
together on the fitted field's interpolant: the least misfit over the group, where the centring alone would
depend on how much of the area a coarse fit resolves.

Discretization error.  :func:`eigenvalue_errors` compares a mesh's cotan spectrum (optionally with per-vertex
factors) with that of its 4-to-1 midpoint subdivision, on which the eigenvalues of a P1 discretization have
converged further: |λ_i − λ_i'| / λ_i estimates the error of λ_i on the mesh (the study's A.2: how many eigenvalues
a mesh can give).  :func:`trusted_numeig` keeps the eigenvalues whose estimate stays below a tolerance.
:func:`refined_eigenvalues` gives the spectra of repeated subdivisions, from which
:func:`~shspec.fitting.targets.refined_target` extrapolates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
from scipy.spatial import cKDTree
import scipy.sparse as sp
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from ..core.checks import check_float, check_int, finite_array
from ..errors import InvalidArgumentError, MeshError
from ..sphere.evaluate import harmonic_matrix
from ..sphere.mobius import mobius_translate
from .bridge import fit_harmonic, mesh_band_limit
from .cotan import cotan_stiffness, vertex_areas
from .eigen import eigenpairs
from .mobius import center_mesh
from .triangle_mesh import TriangleMesh

__all__ = ["MeshQuality", "mesh_quality", "edges", "subdivide", "refine_sphere", "FieldAlignment",
           "align_vertex_field", "refined_eigenvalues", "subdivision_eigenvalues", "eigenvalue_errors",
           "trusted_numeig"]


def _check_mesh(mesh) -> TriangleMesh:
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    return mesh


def _check_values(mesh: TriangleMesh, values, name: str) -> np.ndarray:
    return finite_array(values, name, (mesh.nvertices,))


def _check_sphere(mesh: TriangleMesh) -> None:
    off = np.max(np.abs(np.linalg.norm(mesh.vertices, axis=1) - 1.0))
    if off > 1e-8:
        raise MeshError(f"the vertices are not on the unit sphere: |x| − 1 reaches {off:.3g}")


@dataclass(frozen=True)
class MeshQuality:
    """Shape of a mesh's triangles.

    Attributes
    ----------
    min_angle, max_angle : float
        Smallest and largest triangle angle (degrees).
    aspect_max : float
        Largest √(ℓ_max²·(√3/4) / A) over the faces, ℓ_max the longest edge and A the area (1 for an equilateral
        triangle, large for a sliver).
    euler : int
        V − E + F (2 for a sphere).
    outward : bool
        Every face's normal points away from the origin (sphere meshes).
    """

    min_angle: float
    max_angle: float
    aspect_max: float
    euler: int
    outward: bool


def edges(mesh: TriangleMesh) -> np.ndarray:
    """The undirected edges (E, 2) of a mesh, each once, i < j."""
    f = _check_mesh(mesh).faces
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0)


def mesh_quality(mesh: TriangleMesh) -> MeshQuality:
    """Angles, aspect ratio, Euler characteristic and orientation of a mesh (:class:`MeshQuality`)."""
    mesh = _check_mesh(mesh)
    p = mesh.vertices[mesh.faces]
    angles = []
    for k in range(3):
        a, b = p[:, (k + 1) % 3] - p[:, k], p[:, (k + 2) % 3] - p[:, k]
        cos = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        angles.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    angles = np.stack(angles, 1)
    lengths = np.stack([np.linalg.norm(p[:, (k + 1) % 3] - p[:, k], axis=1) for k in range(3)], 1)
    area = mesh.face_areas()
    aspect = lengths.max(1) ** 2 * np.sqrt(3) / 4 / np.maximum(area, 1e-300)
    normals = mesh.face_normals_unnormalized()
    outward = bool(np.all(np.einsum("ij,ij->i", normals, p.sum(1)) > 0))
    return MeshQuality(min_angle=float(angles.min()), max_angle=float(angles.max()),
                       aspect_max=float(np.sqrt(aspect.max())), euler=mesh.nvertices - len(edges(mesh)) + mesh.nfaces,
                       outward=outward)


def _hull(points: np.ndarray) -> TriangleMesh:
    """The Delaunay triangulation of points on the unit sphere (their convex hull), faces oriented outward."""
    faces = ConvexHull(points).simplices.astype(np.int64)
    p = points[faces]
    flip = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p.sum(1)) < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return TriangleMesh(points, faces)


def subdivide(mesh: TriangleMesh, values=None, *, project: bool = False) -> tuple[TriangleMesh, np.ndarray | None]:
    """4-to-1 midpoint subdivision; ``values`` (n,) are interpolated linearly (means at the new edge midpoints).

    Parameters
    ----------
    mesh : TriangleMesh
        n vertices.
    values : (n,) array, optional
        Vertex values to carry along.
    project : bool
        Move the new vertices radially onto the unit sphere (sphere meshes); otherwise the refined mesh is the same
        piecewise-flat surface.

    Returns
    -------
    (TriangleMesh, (n + E,) array or None)
        The vertices of ``mesh`` first, then one per edge.
    """
    mesh = _check_mesh(mesh)
    v = None if values is None else _check_values(mesh, values, "values")
    e = edges(mesh)
    n = mesh.nvertices
    mid = 0.5 * (mesh.vertices[e[:, 0]] + mesh.vertices[e[:, 1]])
    if project:
        _check_sphere(mesh)
        mid /= np.linalg.norm(mid, axis=1)[:, None]
    index = sp.csr_matrix((np.arange(len(e)) + n, (e[:, 0], e[:, 1])), shape=(n, n))
    index = index + index.T
    f = mesh.faces
    m01, m12, m20 = (np.asarray(index[f[:, a], f[:, b]]).ravel() for a, b in ((0, 1), (1, 2), (2, 0)))
    faces = np.concatenate([np.stack([f[:, 0], m01, m20], 1), np.stack([f[:, 1], m12, m01], 1),
                            np.stack([f[:, 2], m20, m12], 1), np.stack([m01, m12, m20], 1)])
    out = TriangleMesh(np.vstack([mesh.vertices, mid]), faces)
    return out, None if v is None else np.concatenate([v, 0.5 * (v[e[:, 0]] + v[e[:, 1]])])


def refine_sphere(sphere: TriangleMesh, log_factors, nvertices: int, *, fraction: float = 0.25,
                  ) -> tuple[TriangleMesh, np.ndarray]:
    """Refine a unit-sphere mesh where the metric exp(s)·g₀ is large or varies fast, to about ``nvertices``.

    Rounds split the longest edges in the metric (module notes; at most ``fraction`` of the edges per round) at
    their great-circle midpoints, give each new vertex the mean of its edge's two values, and re-triangulate as
    the Delaunay triangulation of the sphere (the convex hull), until the mesh has ``nvertices`` vertices.

    Parameters
    ----------
    sphere : TriangleMesh
        Vertices on the unit sphere, n of them.
    log_factors : (n,) array
        s = log c per vertex.
    nvertices : int
        Vertices wanted, > n.
    fraction : float
        Largest share of the edges split in one round (0 < fraction ≤ 1).

    Returns
    -------
    (TriangleMesh, (nvertices,) array)
        The refined sphere (old vertices first, unchanged) and s on it.

    Raises
    ------
    MeshError
        If the vertices are not on the unit sphere.
    """
    sphere = _check_mesh(sphere)
    _check_sphere(sphere)
    s = _check_values(sphere, log_factors, "log_factors")
    nvertices = check_int(nvertices, "nvertices", minimum=sphere.nvertices + 1)
    fraction = check_float(fraction, "fraction", positive=True)
    if fraction > 1:
        raise InvalidArgumentError(f"fraction must be at most 1, got {fraction}")
    x = sphere.vertices
    while x.shape[0] < nvertices:
        e = edges(_hull(x)) if x.shape[0] != sphere.nvertices else edges(sphere)
        length = np.linalg.norm(x[e[:, 0]] - x[e[:, 1]], axis=1)
        ds = s[e[:, 0]] - s[e[:, 1]]
        metric = length * np.exp(0.25 * (s[e[:, 0]] + s[e[:, 1]])) * (1.0 + np.abs(ds))
        count = min(nvertices - x.shape[0], max(1, int(fraction * len(e))))
        split = e[np.argsort(-metric, kind="stable")[:count]]
        mid = x[split[:, 0]] + x[split[:, 1]]
        x = np.vstack([x, mid / np.linalg.norm(mid, axis=1)[:, None]])
        s = np.concatenate([s, 0.5 * (s[split[:, 0]] + s[split[:, 1]])])
    return _hull(x), s


@dataclass(frozen=True)
class FieldAlignment:
    """Result of :func:`align_vertex_field`.

    Attributes
    ----------
    values : (n_b,) array
        The fitted log factors, moved by the best Möbius map and element of O(3), at the reference vertices (linear
        interpolation on the moved fitted mesh).
    rotation : (3, 3) array
        The orthogonal matrix R (det ±1): values[j] = s_a'(R x_j) on the moved fitted sphere.
    translation : (3,) array
        The Möbius translation c (|c| < 1, :func:`~shspec.sphere.mobius.mobius_translate`) applied after the
        centring: the part of the Möbius map that the best fit adds to the canonical normalization.
    mirrored : bool
        det R = −1.
    rms : float
        Area-weighted RMS of values − s_b over the reference sphere.
    centred_rms : float
        The same after the centring and the best element of O(3) alone (no translation): what a comparison of the
        canonical representatives gives.
    """

    values: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    mirrored: bool
    rms: float
    centred_rms: float


class _Interpolant:
    """The linear interpolant of vertex values on a convex sphere mesh whose vertices may move (a Möbius map keeps
    the triangulation): the face the ray through a point crosses is found among the faces around its nearest
    vertices."""

    def __init__(self, sphere: TriangleMesh):
        n, f = sphere.nvertices, sphere.faces
        incidence = sp.csr_matrix((np.ones(f.size), (f.ravel(), np.repeat(np.arange(len(f)), 3))), shape=(n, len(f)))
        valence = np.diff(incidence.indptr)
        self.table = np.full((n, valence.max()), -1)
        for v in range(n):
            self.table[v, :valence[v]] = incidence.indices[incidence.indptr[v]:incidence.indptr[v + 1]]
        self.faces = f

    def __call__(self, vertices: np.ndarray, values: np.ndarray, points: np.ndarray) -> np.ndarray:
        f = self.faces
        _, near = cKDTree(vertices).query(points, k=min(4, len(vertices)))
        cand = self.table[near].reshape(len(points), -1)
        a, b, c = np.moveaxis(vertices[f[np.maximum(cand, 0)]], -2, 0)  # the candidate faces' corners
        # the coordinates of each point in the basis of its face's corners (Cramer's rule with cross products)
        bc, ca, ab = np.cross(b, c), np.cross(c, a), np.cross(a, b)
        p = points[:, None, :]
        lam = np.stack([np.sum(p * bc, -1), np.sum(p * ca, -1), np.sum(p * ab, -1)], -1) / np.sum(a * bc, -1)[..., None]
        score = np.where(cand >= 0, lam.min(-1), -np.inf)  # the crossed face has all three coordinates ≥ 0
        pick = np.argmax(score, axis=1)
        rows = np.arange(len(points))
        bary = lam[rows, pick] / lam[rows, pick].sum(-1, keepdims=True)
        return np.einsum("ij,ij->i", bary, values[f[cand[rows, pick]]])


_REFINED_SEEDS = 3  # octahedral seeds refined on the interpolant (the best by the harmonic misfit)
# The interpolant is piecewise linear in the vertex positions: finite differences over a step well above the rounding
# but below a triangle's size see its slope, and its kinks stop the steps short of tight tolerances (a few 1e-4 of
# the misfit is far below what a comparison reports).
_LSQ = {"diff_step": 1e-6, "xtol": 1e-6, "ftol": 1e-6, "max_nfev": 60}


def _moved(sphere: TriangleMesh, s: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices of ``sphere`` moved by the Möbius translation c, and the log factors that keep the surface: its
    vertex areas exp(s)·A stay, so s takes the log ratio of the sphere's vertex areas before and after (as cMCF
    defines its factors)."""
    x = mobius_translate(sphere.vertices, c)
    x /= np.linalg.norm(x, axis=1)[:, None]
    return x, s + np.log(vertex_areas(sphere) / vertex_areas(sphere.with_vertices(x)))


def align_vertex_field(sphere_a: TriangleMesh, s_a, sphere_b: TriangleMesh, s_b, *, lmax: int | None = None,
                       ) -> FieldAlignment:
    """Map log factors s_a on one unit-sphere mesh onto another mesh's vertices, up to Möbius maps and O(3).

    Sphere a is Möbius-centred with the areas exp(s_a)·(vertex areas) as weights (the truth's cMCF sphere is
    centred with its surface's areas: the same normalization), its factors taking the change of the sphere's vertex
    areas; s_a is expanded in harmonics of degree ``lmax`` (default: what sphere a determines, at most 10) and
    evaluated at R·x_b, and the 24 rotations of the octahedral group and their mirrors are ranked by the
    area-weighted squared difference to s_b.  From the best three the rotation and a Möbius translation are refined
    together (least squares) on the area-weighted difference of the linear interpolant of s_a to s_b: the centring
    alone depends on where the fit puts its area, and a field that misses part of it (the ears' peaks on a coarse
    mesh) is centred elsewhere although it is close to the truth up to a Möbius map.  The returned values are that
    interpolant at R·x_b.

    Parameters
    ----------
    sphere_a, sphere_b : TriangleMesh
        Unit-sphere meshes, n_a and n_b vertices (sphere b: the reference, e.g. the target's cMCF sphere).
    s_a : (n_a,) array
    s_b : (n_b,) array

    Returns
    -------
    FieldAlignment
    """
    for mesh in (sphere_a, sphere_b):
        _check_mesh(mesh)
        _check_sphere(mesh)
    s_a = _check_values(sphere_a, s_a, "s_a")
    s_b = _check_values(sphere_b, s_b, "s_b")
    centred = center_mesh(sphere_a, np.exp(s_a - s_a.max()) * vertex_areas(sphere_a)).sphere
    s_a = s_a + np.log(vertex_areas(sphere_a) / vertex_areas(centred))  # the surface stays (see _moved)
    la = mesh_band_limit(sphere_a.nvertices, 10 if lmax is None else lmax)
    coef = fit_harmonic(centred, s_a, la).coefficients
    w = vertex_areas(sphere_b)
    w = w / w.sum()
    xb = sphere_b.vertices

    def values(R):
        return harmonic_matrix(xb @ R.T, la) @ coef

    def misfit(R):
        d = values(R) - s_b
        return float(w @ (d * d))

    seeds = []
    for mirror in (1.0, -1.0):
        for rot in Rotation.create_group("O"):
            R = rot.as_matrix() @ np.diag([1.0, 1.0, mirror])
            seeds.append((misfit(R), R))
    seeds.sort(key=lambda t: t[0])
    interpolant = _Interpolant(centred)
    sw = np.sqrt(w)
    # Bounds keep the translation well inside the ball, where it is a map of the sphere.
    bounds = (np.r_[-np.inf, -np.inf, -np.inf, -0.5, -0.5, -0.5], np.r_[np.inf, np.inf, np.inf, 0.5, 0.5, 0.5])
    best = None
    for _, R0 in seeds[:_REFINED_SEEDS]:
        def residual(v, R0=R0):
            x, s = _moved(centred, s_a, v[3:])
            return sw * (interpolant(x, s, xb @ (Rotation.from_rotvec(v[:3]).as_matrix() @ R0).T) - s_b)

        res = scipy.optimize.least_squares(residual, np.zeros(6), bounds=bounds, **_LSQ)
        if best is None or 2 * res.cost < best[0]:
            best = (2 * res.cost, res.x, R0, residual, res.fun / sw + s_b)
    _, v, R0, residual, out = best
    R = Rotation.from_rotvec(v[:3]).as_matrix() @ R0
    # the canonical representatives' misfit: the centring and the best rotation, no translation
    canonical = scipy.optimize.least_squares(lambda u: residual(np.r_[u, 0.0, 0.0, 0.0]), v[:3], **_LSQ)
    return FieldAlignment(values=out, rotation=R, translation=v[3:].copy(), mirrored=bool(np.linalg.det(R) < 0),
                          rms=float(np.sqrt(w @ (out - s_b) ** 2)), centred_rms=float(np.sqrt(2 * canonical.cost)))


def refined_eigenvalues(mesh: TriangleMesh, k: int, levels: int = 1, factors=None) -> np.ndarray:
    """The first k cotan eigenvalues of a mesh and of its repeated 4-to-1 midpoint subdivisions (module notes).

    Parameters
    ----------
    mesh : TriangleMesh
        n vertices; with ``factors`` a unit-sphere mesh.
    k : int
        Number of eigenvalues, 2 ≤ k < n.
    levels : int
        Number of subdivisions, ≥ 1 (the last mesh has about 4^levels · n vertices).
    factors : (n,) array, optional
        Per-vertex conformal factors c (mass diag(c)·M_lumped); on each subdivision log c is interpolated linearly
        and the new vertices are projected to the sphere.

    Returns
    -------
    (levels + 1, k) array
        Row j: λ_i on the mesh subdivided j times, λ₀ = 0 exactly.
    """
    mesh = _check_mesh(mesh)
    k = check_int(k, "k", minimum=2, maximum=mesh.nvertices - 1)
    levels = check_int(levels, "levels", minimum=1)
    if factors is None:
        log_c = None
    else:
        c = _check_values(mesh, factors, "factors")
        if np.any(c <= 0):
            raise InvalidArgumentError("factors must be > 0")
        log_c = np.log(c)
    out = np.empty((levels + 1, k))
    for j in range(levels + 1):
        if j:
            mesh, log_c = subdivide(mesh, log_c, project=log_c is not None)
        c = np.ones(mesh.nvertices) if log_c is None else np.exp(log_c)
        out[j] = eigenpairs(cotan_stiffness(mesh), sp.diags(c * vertex_areas(mesh)), k).eigenvalues
    out[:, 0] = 0.0
    return out


def subdivision_eigenvalues(mesh: TriangleMesh, k: int, factors=None) -> tuple[np.ndarray, np.ndarray]:
    """The first k cotan eigenvalues of a mesh and of its 4-to-1 midpoint subdivision: (coarse (k,), fine (k,)),
    both with λ₀ = 0 exactly (:func:`refined_eigenvalues` with one level, same arguments)."""
    coarse, fine = refined_eigenvalues(mesh, k, 1, factors)
    return coarse, fine


def eigenvalue_errors(mesh: TriangleMesh, k: int, factors=None) -> tuple[np.ndarray, np.ndarray]:
    """Estimated relative discretization errors of the first k cotan eigenvalues of a mesh: their relative changes
    under one subdivision (:func:`subdivision_eigenvalues`, same arguments).

    Returns
    -------
    (eigenvalues (k,), errors (k,))
        λ_i on the mesh and |λ_i − λ_i'| / λ_i against the subdivided mesh (error 0 for λ₀ = 0).
    """
    lam, ref = subdivision_eigenvalues(mesh, k, factors)
    err = np.zeros(lam.size)
    err[1:] = np.abs(lam[1:] - ref[1:]) / lam[1:]
    return lam, err


def trusted_numeig(errors, tol: float) -> int:
    """The largest K such that every estimated error of eigenvalues 1..K−1 is ≤ ``tol`` (K ≥ 2 when the first
    one is; raises InvalidArgumentError if even λ₁ exceeds it)."""
    err = np.asarray(errors, dtype=float)
    tol = check_float(tol, "tol", positive=True)
    if err.ndim != 1 or err.size < 2:
        raise InvalidArgumentError("errors must be a (k,) array with k >= 2")
    bad = np.flatnonzero(err[1:] > tol)
    if bad.size and bad[0] == 0:
        raise InvalidArgumentError(f"even the first eigenvalue's estimated error {err[1]:.3g} exceeds {tol:g}")
    return int(err.size if not bad.size else bad[0] + 1)
