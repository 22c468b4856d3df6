"""Gauss–Legendre grids of pyshtools: evaluate coefficient vectors on them and expand grid values back.

A GLQ grid of degree L has L+1 latitudes (the zeros of P_{L+1}) and 2L+1 equally spaced longitudes; it integrates
products up to total degree 2L+1 in latitude exactly, so projecting a function onto degree <= Lc is exact when the
function itself has degree <= 2L+1 − Lc.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pyshtools

from ..threads import PYSHTOOLS_LOCK
from .harmonics import check_degree, lmax_of_size, vector_to_cilm, cilm_to_vector

__all__ = ["GLQGrid", "glq_grid", "evaluate_on_grid", "expand_grid"]


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


def evaluate_on_grid(coef: np.ndarray, grid: GLQGrid) -> np.ndarray:
    """Values (L+1, 2L+1) of the function with flat coefficients ``coef`` on ``grid``."""
    lc = lmax_of_size(np.size(coef))
    cilm = vector_to_cilm(coef)
    if lc < grid.lmax:
        padded = np.zeros((2, grid.lmax + 1, grid.lmax + 1))
        padded[:, : lc + 1, : lc + 1] = cilm
        cilm = padded
    with PYSHTOOLS_LOCK:
        return pyshtools.expand.MakeGridGLQ(cilm, grid.zero, lmax=grid.lmax, norm=4, csphase=1,
                                            lmax_calc=min(lc, grid.lmax))


def expand_grid(values: np.ndarray, grid: GLQGrid, lmax: int) -> np.ndarray:
    """Flat coefficients up to degree ``lmax`` (<= grid degree) of grid values (L+1, 2L+1), by quadrature."""
    lmax = check_degree(lmax, "lmax", maximum=grid.lmax)
    with PYSHTOOLS_LOCK:
        cilm = pyshtools.expand.SHExpandGLQ(np.asarray(values, dtype=float), grid.w, grid.zero, norm=4, csphase=1,
                                            lmax_calc=lmax)
    return cilm_to_vector(cilm, lmax)
