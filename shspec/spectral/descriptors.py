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

from ..checks import check_int
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
    """
    lam = as_eigenvalues(eigenvalues, minimum=1)
    phi = np.asarray(eigenvectors, dtype=float)
    if phi.ndim != 2 or phi.shape[1] != lam.size:
        raise InvalidArgumentError(f"eigenvectors must have shape (n, {lam.size}), got {phi.shape}")
    if not np.all(np.isfinite(phi)):
        raise InvalidArgumentError("eigenvectors hold NaN or inf")
    t = as_times(t)
    return (phi * phi) @ np.exp(-np.outer(lam, t))
