"""The conformal factor ρ of a metric g = ρ g₀ on the sphere, as real spherical-harmonic coefficients.

ρ = Σ_k a_k Y_k up to degree La (the factor band limit), in shspec's convention (pyshtools ``ortho``, ``csphase=1``,
flat index ``k = l*l + l + m``).  The area of the surface is ∫ ρ dΩ = a_00 √(4π); lengths scale as √ρ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyshtools
import scipy.optimize

from ..errors import InvalidArgumentError, NotPositiveError
from ..core.plotstyle import linear_colorbar_ticks, style_hammer
from ..core.threads import PYSHTOOLS_LOCK
from .grid import evaluate_on_grid, expand_grid, glq_grid
from .harmonics import (as_coefficients, check_degree, lmax_of_size, vector_to_cilm, vector_to_shcoeffs)

__all__ = ["ConformalFactor", "MAX_COEFFICIENT", "Minimum", "as_factor", "derivative_bounds", "grid_lower_bound"]

_SQRT_4PI = np.sqrt(4.0 * np.pi)

#: Largest magnitude of a coefficient of ρ: squares, norms and products with eigenvalues (~1/ρ) then stay far from
#: the overflow and underflow of double precision (an area of 1e100 is beyond any use of the library).
MAX_COEFFICIENT = 1e100


@dataclass(frozen=True)
class Minimum:
    """Where a factor is smallest: value and position (colatitude θ and longitude φ in degrees).

    ``lower_bound`` is a certified bound min ρ >= lower_bound over the whole sphere (see
    :meth:`ConformalFactor.check_positive`), NaN where none was computed.
    """

    value: float
    colat_deg: float
    lon_deg: float
    lower_bound: float = float("nan")

    def __str__(self) -> str:
        return f"{self.value:.6g} at colatitude {self.colat_deg:.2f} deg, longitude {self.lon_deg:.2f} deg"


def derivative_bounds(coefficients: np.ndarray) -> tuple[float, float]:
    """Bounds G >= |∇ρ| and H >= ‖∇²ρ‖ (operator norm) over the unit sphere, from the coefficients of ρ.

    Write S_l = (2l+1)/4π and ‖a_l‖ = (Σ_m a_lm²)^½.  By the addition theorem Σ_m Y_lm(x)² = S_l at every x, and its
    derivatives (or Bochner's formula with Ric = g on the unit sphere) give, also at every x,

        Σ_m |∇Y_lm|² = l(l+1) S_l,      Σ_m ‖∇²Y_lm‖²_F = (l(l+1) − 1) l(l+1) S_l.

    The linear map a_l ↦ ∇ρ_l(x) ∈ R² commutes with the rotations about x, which act irreducibly on the tangent
    plane, so its Gram matrix is a multiple of the identity and its norm is exactly (l(l+1) S_l / 2)^½.  The Hessian
    splits into its trace part ½Δρ_l·g = −½ l(l+1) ρ_l g, of norm <= ½ l(l+1) S_l^½ ‖a_l‖, and a traceless part on
    which the rotations act irreducibly too (by twice the angle), of Frobenius norm <= (Σ_m‖T_m‖²_F / 2)^½ ‖a_l‖ with
    Σ_m‖T_m‖²_F = l(l+1)(l(l+1)/2 − 1) S_l, and operator norm 2^-½ times that.  Summing over degrees:

        G = Σ_l ‖a_l‖ (l(l+1) S_l / 2)^½,
        H = Σ_l ‖a_l‖ [½ l(l+1) S_l^½ + ½ (l(l+1)(l(l+1)/2 − 1) S_l)^½].

    G is attained in every degree; H splits the Hessian's two parts, each bounded sharply, so it is within a
    factor 2 of the best bound; both are attained for l = 1 (G = H = (3/4π)^½ ‖a_1‖).

    Returns
    -------
    G, H : float
        In units of ρ per radian and per radian².
    """
    lmax = lmax_of_size(np.size(coefficients))
    l = np.arange(lmax + 1, dtype=float)
    sq = np.asarray(coefficients, dtype=float) ** 2
    norms = np.sqrt(np.add.reduceat(sq, (np.arange(lmax + 1) ** 2).astype(int)))
    s = (2 * l + 1) / (4 * np.pi)
    ll = l * (l + 1)
    grad = np.sqrt(ll * s / 2)
    hess = 0.5 * ll * np.sqrt(s) + 0.5 * np.sqrt(ll * np.maximum(ll / 2 - 1, 0) * s)
    return float(norms @ grad), float(norms @ hess)


def grid_lower_bound(values: np.ndarray, grid, gmax: float, hmax: float) -> tuple[float, np.ndarray]:
    """A certified lower bound of ρ on the whole sphere from its values on a GLQ grid and the bounds G, H.

    Between two neighbouring nodes of one latitude ring (an arc of length s = sin θ Δφ of a circle of geodesic
    curvature |cot θ|), the second derivative of ρ along the arc is >= −(H + G|cot θ|), so ρ >= min(both ends) −
    (H + G|cot θ|) s²/8 on it.  A meridian between two rings is a geodesic, where ρ'' >= −H: every point of the cell
    between rings i and i+1 is on such a meridian, so ρ >= min(bound on ring i, bound on ring i+1) − H Δθ²/8.  A polar
    cap above the first ring is covered by the meridian great circles through the pole, geodesics of length 2θ₀
    between two points of the ring: ρ >= (ring bound) − H θ₀²/2.

    Parameters
    ----------
    values : (L+1, 2L+1) float array
        ρ on the grid.
    grid : GLQGrid
    gmax, hmax : float
        Bounds of |∇ρ| and ‖∇²ρ‖ (:func:`derivative_bounds`).

    Returns
    -------
    bound : float
        min ρ >= bound everywhere.
    cells : (L+2, 2L+1) float array
        The bound of each cell: row 0 the north cap (repeated), rows 1..L the cells between rings, row L+1 the south
        cap; column j the cells right of longitude node j.
    """
    theta = grid.colat
    dphi = 2 * np.pi / grid.lon.size
    arc = (hmax + gmax * np.abs(np.cos(theta) / np.sin(theta))) * (np.sin(theta) * dphi) ** 2 / 8
    ring = np.minimum(values, np.roll(values, -1, axis=1)) - arc[:, None]
    dtheta = np.diff(theta)
    between = np.minimum(ring[:-1], ring[1:]) - (hmax * dtheta ** 2 / 8)[:, None]
    north = np.full((1, ring.shape[1]), ring[0].min() - hmax * theta[0] ** 2 / 2)
    south = np.full((1, ring.shape[1]), ring[-1].min() - hmax * (np.pi - theta[-1]) ** 2 / 2)
    cells = np.vstack([north, between, south])
    return float(cells.min()), cells


class ConformalFactor:
    """A conformal factor ρ > 0 on the unit sphere given by its harmonic coefficients.

    Parameters
    ----------
    coefficients : (N,) float array, a pyshtools cilm array (2, L+1, L+1), or ``pyshtools.SHCoeffs``
        Coefficients a_k of ρ; N = (La+1)**2.  SHCoeffs in another normalization are converted; a cilm array needs
        ``normalization`` (:func:`~shspec.sphere.harmonics.as_coefficients`).
    lmax : int, optional
        Truncate or zero-pad to this band limit La.
    name : str
        A label used in plots and result files.
    normalization : {"ortho", "4pi", "schmidt", "unnorm"}, optional
        Of a cilm array (required there: pyshtools' default is '4pi', shspec's 'ortho'); ``csphase`` likewise.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import ConformalFactor
    >>> rho = ConformalFactor.mobius_boost(2.0, lmax=20)   # isometric to the unit sphere
    >>> rho.lmax, round(rho.area / (4 * np.pi), 10)
    (20, 1.0)
    >>> round(rho.check_positive().value, 3)      # its minimum: positive, a metric
    0.25
    """

    def __init__(self, coefficients, lmax: int | None = None, *, name: str = "rho", normalization: str | None = None,
                 csphase: int = 1):
        coef = as_coefficients(coefficients, lmax, normalization=normalization, csphase=csphase)
        big = float(np.max(np.abs(coef), initial=0.0))
        if big > MAX_COEFFICIENT:
            raise InvalidArgumentError(
                f"a coefficient of rho of magnitude {big:.3g} exceeds {MAX_COEFFICIENT:g}: its squares and the mass "
                "matrix would overflow double precision; rescale rho (the spectrum of c*rho is that of rho "
                "divided by c)")
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
        if area > MAX_COEFFICIENT * _SQRT_4PI:
            raise InvalidArgumentError(f"the area {area:g} exceeds {MAX_COEFFICIENT * _SQRT_4PI:.3g}, beyond what "
                                       "double precision computes a spectrum for; rescale it")
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
        with PYSHTOOLS_LOCK:
            rot = self.to_shcoeffs().rotate(alpha, beta, gamma, degrees=True, body=True)
        return ConformalFactor(rot, self.lmax, name=f"rotated {self.name}")

    def evaluate(self, grid_lmax: int | None = None) -> tuple[np.ndarray, "object"]:
        """Values of ρ on a GLQ grid; returns (values (L+1, 2L+1), grid)."""
        grid = glq_grid(grid_lmax if grid_lmax is not None else max(2 * self.lmax, 64))
        return evaluate_on_grid(self.coefficients, grid), grid

    def minimum(self, grid_lmax: int | None = None) -> Minimum:
        """Smallest value of ρ found: the lowest node of a GLQ grid of degree max(2·La, 64) (or ``grid_lmax``),
        polished by a local minimizer; ``lower_bound`` is the certified bound of that grid (see
        :meth:`check_positive`)."""
        values, grid = self.evaluate(grid_lmax)
        gmax, hmax = derivative_bounds(self.coefficients)
        bound, _ = grid_lower_bound(values, grid, gmax, hmax)
        i, j = np.unravel_index(int(np.argmin(values)), values.shape)
        value, colat, lon = self._local_minimum(grid.colat[i], grid.lon[j], values[i, j])
        return Minimum(value, colat, lon, bound)

    def check_positive(self, grid_lmax: int | None = None, *, max_grid_lmax: int = 1024) -> Minimum:
        """Raise :class:`NotPositiveError` unless ρ > 0 everywhere on the sphere, as certified by a bound.

        ρ is evaluated on a GLQ grid (degree max(2·La, 64), or ``grid_lmax``) and bounded below between the nodes by
        :func:`grid_lower_bound`, which needs only the node values and the bounds G >= |∇ρ|, H >= ‖∇²ρ‖ of
        :func:`derivative_bounds`; the bound is of second order in the node spacing.  When it is not positive the grid
        degree is raised (at least doubled, up to ``max_grid_lmax``) until the bound is positive or a node is not; a
        grid of degree 128 or 256 costs a fraction of a millisecond at La <= 15, a local minimization tens of
        milliseconds (basin-hop moves of a fit bring ρ near 0 often).  Only a ρ still inconclusive on the finest grid is
        searched between its nodes, by local minimizations from the lowest nodes of the weakest cells, and a node <= 0
        is polished by one, so that the error says where ρ is smallest.  The cost is one grid evaluation (0.25 ms at La
        = 15 and 30) for a ρ clearly away from 0; a ρ with a deep narrow minimum (the boost k = 5: min/mean = 1/600)
        needs grids up to degree 512 (about 0.1 s).

        Returns
        -------
        Minimum
            The smallest node value of the grid that certified ρ, and where, with its ``lower_bound`` (> 0).

        Raises
        ------
        NotPositiveError
            ρ <= 0 somewhere (the message says where and by how much), or ρ is so close to 0 that positivity cannot
            be certified at ``max_grid_lmax``.
        """
        values, grid = self.evaluate(grid_lmax)
        gmax, hmax = derivative_bounds(self.coefficients)
        while True:
            bound, cells = grid_lower_bound(values, grid, gmax, hmax)
            i, j = np.unravel_index(int(np.argmin(values)), values.shape)
            low = Minimum(float(values[i, j]), float(np.degrees(grid.colat[i])), float(np.degrees(grid.lon[j])),
                          bound)
            if bound > 0 and low.value > 0:
                return low
            if low.value > 0 and grid.lmax >= max_grid_lmax:
                low = self._search_inconclusive(values, grid, cells, bound)
            elif not low.value > 0:
                low = Minimum(*self._local_minimum(grid.colat[i], grid.lon[j], low.value), bound)
            if not low.value > 0:
                raise NotPositiveError(
                    f"{self.name} is not a metric: it is not positive everywhere; its minimum is {low} "
                    f"(mean value {self.area / (4 * np.pi):.6g}), so the mass matrix is not positive definite")
            if grid.lmax >= max_grid_lmax:
                raise NotPositiveError(
                    f"{self.name} cannot be certified positive: its smallest value found is {low}, but the lower "
                    f"bound on a grid of degree {grid.lmax} is {bound:.3g} (mean value "
                    f"{self.area / (4 * np.pi):.6g}); rho is too close to 0 to be a usable metric")
            # the bound's deficit shrinks like the squared node spacing: go straight to the degree that should
            # halve it below the smallest value (at least doubling)
            degree = int(np.ceil(grid.lmax * np.sqrt(2.0 * (low.value - bound) / low.value)))
            values, grid = self.evaluate(min(max(2 * grid.lmax, degree), max_grid_lmax))

    def _search_inconclusive(self, values, grid, cells, bound, starts: int = 8) -> Minimum:
        """The lowest local minimum reached from the lowest nodes of the (up to ``starts``) weakest cells."""
        best = Minimum(float("inf"), 0.0, 0.0, bound)
        nrow, ncol = values.shape
        flat_cells = cells.ravel()
        weakest = np.argpartition(flat_cells, min(starts, flat_cells.size - 1))[:starts]  # not a sort of 2M cells
        for flat in weakest[np.argsort(flat_cells[weakest], kind="stable")]:
            r, c = np.unravel_index(int(flat), cells.shape)
            if cells[r, c] > 0:
                break
            rows = [0] if r == 0 else [nrow - 1] if r == nrow else [r - 1, r]
            cols = slice(None) if r in (0, nrow) else [c, (c + 1) % ncol]
            block = values[rows][:, cols]
            bi, bj = np.unravel_index(int(np.argmin(block)), block.shape)
            i = rows[bi]
            j = bj if r in (0, nrow) else [c, (c + 1) % ncol][bj]
            value, colat, lon = self._local_minimum(grid.colat[i], grid.lon[j], values[i, j])
            if value < best.value:
                best = Minimum(value, colat, lon, bound)
            if value <= 0:
                break
        return best

    def _local_minimum(self, colat: float, lon: float, start_value: float) -> tuple[float, float, float]:
        """Nelder–Mead from (colat, lon) (radians) in tangent-plane coordinates (no pole singularity); returns
        (value, colatitude°, longitude°) of the best point seen."""
        cilm = self.to_cilm()
        p = np.array([np.sin(colat) * np.cos(lon), np.sin(colat) * np.sin(lon), np.cos(colat)])
        e1 = np.cross(p, [0.0, 0.0, 1.0] if abs(p[2]) < 0.9 else [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(p, e1)

        def point(uv):
            x = p + uv[0] * e1 + uv[1] * e2
            x /= np.linalg.norm(x)
            return np.degrees(np.arcsin(np.clip(x[2], -1, 1))), np.degrees(np.arctan2(x[1], x[0])) % 360.0

        def rho(uv):
            lat, lo = point(uv)
            with PYSHTOOLS_LOCK:
                return float(pyshtools.expand.MakeGridPoint(cilm, lat, lo, norm=4, csphase=1))

        res = scipy.optimize.minimize(rho, np.zeros(2), method="Nelder-Mead",
                                      options={"xatol": 1e-9, "fatol": 1e-14, "initial_simplex":
                                               np.array([[0, 0], [0.02, 0], [0, 0.02]])})
        if not res.fun < start_value:
            return float(start_value), float(np.degrees(colat)), float(np.degrees(lon))
        lat, lo = point(res.x)
        return float(res.fun), float(90.0 - lat), float(lo)

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
        style_hammer(ax)
        linear_colorbar_ticks(ax.figure.colorbar(mesh, ax=ax, orientation="horizontal", pad=0.1, shrink=0.6,
                                                 label="rho"))
        ax.set_title(title if title is not None else self.name, pad=10)
        return ax

    def __repr__(self) -> str:
        return f"ConformalFactor(name={self.name!r}, lmax={self.lmax}, area={self.area:.6g})"


def as_factor(rho, lmax: int | None = None) -> ConformalFactor:
    """A :class:`ConformalFactor` from a factor, a flat vector, a cilm array or an SHCoeffs object."""
    if isinstance(rho, ConformalFactor):
        return rho if lmax is None or lmax == rho.lmax else rho.truncated(lmax)
    return ConformalFactor(rho, lmax)
