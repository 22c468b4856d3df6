"""Möbius centering: the representative of a spherical map (or of a conformal factor ρ) whose area measure has its
centre of mass at the origin (Baden, Crane, Kazhdan, "Möbius Registration", SGP 2018).

The maps used are the hyperbolic translations of the unit ball, restricted to the sphere,

    φ_c(x) = (1 − |c|²)(x − c) / |x − c|² − c,     |c| < 1,

which send the point c of the ball to the origin; |dφ_c(x)| = (1 − |c|²)/|x − c|² is its conformal scale on the
sphere, and φ_{−c} = φ_c⁻¹.  For a measure μ of mass 1 on the sphere, the centre of mass of φ_c#μ is
C(c) = ∫ φ_c dμ, and ∂C/∂c at c = 0 is ∫ (−2I + 2xxᵀ) dμ (negative definite unless μ sits on two antipodal points).
Newton's method on C(c) = 0, composing one translation per step, converges quadratically.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyshtools

from ..errors import ConvergenceError, InvalidArgumentError, MeshError, NotPositiveError
from ..harmonics import as_coefficients, check_degree, cilm_to_vector, lmax_of_size, vector_to_cilm
from .triangle_mesh import TriangleMesh

__all__ = ["mobius_translate", "mobius_scale", "center_mesh", "center_harmonic", "MeshCentering",
           "HarmonicCentering"]


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


def _newton(points, weights):
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
    """
    if not isinstance(sphere, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(sphere).__name__}")
    x = sphere.vertices
    off = np.max(np.abs(np.linalg.norm(x, axis=1) - 1.0))
    if off > 1e-8:
        raise MeshError(f"the vertices are not on the unit sphere: |x| − 1 reaches {off:.3g}")
    w = np.asarray(weights, dtype=float)
    if w.shape != (sphere.nvertices,) or not np.all(np.isfinite(w)):
        raise InvalidArgumentError(f"weights must be a finite array of shape ({sphere.nvertices},)")
    if np.any(w <= 0):
        raise NotPositiveError(f"weights must be > 0; vertex {int(np.flatnonzero(w <= 0)[0])} has "
                               f"{w[w <= 0][0]:.3g}")
    if not 0 < tol < 1:
        raise InvalidArgumentError(f"tol must be in (0, 1), got {tol}")
    for it in range(max_iter + 1):
        step, center = _newton(x, w)
        if np.linalg.norm(center) <= tol:
            return MeshCentering(sphere.with_vertices(x), center, it)
        x = mobius_translate(x, step)
        # Renormalize: each step is exact on the sphere up to rounding, which would otherwise accumulate.
        x /= np.linalg.norm(x, axis=1)[:, None]
    raise ConvergenceError(f"Möbius centering: |centre| = {np.linalg.norm(center):.3g} > {tol:g} after "
                           f"{max_iter} Newton steps")


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
    Gauss–Legendre grid (the original ρ at the moved points, with pyshtools) and expanded back with
    ``pyshtools.expand.SHExpandGLQ``.

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
    cilm = vector_to_cilm(a)
    zero, w = pyshtools.expand.SHGLQ(grid_lmax)
    lat, lon = pyshtools.expand.GLQGridCoord(grid_lmax)
    lat_g, lon_g = np.meshgrid(np.radians(lat), np.radians(lon), indexing="ij")
    x = np.stack([np.cos(lat_g) * np.cos(lon_g), np.cos(lat_g) * np.sin(lon_g), np.sin(lat_g)], -1).reshape(-1, 3)
    quad = (w[:, None] * np.full(lon.size, 2 * np.pi / lon.size)[None, :]).ravel()
    rho0 = _evaluate(cilm, x).reshape(lat.size, lon.size)
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
        rho = _evaluate(cilm, y) * scale ** 2
        step, center = _newton(x, quad * rho)
        if np.max(np.abs(center)) <= tol:
            break
        # Push the measure forward by φ_step: ρ''(x) = ρ'(φ_{−step}(x)) |dφ_{−step}(x)|², i.e. ψ ← ψ ∘ φ_{−step}.
        steps.append(step)
    else:
        raise ConvergenceError(f"harmonic Möbius centering: |centre| = {np.linalg.norm(center):.3g} > {tol:g} "
                               f"after {max_iter} Newton steps")
    grid = rho.reshape(lat.size, lon.size)
    full = pyshtools.expand.SHExpandGLQ(grid, w, zero, norm=4, csphase=1, lmax_calc=grid_lmax)
    vec_full = cilm_to_vector(full)
    out = vec_full[: (lmax + 1) ** 2].copy()
    truncation = float(np.linalg.norm(vec_full[out.size:]) / np.linalg.norm(vec_full))
    residual = float(np.max(np.abs(out[1:4])) / out[0])
    return HarmonicCentering(out, np.array(steps).reshape(-1, 3), residual, truncation, it)


def _evaluate(cilm, points) -> np.ndarray:
    """ρ at points (n, 3) on the unit sphere, by pyshtools."""
    lat = np.degrees(np.arcsin(np.clip(points[:, 2], -1.0, 1.0)))
    lon = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
    return pyshtools.SHCoeffs.from_array(cilm, normalization="ortho", csphase=1).expand(lat=lat, lon=lon)
