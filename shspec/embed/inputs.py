"""Per-vertex conformal factors of a sphere mesh from whatever the caller has (values, or a harmonic ρ)."""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError
from ..mesh.triangle_mesh import TriangleMesh
from ..sphere.evaluate import sample_harmonic
from ..sphere.factor import ConformalFactor
from .lengths import check_factors, check_sphere

__all__ = ["vertex_factors"]


def vertex_factors(sphere: TriangleMesh, factors) -> np.ndarray:
    """Per-vertex factors (n,) of a sphere mesh from per-vertex values or a harmonic ρ sampled at the vertices.

    Parameters
    ----------
    sphere : TriangleMesh
        Unit-sphere mesh, n vertices.
    factors : (n,) array, ConformalFactor, pyshtools SHCoeffs, cilm array (2, L+1, L+1) or (N,) coefficients
        A (n,) array is read as per-vertex values, also when n happens to be a square (L+1)²; any other 1-D
        length (L+1)² as flat harmonic coefficients of ρ (shspec's convention), which are evaluated at the vertex
        directions (:func:`~shspec.mesh.bridge.sample_harmonic`).

    Returns
    -------
    (n,) array
        Values c > 0.

    Raises
    ------
    InvalidArgumentError
        Not numeric, or a length that is neither n nor a square.
    NotPositiveError
        ρ ≤ 0 at some vertex (a band-limited expansion of extreme factors can be).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import ConformalFactor
    >>> from shspec.embed import vertex_factors
    >>> from shspec.mesh import icosphere
    >>> a = np.zeros(4); a[0] = np.sqrt(4 * np.pi)    # rho = 1, as harmonic coefficients
    >>> vertex_factors(icosphere(1), ConformalFactor(a))[:3].round(12)
    array([1., 1., 1.])
    """

    sphere = check_sphere(sphere)
    n = sphere.nvertices
    if isinstance(factors, ConformalFactor):
        values = sample_harmonic(factors.coefficients, sphere.vertices)
    elif type(factors).__module__.startswith("pyshtools"):
        values = sample_harmonic(factors, sphere.vertices)
    else:
        try:
            arr = np.asarray(factors, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidArgumentError(f"factors must be numeric: {exc}") from None
        if arr.shape == (n,):
            values = arr
        elif arr.ndim == 3 or (arr.ndim == 1 and arr.size > 0 and round(np.sqrt(arr.size)) ** 2 == arr.size):
            if not np.all(np.isfinite(arr)):
                raise InvalidArgumentError("harmonic coefficients contain NaN or inf")
            values = sample_harmonic(arr, sphere.vertices)
        else:
            raise InvalidArgumentError(f"factors must be ({n},) per-vertex values or (L+1)² harmonic coefficients, "
                                       f"got shape {arr.shape}")
    return check_factors(values, n)
