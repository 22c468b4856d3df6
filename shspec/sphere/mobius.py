"""Möbius maps of the sphere and the Möbius centering of a conformal factor ρ.

The maps used are the hyperbolic translations of the unit ball, restricted to the sphere,

    φ_c(x) = (1 − |c|²)(x − c) / |x − c|² − c,     |c| < 1,

which send the point c of the ball to the origin; |dφ_c(x)| = (1 − |c|²)/|x − c|² is its conformal scale on the
sphere, and φ_{−c} = φ_c⁻¹.  For a measure μ of mass 1 on the sphere, the centre of mass of φ_c#μ is
C(c) = ∫ φ_c dμ, and ∂C/∂c at c = 0 is ∫ (−2I + 2xxᵀ) dμ (negative definite unless μ sits on two antipodal points).
Newton's method on C(c) = 0, composing one translation per step, converges quadratically (Baden, Crane, Kazhdan,
"Möbius Registration", SGP 2018).  Centering a ρ makes a_1m vanish, the gauge of the harmonic inverse problem
(:doc:`/theory`); the same Newton steps centre a mesh in :mod:`shspec.mesh.mobius`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConvergenceError, InvalidArgumentError, NotPositiveError
from .evaluate import sample_harmonic
from .grid import expand_grid, glq_grid
from .harmonics import as_coefficients, check_degree, lmax_of_size

__all__ = ["mobius_translate", "mobius_scale", "newton_step", "center_harmonic", "HarmonicCentering"]


def mobius_translate(points, c) -> np.ndarray:
    """φ_c(x) for points x (n, 3) on the unit sphere and c (3,) with |c| < 1; returns (n, 3) unit vectors."""
    x = np.asarray(points, dtype=float)
    c = _boost(c)
    d = x - c
    return (1.0 - c @ c) * d / np.einsum("ij,ij->i", d, d)[:, None] - c


def mobius_scale(points, c) -> np.ndarray:
    """Conformal scale |dφ_c(x)| = (1 − |c|²)/|x − c|², (n,), at points x (n, 3) of the unit sphere."""
    x = np.asarray(points, dtype=float)
    c = _boost(c)
    d = x - c
    return (1.0 - c @ c) / np.einsum("ij,ij->i", d, d)


def _boost(c) -> np.ndarray:
    c = np.asarray(c, dtype=float)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise InvalidArgumentError(f"a Möbius translation c must be a finite 3-vector, got {c!r}")
    if c @ c >= 1.0:
        raise InvalidArgumentError(f"a Möbius translation needs |c| < 1, got |c| = {np.sqrt(c @ c):.6g}")
    return c


def newton_step(points, weights):
    """Newton step c for the centre of mass of the point masses weights (n,) at points (n, 3), plus the centre."""
    w = weights / weights.sum()
    center = w @ points
    J = -2.0 * np.eye(3) + 2.0 * (points.T * w) @ points
    step = -np.linalg.solve(J, center)
    # Stay well inside the ball: a damped step when far from the solution keeps |c| < 1.
    norm = np.linalg.norm(step)
    if norm > 0.5:
        step *= 0.5 / norm
    return step, center


@dataclass(frozen=True)
class HarmonicCentering:
    """Result of :func:`center_harmonic`.

    Attributes
    ----------
    coefficients : ((lmax+1)**2,) array
        Flat coefficients of the centred ρ, with a_1m ≈ 0.
    translations : (j, 3) array
        The Newton steps c_1..c_j: ρ' = (ρ∘ψ)|dψ|² with ψ = φ_{−c_1} ∘ ... ∘ φ_{−c_j}.
    residual : float
        max |a_1m| / a_00 of the returned coefficients.
    truncation : float
        Relative L2 norm of the centred ρ above degree lmax (on the quadrature grid): the band-limit error.
    iterations : int
        Newton steps taken.
    """

    coefficients: np.ndarray
    translations: np.ndarray
    residual: float
    truncation: float
    iterations: int


def center_harmonic(coeffs, lmax: int | None = None, *, grid_lmax: int | None = None, tol: float = 1e-12,
                    max_iter: int = 50) -> HarmonicCentering:
    """Möbius-centre a conformal factor ρ given by real harmonic coefficients: make a_1m vanish.

    The centred factor is ρ' = (ρ∘ψ)|dψ|² with ψ a Möbius map of the sphere; its area measure ρ' dΩ is the
    push-forward of ρ dΩ by ψ⁻¹, so that ∫ x ρ' dΩ = 0, i.e. a'_1m = 0.  ψ is a composition of translations
    φ_{−c} found by Newton steps on the centre of mass (module notes); ρ' is evaluated exactly at the nodes of a
    Gauss–Legendre grid (the original ρ at the moved points, :func:`~shspec.sphere.evaluate.sample_harmonic`) and
    expanded back (:func:`~shspec.sphere.grid.expand_grid`).

    Parameters
    ----------
    coeffs : flat vector, cilm array or SHCoeffs
        ρ, positive on the sphere, band limit La.
    lmax : int, optional
        Band limit of the result; default La.  ρ' is not band-limited: the part above lmax is dropped and reported.
    grid_lmax : int, optional
        Degree of the quadrature grid; default max(4·lmax, 32).  Raise it for strong boosts.
    tol : float, default 1e-12
        Stop when max |a'_1m| / a'_00 ≤ tol (computed on the grid, before truncation).
    max_iter : int, default 50

    Returns
    -------
    HarmonicCentering

    Raises
    ------
    NotPositiveError
        If ρ is ≤ 0 at a grid node.
    ConvergenceError
        If the tolerance is not met after ``max_iter`` steps.
    """
    a = as_coefficients(coeffs)
    la = lmax_of_size(a.size)
    lmax = la if lmax is None else check_degree(lmax, "lmax")
    grid_lmax = max(4 * lmax, 32) if grid_lmax is None else check_degree(grid_lmax, "grid_lmax")
    if grid_lmax < lmax:
        raise InvalidArgumentError(f"grid_lmax = {grid_lmax} must be >= lmax = {lmax}")
    grid = glq_grid(grid_lmax)
    x, quad = grid.unit_vectors().reshape(-1, 3), grid.weights.ravel()
    rho0 = sample_harmonic(a, x).reshape(grid.shape)
    if np.any(rho0 <= 0):
        raise NotPositiveError(f"ρ is not positive on the sphere (min {rho0.min():.3g} on a degree-{grid_lmax} grid)")
    # ψ = φ_{−c_1} ∘ ... ∘ φ_{−c_j}, kept as the list of c's and evaluated afresh at the grid nodes each step, so
    # that ρ is only ever evaluated exactly (at moved points), never re-expanded.
    steps: list[np.ndarray] = []
    for it in range(max_iter + 1):
        y, scale = x, np.ones(x.shape[0])
        for c in reversed(steps):
            scale = scale * mobius_scale(y, -c)
            y = mobius_translate(y, -c)
            y /= np.linalg.norm(y, axis=1)[:, None]
        rho = sample_harmonic(a, y) * scale ** 2
        step, center = newton_step(x, quad * rho)
        if np.max(np.abs(center)) <= tol:
            break
        # Push the measure forward by φ_step: ρ''(x) = ρ'(φ_{−step}(x)) |dφ_{−step}(x)|², i.e. ψ ← ψ ∘ φ_{−step}.
        steps.append(step)
    else:
        raise ConvergenceError(f"harmonic Möbius centering: |centre| = {np.linalg.norm(center):.3g} > {tol:g} "
                               f"after {max_iter} Newton steps")
    vec_full = expand_grid(rho.reshape(grid.shape), grid, grid_lmax)
    out = vec_full[: (lmax + 1) ** 2].copy()
    truncation = float(np.linalg.norm(vec_full[out.size:]) / np.linalg.norm(vec_full))
    residual = float(np.max(np.abs(out[1:4])) / out[0])
    return HarmonicCentering(out, np.array(steps).reshape(-1, 3), residual, truncation, it)
