"""Gauss–Legendre grids of pyshtools: evaluate coefficient vectors on them and expand grid values back.

A GLQ grid of degree L has L+1 latitudes (the zeros of P_{L+1}) and 2L+1 equally spaced longitudes; it integrates
products up to total degree 2L+1 in latitude exactly, so projecting a function onto degree <= Lc is exact when the
function itself has degree <= 2L+1 − Lc.

The transforms are pyshtools' orthonormal Legendre functions (``PlmON``, tabulated once per grid) and products with
the longitudes' cosines and sines, not pyshtools' ``MakeGridGLQ``/``SHExpandGLQ``: those plan their FFTs with
FFTW_MEASURE, which times candidate algorithms and keeps the fastest, so their rounding depended on the machine's
load (measured: the same expansion at L = 47 came out in other bits in 2 of 10 processes started next to a busy
core), and through the log-ρ model's mass, a fit's path did too.  Products of fixed shapes add in a fixed order on
the one BLAS thread shspec computes with (:mod:`shspec.core.threads`); they agree with pyshtools' transforms to rounding
(tests) and cost a millisecond at the grids of a fit.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pyshtools

from ..errors import InvalidArgumentError
from ..core.threads import PYSHTOOLS_LOCK
from .harmonics import check_degree, lmax_of_size, vector_to_cilm, cilm_to_vector

__all__ = ["GLQGrid", "glq_grid", "legendre_at_nodes", "evaluate_on_grid", "expand_grid"]


@dataclass(frozen=True)
class GLQGrid:
    """A pyshtools Gauss–Legendre grid.

    Attributes
    ----------
    lmax : int
        Degree L of the grid.
    colat, lon : (L+1,), (2L+1,) float arrays
        Colatitudes θ in [0, π] and longitudes φ in [0, 2π), radians.
    weights : (L+1, 2L+1) float array
        Quadrature weights on the unit sphere (they sum to 4π).
    zero, w : (L+1,) float arrays
        pyshtools' nodes (cos θ) and latitude weights, as returned by ``SHGLQ``.
    """

    lmax: int
    colat: np.ndarray
    lon: np.ndarray
    weights: np.ndarray
    zero: np.ndarray
    w: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return self.colat.size, self.lon.size

    def unit_vectors(self) -> np.ndarray:
        """(L+1, 2L+1, 3) array of the grid points on the unit sphere."""
        st = np.sin(self.colat)[:, None]
        return np.stack([st * np.cos(self.lon)[None, :], st * np.sin(self.lon)[None, :],
                         np.broadcast_to(np.cos(self.colat)[:, None], self.shape)], axis=-1)


@lru_cache(maxsize=16)
def glq_grid(lmax: int) -> GLQGrid:
    """The GLQ grid of degree ``lmax`` (cached)."""
    lmax = check_degree(lmax, "grid degree")
    with PYSHTOOLS_LOCK:
        zero, w = pyshtools.expand.SHGLQ(lmax)
        lat, lon = pyshtools.expand.GLQGridCoord(lmax)
    colat = np.radians(90.0 - lat)
    lonr = np.radians(lon)
    weights = np.outer(w, np.full(lon.size, 2.0 * np.pi / lon.size))
    for arr in (colat, lonr, weights, zero, w):
        arr.setflags(write=False)
    return GLQGrid(lmax, colat, lonr, weights, zero, w)


def legendre_at_nodes(grid: GLQGrid, lmax: int) -> np.ndarray:
    """Orthonormal Legendre functions P_lm (``PlmON``, csphase 1) at the latitudes of ``grid``, as an
    (L+1, (lmax+1)(lmax+2)/2) array in pyshtools' packed order l(l+1)/2 + m."""
    lmax = check_degree(lmax, "lmax")
    with PYSHTOOLS_LOCK:
        return np.stack([pyshtools.legendre.PlmON(lmax, z, csphase=1) for z in grid.zero])


@lru_cache(maxsize=32)
def _legendre(grid_lmax: int, lmax: int) -> np.ndarray:
    """:func:`legendre_at_nodes` of the grid of degree ``grid_lmax`` as an (lmax+1, L+1, lmax+1) array indexed
    [m, node, l], zero for l < m (cached, read-only)."""
    grid = glq_grid(grid_lmax)
    packed = legendre_at_nodes(grid, lmax)
    l, m = np.tril_indices(lmax + 1)
    table = np.zeros((lmax + 1, grid.zero.size, lmax + 1))
    table[m, :, l] = packed[:, l * (l + 1) // 2 + m].T
    table.setflags(write=False)
    return table


@lru_cache(maxsize=32)
def _cos_sin(grid_lmax: int, lmax: int) -> tuple[np.ndarray, np.ndarray]:
    """cos mφ_j and sin mφ_j, m = 0 … lmax, at the grid's longitudes: two (lmax+1, 2L+1) arrays (cached)."""
    mphi = np.outer(np.arange(lmax + 1), glq_grid(grid_lmax).lon)
    cos, sin = np.cos(mphi), np.sin(mphi)
    cos.setflags(write=False)
    sin.setflags(write=False)
    return cos, sin


def evaluate_on_grid(coef: np.ndarray, grid: GLQGrid) -> np.ndarray:
    """Values (L+1, 2L+1) of the function with flat coefficients ``coef`` on ``grid`` (its degrees above the
    grid's are left out)."""
    lc = min(lmax_of_size(np.size(coef)), grid.lmax)
    cilm = vector_to_cilm(coef)[:, : lc + 1, : lc + 1]
    legendre = _legendre(grid.lmax, lc)
    cos, sin = _cos_sin(grid.lmax, lc)
    # per order m, the sums over l at every node: (m, nodes)
    a = np.matmul(legendre, cilm[0].T[:, :, None])[:, :, 0]
    b = np.matmul(legendre, cilm[1].T[:, :, None])[:, :, 0]
    return a.T @ cos + b.T @ sin


def expand_grid(values: np.ndarray, grid: GLQGrid, lmax: int) -> np.ndarray:
    """Flat coefficients up to degree ``lmax`` (<= grid degree) of grid values (L+1, 2L+1), by quadrature."""
    lmax = check_degree(lmax, "lmax", maximum=grid.lmax)
    values = np.asarray(values, dtype=float)
    if values.shape != grid.shape:
        raise InvalidArgumentError(f"grid values must have the grid's shape {grid.shape}, got {values.shape}")
    legendre = _legendre(grid.lmax, lmax)
    cos, sin = _cos_sin(grid.lmax, lmax)
    # the longitude sums with their weight 2π/nlon, then the Gauss weight of each node: (nodes, m)
    weight = grid.w[:, None] * (2.0 * np.pi / grid.lon.size)
    gc, gs = (values @ cos.T) * weight, (values @ sin.T) * weight
    cilm = np.empty((2, lmax + 1, lmax + 1))
    cilm[0] = np.matmul(legendre.transpose(0, 2, 1), gc.T[:, :, None])[:, :, 0].T
    cilm[1] = np.matmul(legendre.transpose(0, 2, 1), gs.T[:, :, None])[:, :, 0].T
    return cilm_to_vector(cilm, lmax)
