"""The bridge between per-vertex values on a spherical mesh and real spherical-harmonic coefficients.

Harmonics are shspec's (pyshtools ``normalization='ortho'``, ``csphase=1``, flat index ``l*l + l + m``); a point
x on the unit sphere has colatitude θ = arccos z (from +z) and longitude φ = atan2(y, x) (from +x).  They are
evaluated with :func:`scipy.special.sph_harm_y` (complex, with the Condon–Shortley phase), converted by
Y_{l,m>0} = √2 (−1)^m Re Y_l^m and Y_{l,−m} = √2 (−1)^m Im Y_l^m; tests check this against pyshtools.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import sph_harm_y

from ..errors import InvalidArgumentError, MeshError
from ..harmonics import as_coefficients, check_degree, degree_order, lmax_of_size
from .cotan import vertex_areas
from .triangle_mesh import TriangleMesh

__all__ = ["harmonic_matrix", "sample_harmonic", "fit_harmonic", "HarmonicFit", "FIT_METHODS",
           "points_to_angles"]

#: Ways to expand vertex values: area-weighted least squares, or the lumped-area quadrature a_k = Σ A_i f_i Y_k(x_i).
FIT_METHODS = ("lsq", "quadrature")


def _points(points) -> np.ndarray:
    try:
        x = np.asarray(points, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"points must be numeric: {exc}") from None
    if x.ndim != 2 or x.shape[1] != 3:
        raise InvalidArgumentError(f"points must have shape (n, 3), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise InvalidArgumentError("points contain NaN or inf")
    r = np.linalg.norm(x, axis=1)
    if np.any(r == 0):
        raise InvalidArgumentError(f"point {int(np.flatnonzero(r == 0)[0])} is the origin: it has no direction")
    return x


def points_to_angles(points) -> tuple[np.ndarray, np.ndarray]:
    """Colatitude θ ∈ [0, π] and longitude φ ∈ (−π, π] (radians), each (n,), of the directions of points (n, 3)."""
    x = _points(points)
    r = np.linalg.norm(x, axis=1)
    theta = np.arccos(np.clip(x[:, 2] / r, -1.0, 1.0))
    phi = np.arctan2(x[:, 1], x[:, 0])
    return theta, phi


def harmonic_matrix(points, lmax: int) -> np.ndarray:
    """Real orthonormal harmonics at the directions of points.

    Parameters
    ----------
    points : (n, 3) array
        Points; only their directions matter.
    lmax : int
        Band limit.

    Returns
    -------
    (n, (lmax+1)**2) array
        Column i is Y_i, i = l*l + l + m, evaluated at every point.
    """
    lmax = check_degree(lmax, "lmax")
    theta, phi = points_to_angles(points)
    l, m = degree_order(lmax)
    am = np.abs(m)
    y = sph_harm_y(l[None, :], am[None, :], theta[:, None], phi[:, None])
    scale = np.where(am % 2 == 0, 1.0, -1.0) * np.where(m == 0, 1.0, np.sqrt(2.0))
    out = scale * np.where(m < 0, y.imag, y.real)
    return out


def sample_harmonic(coeffs, points) -> np.ndarray:
    """Values (n,) of the harmonic expansion ``coeffs`` (flat vector, cilm array or SHCoeffs) at points (n, 3)."""
    a = as_coefficients(coeffs)
    return harmonic_matrix(points, lmax_of_size(a.size)) @ a


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
    Y = harmonic_matrix(sphere.vertices, lmax)
    if method == "lsq":
        sw = np.sqrt(w)
        a = np.linalg.lstsq(sw[:, None] * Y, sw * f, rcond=None)[0]
    else:
        a = Y.T @ (w * f)
    r = f - Y @ a
    residual = float(np.sqrt(np.sum(w * r * r) / max(np.sum(w * f * f), np.finfo(float).tiny)))
    return HarmonicFit(a, lmax, method, residual)
