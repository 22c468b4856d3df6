"""Möbius centering of a spherical mesh: the representative whose area measure has its centre of mass at the origin
(Baden, Crane, Kazhdan, "Möbius Registration", SGP 2018).  The maps and the Newton step are those of
:mod:`shspec.sphere.mobius`, which also centres a harmonic ρ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.checks import finite_array
from ..errors import ConvergenceError, InvalidArgumentError, MeshError, NotPositiveError
from ..sphere.mobius import mobius_translate, newton_step
from .triangle_mesh import TriangleMesh

__all__ = ["center_mesh", "MeshCentering"]


@dataclass(frozen=True)
class MeshCentering:
    """Result of :func:`center_mesh`.

    Attributes
    ----------
    sphere : TriangleMesh
        The centred spherical mesh (vertices on the unit sphere).
    center : (3,) array
        Final centre of mass Σ w_i x_i / Σ w_i (its norm is the residual).
    iterations : int
        Newton steps taken.

    Examples
    --------
    >>> from shspec.mesh import blob, center_mesh, cmcf, vertex_areas
    >>> flow = cmcf(blob(2))
    >>> centred = center_mesh(flow.sphere, flow.factors * vertex_areas(flow.sphere))
    >>> centred.sphere.nvertices, centred.center.shape
    (162, (3,))
    """

    sphere: TriangleMesh
    center: np.ndarray
    iterations: int


def center_mesh(sphere: TriangleMesh, weights, *, tol: float = 1e-12, max_iter: int = 50) -> MeshCentering:
    """Möbius-centre a spherical mesh: move its vertices by sphere translations until Σ w_i x_i = 0.

    Parameters
    ----------
    sphere : TriangleMesh
        Vertices on the unit sphere (n, 3).
    weights : (n,) array
        Positive mass per vertex, e.g. the vertex areas of the original surface (the pulled-back area measure,
        which a Möbius map of the sphere does not change).
    tol : float, default 1e-12
        Stop when |Σ w_i x_i| / Σ w_i ≤ tol.
    max_iter : int, default 50

    Returns
    -------
    MeshCentering

    Raises
    ------
    MeshError
        If the vertices are not on the unit sphere (to 1e-8).
    NotPositiveError
        If a weight is ≤ 0.
    ConvergenceError
        If the tolerance is not met after ``max_iter`` steps.

    Examples
    --------
    >>> from shspec.mesh import center_mesh, icosphere, vertex_areas
    >>> sphere = icosphere(2)
    >>> centred = center_mesh(sphere, vertex_areas(sphere))   # already centred: no Moebius map needed
    >>> abs(centred.center).max() < 1e-12, centred.iterations
    (True, 0)
    """
    if not isinstance(sphere, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(sphere).__name__}")
    x = sphere.vertices
    off = np.max(np.abs(np.linalg.norm(x, axis=1) - 1.0))
    if off > 1e-8:
        raise MeshError(f"the vertices are not on the unit sphere: |x| − 1 reaches {off:.3g}")
    w = finite_array(weights, "weights", (sphere.nvertices,))
    if np.any(w <= 0):
        raise NotPositiveError(f"weights must be > 0; vertex {int(np.flatnonzero(w <= 0)[0])} has "
                               f"{w[w <= 0][0]:.3g}")
    if not 0 < tol < 1:
        raise InvalidArgumentError(f"tol must be in (0, 1), got {tol}")
    for it in range(max_iter + 1):
        step, center = newton_step(x, w)
        if np.linalg.norm(center) <= tol:
            return MeshCentering(sphere.with_vertices(x), center, it)
        x = mobius_translate(x, step)
        # Renormalize: each step is exact on the sphere up to rounding, which would otherwise accumulate.
        x /= np.linalg.norm(x, axis=1)[:, None]
    raise ConvergenceError(f"Möbius centering: |centre| = {np.linalg.norm(center):.3g} > {tol:g} after "
                           f"{max_iter} Newton steps")

