"""Cotangent stiffness and mass matrices of the piecewise-linear Laplace–Beltrami operator.

With hat functions φ_i, the stiffness is L_ij = ∫ ∇φ_i·∇φ_j dA (off-diagonal −½(cot α_ij + cot β_ij), rows summing
to zero, positive semi-definite; dimensionless) and the consistent mass is M_ij = ∫ φ_i φ_j dA (area/6 on the
diagonal and area/12 off it, per triangle).  The lumped mass puts one third of each triangle's area on its
vertices.  The spectrum is L v = λ M v, with λ in 1/area.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..core.checks import check_choice
from ..errors import InvalidArgumentError
from .triangle_mesh import TriangleMesh

__all__ = ["cotan_stiffness", "mass_matrix", "vertex_areas", "MASS_KINDS"]

#: The two mass matrices: "lumped" (diagonal, vertex areas) and "consistent" (the exact P1 Gram matrix).
MASS_KINDS = ("lumped", "consistent")


def _mesh(mesh) -> TriangleMesh:
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    return mesh


def cotan_stiffness(mesh: TriangleMesh) -> sp.csr_matrix:
    """Cotangent stiffness matrix L (n, n), symmetric positive semi-definite, dimensionless.

    Parameters
    ----------
    mesh : TriangleMesh
        n vertices, m non-degenerate faces.

    Returns
    -------
    scipy.sparse.csr_matrix
        L with L_ij = −½(cot α_ij + cot β_ij) for an edge ij, L_ii = −Σ_j L_ij, zero elsewhere.

    Examples
    --------
    >>> from shspec.mesh import cotan_stiffness, icosphere
    >>> L = cotan_stiffness(icosphere(2))
    >>> L.shape, abs(L.sum()) < 1e-12          # (n, n), constants in its kernel
    ((162, 162), True)
    """
    mesh = _mesh(mesh)
    p = mesh.vertices[mesh.faces]
    f = mesh.faces
    # Edge opposite to corner k: e_k = p[k+2] − p[k+1]; cot of the angle at corner k = (e_{k+1}·e_{k+2}) / |cross|.
    e = np.stack([p[:, 2] - p[:, 1], p[:, 0] - p[:, 2], p[:, 1] - p[:, 0]], axis=1)
    dbl_area = np.linalg.norm(np.cross(e[:, 0], e[:, 1]), axis=1)
    n = mesh.nvertices
    rows, cols, vals = [], [], []
    for k in range(3):
        i, j = f[:, (k + 1) % 3], f[:, (k + 2) % 3]
        cot = -np.einsum("ij,ij->i", e[:, (k + 1) % 3], e[:, (k + 2) % 3]) / dbl_area
        w = -0.5 * cot
        rows += [i, j, i, j]
        cols += [j, i, i, j]
        vals += [w, w, -w, -w]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))


def vertex_areas(mesh: TriangleMesh) -> np.ndarray:
    """(n,) array of lumped vertex areas: one third of the area of each incident face (length unit squared).

    Examples
    --------
    >>> from shspec.mesh import icosphere, vertex_areas
    >>> sphere = icosphere(2)
    >>> areas = vertex_areas(sphere)          # a third of each face's area at each of its vertices
    >>> areas.shape, round(areas.sum(), 6) == round(sphere.area(), 6)
    ((162,), True)
    """
    mesh = _mesh(mesh)
    third = np.repeat(mesh.face_areas() / 3.0, 3)
    return np.bincount(mesh.faces.ravel(), weights=third, minlength=mesh.nvertices)


def mass_matrix(mesh: TriangleMesh, kind: str = "lumped") -> sp.csr_matrix:
    """Mass matrix M (n, n) in length unit squared.

    Parameters
    ----------
    mesh : TriangleMesh
        n vertices.
    kind : {"lumped", "consistent"}
        "lumped": diagonal of vertex areas; "consistent": the P1 Gram matrix ∫ φ_i φ_j dA.

    Returns
    -------
    scipy.sparse.csr_matrix
        Symmetric positive definite for a mesh without isolated vertices or degenerate faces.

    Raises
    ------
    InvalidArgumentError
        If ``kind`` is not one of :data:`MASS_KINDS`.

    Examples
    --------
    >>> from shspec.mesh import icosphere, mass_matrix
    >>> sphere = icosphere(2)
    >>> round(mass_matrix(sphere).sum(), 6) == round(sphere.area(), 6)   # either kind sums to the area
    True
    """
    mesh = _mesh(mesh)
    check_choice(kind, "mass kind", MASS_KINDS)
    n = mesh.nvertices
    if kind == "lumped":
        return sp.diags(vertex_areas(mesh)).tocsr()
    f = mesh.faces
    a = mesh.face_areas()
    rows = np.concatenate([f[:, i] for i in range(3) for _ in range(3)])
    cols = np.concatenate([f[:, j] for _ in range(3) for j in range(3)])
    vals = np.concatenate([a / 6.0 if i == j else a / 12.0 for i in range(3) for j in range(3)])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
