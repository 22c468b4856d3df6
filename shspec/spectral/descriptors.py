"""The descriptors users of LaPy and Shape-DNA expect: normalized eigenvalues, the heat trace, the heat kernel signature.

Normalization.  Shape-DNA (Reuter, Wolter, Peinecke 2006) compares surfaces by the eigenvalues of the surface
scaled to unit area, λ_n·A (λ scales like 1/length²): exactly LaPy's ``shapedna.normalize_ev(mesh, evals,
method="geometry")`` for a triangle mesh.  ``reweight=True`` divides the n-th value (1-based) by n, LaPy's
``reweight_ev``, which evens out the growth of Weyl's law (λ_n A ≈ 4πn).

Heat kernel signature (Sun, Ovsjanikov, Guibas 2009).  HKS(x, t) = Σ_n e^{−λ_n t} φ_n(x)² with M-orthonormal
eigenfunctions φ_n (``VᵀMV = I``, as :func:`~shspec.mesh.eigen.mesh_spectrum` returns them); its mass-weighted sum
over the vertices is the heat trace Z(t).  The default times are theirs: log-spaced from 4 ln 10/λ_K to 4 ln 10/λ₁.
"""

from __future__ import annotations

import numpy as np

from ..core.checks import check_int
from ..errors import InvalidArgumentError
from .heat import as_eigenvalues, as_times

__all__ = ["shape_dna", "hks_times", "heat_kernel_signature"]


def shape_dna(eigenvalues, area: float, *, reweight: bool = False) -> np.ndarray:
    """Area-normalized eigenvalues λ_n·A (Reuter et al.'s unit-area normalization; module notes).

    Parameters
    ----------
    eigenvalues : (k,) array_like
        λ₀ = 0 first, ascending, 1/area.
    area : float
        Surface area A > 0.
    reweight : bool
        Divide the n-th value (1-based) by n, as LaPy's ``reweight_ev``.

    Returns
    -------
    (k,) ndarray
        Dimensionless.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import shape_dna
    >>> shape_dna(np.array([0.0, 2.0, 2.0, 2.0, 6.0]), area=4 * np.pi).round(2)   # lambda * area: scale-free
    array([ 0.  , 25.13, 25.13, 25.13, 75.4 ])
    """
    lam = as_eigenvalues(eigenvalues, minimum=1)
    area = float(area)
    if not (np.isfinite(area) and area > 0):
        raise InvalidArgumentError(f"area must be finite and positive, got {area}")
    out = lam * area
    return out / np.arange(1, out.size + 1) if reweight else out


def hks_times(eigenvalues, count: int = 16) -> np.ndarray:
    """``count`` log-spaced times from 4 ln 10/λ_K to 4 ln 10/λ₁ (Sun et al.), area units, (count,).

    Raises
    ------
    InvalidArgumentError
        If λ₁ is 0 (a second component) or fewer than two eigenvalues are given.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import hks_times
    >>> l = np.repeat(np.arange(20), 2 * np.arange(20) + 1)
    >>> hks_times(l * (l + 1.0), 4).round(4)      # log-spaced between the spectrum's scales
    array([0.0242, 0.1393, 0.8011, 4.6052])
    """
    lam = as_eigenvalues(eigenvalues, minimum=2)
    count = check_int(count, "count", minimum=1, maximum=100_000)
    if lam[1] <= 0:
        raise InvalidArgumentError("λ₁ = 0: the surface has several components; give the times explicitly")
    return np.geomspace(4 * np.log(10) / lam[-1], 4 * np.log(10) / lam[1], count)


def heat_kernel_signature(eigenvalues, eigenvectors, t) -> np.ndarray:
    """HKS(x, t) = Σ_n e^{−λ_n t} φ_n(x)² per vertex (module notes).

    Parameters
    ----------
    eigenvalues : (k,) array_like
    eigenvectors : (n, k) array_like
        M-orthonormal eigenfunctions, column n belonging to λ_n.
    t : float or (p,) array_like
        Times > 0 (area units).

    Returns
    -------
    (n, p) ndarray
        Units 1/area (φ² is a density).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.mesh import icosphere, mesh_spectrum
    >>> from shspec.spectral import heat_kernel_signature
    >>> spec = mesh_spectrum(icosphere(1), 4)
    >>> heat_kernel_signature(spec.eigenvalues, spec.eigenvectors, np.array([0.1, 1.0])).shape   # (vertices, times)
    (42, 2)
    """
    lam = as_eigenvalues(eigenvalues, minimum=1)
    phi = np.asarray(eigenvectors, dtype=float)
    if phi.ndim != 2 or phi.shape[1] != lam.size:
        raise InvalidArgumentError(f"eigenvectors must have shape (n, {lam.size}), got {phi.shape}")
    if not np.all(np.isfinite(phi)):
        raise InvalidArgumentError("eigenvectors hold NaN or inf")
    t = as_times(t)
    return (phi * phi) @ np.exp(-np.outer(lam, t))
