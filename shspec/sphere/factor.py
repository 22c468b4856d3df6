"""The conformal factor ρ of a metric g = ρ g₀ on the sphere, as real spherical-harmonic coefficients.

ρ = Σ_k a_k Y_k up to degree La (the factor band limit), in shspec's convention (pyshtools ``ortho``, ``csphase=1``,
flat index ``k = l*l + l + m``).  The area of the surface is ∫ ρ dΩ = a_00 √(4π); lengths scale as √ρ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyshtools

from ..errors import InvalidArgumentError, NotPositiveError
from .grid import evaluate_on_grid, expand_grid, glq_grid
from .harmonics import (as_coefficients, check_degree, lmax_of_size, vector_to_cilm, vector_to_shcoeffs)

__all__ = ["ConformalFactor", "Minimum", "as_factor"]

_SQRT_4PI = np.sqrt(4.0 * np.pi)


@dataclass(frozen=True)
class Minimum:
    """Where a factor is smallest on a grid: value and position (colatitude θ and longitude φ in degrees)."""

    value: float
    colat_deg: float
    lon_deg: float

    def __str__(self) -> str:
        return f"{self.value:.6g} at colatitude {self.colat_deg:.2f} deg, longitude {self.lon_deg:.2f} deg"


class ConformalFactor:
    """A conformal factor ρ > 0 on the unit sphere given by its harmonic coefficients.

    Parameters
    ----------
    coefficients : (N,) float array, a pyshtools cilm array (2, L+1, L+1), or ``pyshtools.SHCoeffs``
        Coefficients a_k of ρ; N = (La+1)**2.  SHCoeffs in another normalization are converted.
    lmax : int, optional
        Truncate or zero-pad to this band limit La.
    name : str
        A label used in plots and result files.
    """

    def __init__(self, coefficients, lmax: int | None = None, *, name: str = "rho"):
        coef = as_coefficients(coefficients, lmax)
        self.coefficients = coef
        self.coefficients.setflags(write=False)
        self.name = str(name)

    # -- construction ---------------------------------------------------------------------------------------------

    @classmethod
    def sphere(cls, area: float = 4.0 * np.pi, lmax: int = 0) -> "ConformalFactor":
        """The round sphere of the given area (ρ constant = area / 4π)."""
        area = float(area)
        if not np.isfinite(area) or area <= 0:
            raise InvalidArgumentError(f"the area must be positive and finite, got {area}")
        coef = np.zeros((check_degree(lmax, "lmax") + 1) ** 2)
        coef[0] = area / _SQRT_4PI
        return cls(coef, name=f"sphere(area={area:g})")

    @classmethod
    def from_function(cls, func, lmax: int, *, grid_lmax: int | None = None, name: str = "rho",
                      ) -> "ConformalFactor":
        """Project ρ(θ, φ) onto degree <= ``lmax`` by Gauss–Legendre quadrature.

        Parameters
        ----------
        func : callable
            ``func(theta, phi)`` with colatitude θ (L+1, 1) and longitude φ (1, 2L+1) in radians, broadcasting to
            the grid's shape.
        lmax : int
            Band limit La of the result.
        grid_lmax : int, optional
            Degree of the quadrature grid; default max(2·La, La + 32), which makes the aliasing error of smooth ρ
            negligible.
        """
        lmax = check_degree(lmax, "lmax")
        grid = glq_grid(grid_lmax if grid_lmax is not None else max(2 * lmax, lmax + 32))
        values = np.broadcast_to(np.asarray(func(grid.colat[:, None], grid.lon[None, :]), dtype=float), grid.shape)
        return cls.from_grid(values, lmax, grid_lmax=grid.lmax, name=name)

    @classmethod
    def from_grid(cls, values, lmax: int, *, grid_lmax: int | None = None, name: str = "rho") -> "ConformalFactor":
        """Expand values on a pyshtools GLQ grid (L+1, 2L+1) of degree L >= ``lmax`` into degree <= ``lmax``."""
        values = np.asarray(values, dtype=float)
        if values.ndim != 2 or values.shape[1] != 2 * values.shape[0] - 1:
            raise InvalidArgumentError(f"GLQ grid values have shape (L+1, 2L+1), got {values.shape}")
        if not np.all(np.isfinite(values)):
            raise InvalidArgumentError("grid values contain NaN or inf")
        grid = glq_grid(values.shape[0] - 1 if grid_lmax is None else grid_lmax)
        if grid.shape != values.shape:
            raise InvalidArgumentError(f"values of shape {values.shape} are not on a GLQ grid of degree {grid.lmax}")
        if lmax > grid.lmax:
            raise InvalidArgumentError(f"a grid of degree {grid.lmax} cannot resolve lmax = {lmax}")
        return cls(expand_grid(values, grid, lmax), name=name)

    @classmethod
    def mobius_boost(cls, k: float, lmax: int, axis=(0.0, 0.0, 1.0), *, area_scale: float = 1.0,
                     ) -> "ConformalFactor":
        """The Möbius boost tan(θ'/2) = k tan(θ/2) about ``axis``, band-limited to ``lmax``.

        ρ_k = k² / (cos²(γ/2) + k² sin²(γ/2))² with γ the angle from the axis: the pull-back of the round metric, so
        the surface is isometric to the unit sphere and its spectrum is exactly l(l+1) (2l+1 times each) for every
        k > 0 — up to the truncation error of the expansion, which decays like ((k−1)/(k+1))^La.
        """
        k = float(k)
        if not np.isfinite(k) or k <= 0:
            raise InvalidArgumentError(f"the boost parameter k must be positive, got {k}")
        n = np.asarray(axis, dtype=float)
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
            raise InvalidArgumentError(f"axis must be a non-zero 3-vector, got {axis!r}")
        n = n / np.linalg.norm(n)

        def rho(theta, phi):
            t = (np.sin(theta) * np.cos(phi) * n[0] + np.sin(theta) * np.sin(phi) * n[1] + np.cos(theta) * n[2])
            return area_scale * k * k / ((1.0 + t) / 2.0 + k * k * (1.0 - t) / 2.0) ** 2

        return cls.from_function(rho, lmax, name=f"boost(k={k:g}, axis={np.round(n, 4).tolist()})")

    # -- properties -----------------------------------------------------------------------------------------------

    @property
    def lmax(self) -> int:
        """Band limit La."""
        return lmax_of_size(self.coefficients.size)

    @property
    def area(self) -> float:
        """Area ∫ ρ dΩ of the surface."""
        return float(self.coefficients[0] * _SQRT_4PI)

    def to_cilm(self) -> np.ndarray:
        """pyshtools cilm array (2, La+1, La+1)."""
        return vector_to_cilm(self.coefficients)

    def to_shcoeffs(self) -> pyshtools.SHCoeffs:
        """``pyshtools.SHCoeffs`` (ortho, csphase=1), for pyshtools' plotting, rotation and analysis."""
        return vector_to_shcoeffs(self.coefficients)

    def truncated(self, lmax: int) -> "ConformalFactor":
        """The factor cut (or zero-padded) to degree ``lmax``."""
        lmax = check_degree(lmax, "lmax")
        coef = np.zeros((lmax + 1) ** 2)
        n = min(coef.size, self.coefficients.size)
        coef[:n] = self.coefficients[:n]
        return ConformalFactor(coef, name=self.name)

    def scaled(self, c: float) -> "ConformalFactor":
        """c·ρ (the surface scaled by √c in length)."""
        return ConformalFactor(self.coefficients * float(c), name=f"{c:g}*{self.name}")

    def rotated(self, alpha: float, beta: float, gamma: float) -> "ConformalFactor":
        """ρ∘R⁻¹ for the rotation with Euler angles (z-y-z, degrees) of pyshtools ``SHCoeffs.rotate(body=True)``."""
        rot = self.to_shcoeffs().rotate(alpha, beta, gamma, degrees=True, body=True)
        return ConformalFactor(rot, self.lmax, name=f"rotated {self.name}")

    def evaluate(self, grid_lmax: int | None = None) -> tuple[np.ndarray, "object"]:
        """Values of ρ on a GLQ grid; returns (values (L+1, 2L+1), grid)."""
        grid = glq_grid(grid_lmax if grid_lmax is not None else max(2 * self.lmax, 64))
        return evaluate_on_grid(self.coefficients, grid), grid

    def minimum(self, grid_lmax: int | None = None) -> Minimum:
        """Smallest value of ρ on a GLQ grid of degree max(2·La, 64) (or ``grid_lmax``), and where it is."""
        values, grid = self.evaluate(grid_lmax)
        i, j = np.unravel_index(int(np.argmin(values)), values.shape)
        return Minimum(float(values[i, j]), float(np.degrees(grid.colat[i])), float(np.degrees(grid.lon[j])))

    def check_positive(self, grid_lmax: int | None = None) -> Minimum:
        """Raise :class:`NotPositiveError` (saying where and by how much) unless ρ > 0 on the grid."""
        low = self.minimum(grid_lmax)
        if not low.value > 0:
            raise NotPositiveError(
                f"{self.name} is not a metric: it is not positive everywhere; its minimum on a grid is {low} "
                f"(mean value {self.area / (4 * np.pi):.6g}), so the mass matrix is not positive definite")
        return low

    def plot(self, ax=None, *, grid_lmax: int | None = None, cmap: str = "viridis", title: str | None = None,
             vmin: float | None = None, vmax: float | None = None):
        """Hammer projection of ρ (longitude −180…180°, latitude −90…90°); returns the matplotlib Axes.

        ``vmin``, ``vmax`` fix the colour range (so that several maps can share one); default: ρ's own range.
        """
        import matplotlib.pyplot as plt

        values, grid = self.evaluate(grid_lmax)
        lon = np.where(grid.lon > np.pi, grid.lon - 2 * np.pi, grid.lon)
        order = np.argsort(lon)
        lat = np.pi / 2 - grid.colat
        if ax is None:
            fig = plt.figure(figsize=(8, 4.5))
            ax = fig.add_subplot(111, projection="hammer")
        mesh = ax.pcolormesh(lon[order], lat, values[:, order], shading="nearest", cmap=cmap, vmin=vmin, vmax=vmax)
        ax.figure.colorbar(mesh, ax=ax, orientation="horizontal", pad=0.05, shrink=0.6, label="rho")
        ax.grid(True, alpha=0.3)
        ax.set_title(title if title is not None else self.name)
        return ax

    def __repr__(self) -> str:
        return f"ConformalFactor(name={self.name!r}, lmax={self.lmax}, area={self.area:.6g})"


def as_factor(rho, lmax: int | None = None) -> ConformalFactor:
    """A :class:`ConformalFactor` from a factor, a flat vector, a cilm array or an SHCoeffs object."""
    if isinstance(rho, ConformalFactor):
        return rho if lmax is None or lmax == rho.lmax else rho.truncated(lmax)
    return ConformalFactor(rho, lmax)
