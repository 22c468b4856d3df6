"""The heat trace Z(t) = Σ_n e^{−λ_n t} of a spectrum, and Weyl's estimate of what a truncated spectrum misses.

For a closed surface of area A and Euler characteristic χ, Z(t) = A/(4πt) + χ/6 + a₁t + O(t²) as t → 0
(McKean–Singer; a₁ = ∫K² dA/(60π)), and Z(t) → 1 (the constants, λ₀ = 0) as t → ∞.  A spectrum known only up to
λ_K misses Σ_{n>K} e^{−λ_n t}; with a density dN/dλ = ρ above λ_K that tail is ∫_{λ_K}^∞ ρ e^{−λt} dλ = ρe^{−λ_K t}/t
(:func:`spectral_tail`; Weyl's law has ρ = A/(4π), a mesh's cotan spectrum a larger and growing one).
"""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError

__all__ = ["as_eigenvalues", "as_times", "heat_trace", "spectral_tail"]


def as_eigenvalues(values, *, minimum: int = 2, zero_rtol: float = 1e-8) -> np.ndarray:
    """A spectrum as a float array (k,), checked: finite, ascending, λ₀ = 0 first, the rest positive.

    Parameters
    ----------
    values : array_like, (k,)
        Eigenvalues in 1/area.  λ₀ within ``zero_rtol``·max|λ| of 0 (rounding of a mesh solver) is set to exactly 0.
    minimum : int
        Fewest eigenvalues accepted.

    Raises
    ------
    InvalidArgumentError
        If the values are not a finite 1-d array of at least ``minimum`` entries starting at 0 and ascending.

    Examples
    --------
    >>> from shspec.spectral import as_eigenvalues
    >>> as_eigenvalues([0, 2, 2, 2, 6.0])         # checked: lambda_0 = 0, ascending, finite
    array([0., 2., 2., 2., 6.])
    """
    try:
        lam = np.array(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"eigenvalues must be numeric: {exc}") from None
    if lam.ndim != 1 or lam.size < minimum:
        raise InvalidArgumentError(f"need a 1-d spectrum of at least {minimum} eigenvalues, got shape {lam.shape}")
    bad = np.flatnonzero(~np.isfinite(lam))
    if bad.size:
        raise InvalidArgumentError(f"eigenvalue {bad[0]} is {lam[bad[0]]}; eigenvalues must be finite")
    scale = np.abs(lam).max()
    if abs(lam[0]) > zero_rtol * scale:
        raise InvalidArgumentError(f"a closed surface's spectrum starts with λ₀ = 0, got λ₀ = {lam[0]:g}")
    lam[0] = 0.0
    drop = np.flatnonzero(np.diff(lam) < -zero_rtol * scale)
    if drop.size:
        i = int(drop[0])
        raise InvalidArgumentError(f"eigenvalues must ascend: λ_{i + 1} = {lam[i + 1]:g} < λ_{i} = {lam[i]:g}")
    if lam.size > 1 and lam[-1] <= 0:
        raise InvalidArgumentError("all eigenvalues are zero: no geometry to read")
    return lam


def as_times(t) -> np.ndarray:
    """Times as a float array (p,), checked finite and positive (area units)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)) or np.any(t <= 0):
        raise InvalidArgumentError("heat-trace times t must be a non-empty 1-d array of finite positive values")
    return t


def heat_trace(eigenvalues, t) -> np.ndarray:
    """Z(t) = Σ_n e^{−λ_n t} of the given eigenvalues (no tail correction).

    Parameters
    ----------
    eigenvalues : (k,) array_like
        λ₀ = 0 first, ascending, in 1/area.
    t : float or (p,) array_like
        Times, positive, in area units.

    Returns
    -------
    (p,) ndarray
        Z at each t (dimensionless).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import heat_trace
    >>> l = np.repeat(np.arange(20), 2 * np.arange(20) + 1)
    >>> heat_trace(l * (l + 1.0), np.array([0.1, 1.0])).round(4)   # sum_i exp(-lambda_i t), the unit sphere
    array([10.3401,  1.4184])
    """
    lam = as_eigenvalues(eigenvalues, minimum=1)
    t = as_times(t)
    # Chunks over t keep the (p, k) exponent matrix small for long grids and spectra.
    out = np.empty(t.size)
    step = max(1, 2_000_000 // lam.size)
    for s in range(0, t.size, step):
        out[s:s + step] = np.exp(-np.outer(t[s:s + step], lam)).sum(axis=1)
    return out


def spectral_tail(t, lam_max: float, density: float, density_slope: float = 0.0) -> np.ndarray:
    """Estimate of Σ_{n>K} e^{−λ_n t}, the part of Z(t) above the last known eigenvalue λ_K.

    With the counting function continued above λ_K as N(λ) ≈ N(λ_K) + ρ(λ − λ_K) + ½ρ'(λ − λ_K)², the tail is
    ∫_{λ_K}^∞ e^{−λt} dN = e^{−λ_K t}(ρ/t + ρ'/t²).  Weyl's law is ρ = A/(4π), ρ' = 0.

    Parameters
    ----------
    t : float or (p,) array_like
        Times > 0.
    lam_max : float
        The largest eigenvalue known, λ_K > 0.
    density : float
        dN/dλ at λ_K (area units), > 0.
    density_slope : float
        d²N/dλ² at λ_K.

    Returns
    -------
    (p,) ndarray

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import spectral_tail
    >>> tail = spectral_tail(np.array([0.01, 1.0]), lam_max=400.0, density=1.0)   # eigenvalues above 400
    >>> bool(tail[0] > 1.0), bool(tail[1] < 1e-100)      # matter at small t only
    (True, True)
    """
    t = as_times(t)
    lam_max, density, density_slope = float(lam_max), float(density), float(density_slope)
    if not (np.isfinite(lam_max) and lam_max > 0 and np.isfinite(density) and density > 0
            and np.isfinite(density_slope)):
        raise InvalidArgumentError(f"need finite lam_max > 0, density > 0 and density_slope, got {lam_max}, "
                                   f"{density}, {density_slope}")
    return np.exp(-lam_max * t) * (density / t + density_slope / t ** 2)
