"""Real spherical harmonics at points of the sphere: the one evaluation path of shspec for scattered points.

Harmonics are shspec's (pyshtools ``normalization='ortho'``, ``csphase=1``, flat index ``l*l + l + m``); a point
x on the unit sphere has colatitude θ = arccos z (from +z) and longitude φ = atan2(y, x) (from +x).  They are
evaluated with :func:`scipy.special.sph_harm_y` (complex, with the Condon–Shortley phase), converted by
Y_{l,m>0} = √2 (−1)^m Re Y_l^m and Y_{l,−m} = √2 (−1)^m Im Y_l^m; tests check this against pyshtools.  On the
nodes of a Gauss–Legendre grid, :mod:`shspec.sphere.grid` (a fast transform) serves instead.
"""

from __future__ import annotations

import numpy as np
import pyshtools
from scipy.special import sph_harm_y

from ..errors import InvalidArgumentError
from ..core.threads import PYSHTOOLS_LOCK
from .harmonics import as_coefficients, check_degree, degree_order, vector_to_cilm

__all__ = ["points_to_angles", "harmonic_matrix", "sample_harmonic", "weighted_expansion", "weighted_misfit"]


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
    """Values (n,) of the harmonic expansion ``coeffs`` (flat vector, cilm array or SHCoeffs) at points (n, 3).

    Summed by pyshtools' ``MakeGridPoint`` point by point (the same harmonics as :func:`harmonic_matrix`, to
    rounding), which needs no (n, (L+1)²) matrix: at degree 48 on 20000 points it took 1.6 s where the matrix took
    130 s on a loaded machine (the Möbius centring of a fitted ρ evaluates it at every Newton step).
    """
    a = as_coefficients(coeffs)
    theta, phi = points_to_angles(points)
    with PYSHTOOLS_LOCK:
        values = pyshtools.expand.MakeGridPoint(vector_to_cilm(a), 90.0 - np.degrees(theta), np.degrees(phi),
                                                norm=4, csphase=1)
    return np.atleast_1d(np.asarray(values, dtype=float))


def weighted_expansion(points, weights, values, lmax: int) -> tuple[np.ndarray, float]:
    """The weighted least-squares expansion of values at points: a = argmin Σ_i w_i (f_i − Σ_k a_k Y_k(x_i))².

    Parameters
    ----------
    points : (n, 3) array
        Points; only their directions matter.
    weights : (n,) array
        Quadrature weights w_i > 0 (e.g. the lumped vertex areas of a sphere mesh).
    values : (n,) array
        f_i, finite.
    lmax : int
        Band limit L; (L + 1)² must not exceed n.

    Returns
    -------
    a : ((L + 1)²,) array
        Flat coefficients (the unit of the values).
    residual : float
        ‖f − Σ a_k Y_k‖_w / ‖f‖_w, the relative weighted L2 misfit at the points.
    """
    y = harmonic_matrix(points, lmax)
    w = np.asarray(weights, dtype=float)
    f = np.asarray(values, dtype=float)
    if w.shape != (y.shape[0],) or f.shape != (y.shape[0],):
        raise InvalidArgumentError(f"weights and values must have shape ({y.shape[0]},), got {w.shape} and {f.shape}")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(w)) and np.all(w > 0)):
        raise InvalidArgumentError("values must be finite and weights finite and > 0")
    if y.shape[1] > y.shape[0]:
        raise InvalidArgumentError(f"lmax = {lmax} needs {y.shape[1]} coefficients; {y.shape[0]} points are too few")
    sw = np.sqrt(w)
    a = np.linalg.lstsq(sw[:, None] * y, sw * f, rcond=None)[0]
    return a, weighted_misfit(f, y @ a, w)


def weighted_misfit(values, fitted, weights) -> float:
    """‖f − g‖_w / ‖f‖_w: the relative weighted L2 misfit of fitted values g (n,) to values f (n,) with weights
    w (n,)."""
    r = values - fitted
    return float(np.sqrt(np.sum(weights * r * r) / max(np.sum(weights * values * values), np.finfo(float).tiny)))
