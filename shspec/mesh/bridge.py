"""The bridge between per-vertex values on a spherical mesh and real spherical-harmonic coefficients.

The harmonics are evaluated at the vertices by :func:`shspec.sphere.evaluate.harmonic_matrix`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.checks import check_int
from ..errors import InvalidArgumentError, MeshError
from ..sphere.evaluate import harmonic_matrix, weighted_expansion, weighted_misfit
from ..sphere.harmonics import check_degree
from .cotan import vertex_areas
from .triangle_mesh import TriangleMesh

__all__ = ["fit_harmonic", "mesh_band_limit", "HarmonicFit", "FIT_METHODS"]

#: Ways to expand vertex values: area-weighted least squares, or the lumped-area quadrature a_k = Σ A_i f_i Y_k(x_i).
FIT_METHODS = ("lsq", "quadrature")


def mesh_band_limit(nvertices: int, lmax_factor: int | None = None) -> int:
    """The largest degree L whose (L+1)² coefficients a least-squares fit on ``nvertices`` vertices determines well
    (at least two vertices per coefficient, the rule of :func:`fit_harmonic`), capped at ``lmax_factor``."""
    nvertices = check_int(nvertices, "the number of vertices", minimum=8)
    la = int(np.sqrt(nvertices / 2)) - 1
    return la if lmax_factor is None else min(check_degree(lmax_factor, "lmax_factor"), la)


@dataclass(frozen=True)
class HarmonicFit:
    """Harmonic expansion of per-vertex values.

    Attributes
    ----------
    coefficients : ((lmax+1)**2,) array
        Flat coefficient vector (same unit as the values).
    lmax : int
        Band limit.
    method : str
        "lsq" or "quadrature".
    residual : float
        Relative area-weighted L2 misfit ‖f − Σ a_k Y_k‖ / ‖f‖ at the vertices (lumped sphere areas).

    Examples
    --------
    >>> from shspec.mesh import blob, cmcf, fit_harmonic
    >>> flow = cmcf(blob(2))
    >>> fit = fit_harmonic(flow.sphere, flow.factors, 4)
    >>> fit.lmax, fit.method
    (4, 'lsq')
    """

    coefficients: np.ndarray
    lmax: int
    method: str
    residual: float


def fit_harmonic(sphere: TriangleMesh, values, lmax: int, method: str = "lsq") -> HarmonicFit:
    """Expand per-vertex values on a spherical mesh in real harmonics up to degree lmax.

    Parameters
    ----------
    sphere : TriangleMesh
        A mesh whose vertices lie on the unit sphere (n vertices), e.g. :attr:`CMCFResult.sphere`.
    values : (n,) array
        One value per vertex, e.g. conformal factors.
    lmax : int
        Band limit La; "lsq" needs (lmax+1)**2 well below n.
    method : {"lsq", "quadrature"}
        "lsq": minimize Σ_i A_i (f_i − Σ_k a_k Y_k(x_i))² with A_i the lumped vertex areas of the sphere mesh;
        exact for band-limited data.  "quadrature": a_k = Σ_i A_i f_i Y_k(x_i), an O(h²) approximation of the
        integral, cheaper and not exact.

    Returns
    -------
    HarmonicFit

    Raises
    ------
    MeshError
        If the vertices are not on the unit sphere (to 1e-6).
    InvalidArgumentError
        If the values have the wrong shape or are not finite, the method is unknown, or lmax is too large for
        the number of vertices.

    Examples
    --------
    >>> from shspec.mesh import blob, cmcf, fit_harmonic
    >>> flow = cmcf(blob(2))
    >>> expansion = fit_harmonic(flow.sphere, flow.factors, 4)   # the factors in harmonics of degree <= 4
    >>> expansion.coefficients.shape, expansion.residual < 0.05
    ((25,), True)
    """
    if not isinstance(sphere, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(sphere).__name__}")
    radius = np.linalg.norm(sphere.vertices, axis=1)
    if np.max(np.abs(radius - 1.0)) > 1e-6:
        raise MeshError(f"the vertices are not on the unit sphere: |x| − 1 reaches {np.max(np.abs(radius - 1)):.3g}")
    f = np.asarray(values, dtype=float)
    if f.shape != (sphere.nvertices,):
        raise InvalidArgumentError(f"values must have shape ({sphere.nvertices},), got {f.shape}")
    if not np.all(np.isfinite(f)):
        raise InvalidArgumentError("values contain NaN or inf")
    if method not in FIT_METHODS:
        raise InvalidArgumentError(f"method must be one of {FIT_METHODS}, got {method!r}")
    lmax = check_degree(lmax, "lmax")
    if 2 * (lmax + 1) ** 2 > sphere.nvertices:
        raise InvalidArgumentError(f"lmax = {lmax} needs {(lmax + 1) ** 2} coefficients; with {sphere.nvertices} "
                                   "vertices use at most half as many")
    w = vertex_areas(sphere)
    if method == "lsq":
        a, residual = weighted_expansion(sphere.vertices, w, f, lmax)
        return HarmonicFit(a, lmax, method, residual)
    Y = harmonic_matrix(sphere.vertices, lmax)
    a = Y.T @ (w * f)
    return HarmonicFit(a, lmax, method, weighted_misfit(f, Y @ a, w))
