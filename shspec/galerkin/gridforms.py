"""The quadratic forms v_qᵀ G_k v_q of many vectors at once, by Gauss–Legendre quadrature and GEMMs.

Q_kq = Σ_ij G_ijk v_iq v_jq = ∫ Y_k f_q² dΩ with f_q = Σ_i v_iq Y_i: evaluate every f_q on a grid, square, and
project onto the Y_k.  The integrand Y_k f_q² has degree ≤ La + 2·Lb, so a pyshtools GLQ grid of degree
⌈(2·Lb + La)/2⌉ (⌈·⌉ + 1 latitudes, 2⌈·⌉ + 1 longitudes) integrates it exactly: the result equals the Gaunt-table
contraction to rounding.  The harmonics separate, Y_lm(θ, φ) = P̄_l|m|(cos θ) t_m(φ) (t_m = cos mφ for m ≥ 0,
sin |m|φ for m < 0), so each of the four steps is a small batch of matrix products:

1. per order m, the Legendre sums  A_m(θ, q) = Σ_l P̄_l|m|(θ) v_(l,m),q          (nlat × nl_m) @ (nl_m × q);
2. the longitudes                    f(θ, q, φ) = Σ_m A_m(θ, q) t_m(φ)          one (nlat·q × 2Lb+1) @ (2Lb+1 × nlon);
3. after squaring, the longitude projection onto t_m', |m'| ≤ La                  one (nlat·q × nlon) @ (nlon × 2La+1);
4. per order m', the latitude projection with the Gauss weights                  (nl_m' × nlat) @ (nlat × q).

At (Lb, La, q) = (30, 15, 256) that is about 0.2 GFlop, where the table kernel walks every Gaunt coefficient once per
vector (both measured: :doc:`/benchmarks`; :meth:`HarmonicModel.jacobian` picks by size).
"""

from __future__ import annotations

import numpy as np

from ..core.checks import check_int
from ..errors import InvalidArgumentError
from ..sphere.grid import glq_grid, legendre_at_nodes
from ..sphere.harmonics import check_degree, ncoeffs

__all__ = ["GridQuadraticForms"]


class GridQuadraticForms:
    """Q[k, q] = v_qᵀ G_k v_q for basis degree Lb and factor degree La, computed on a GLQ grid.

    Parameters
    ----------
    lmax : int
        Basis band limit Lb (vectors have (Lb+1)² rows).
    lmax_factor : int
        Factor band limit La (Q has (La+1)² rows), at most 2·Lb.
    grid_degree : int, optional
        Degree of the GLQ grid; default ⌈(2·Lb + La)/2⌉, the smallest that integrates Y_k f_q² exactly.  A
        finer grid serves a weight that is not band-limited (``weight`` of :meth:`__call__`).
    """

    def __init__(self, lmax: int, lmax_factor: int, grid_degree: int | None = None):
        self.lmax = check_degree(lmax, "lmax", minimum=1)
        self.lmax_factor = check_degree(lmax_factor, "lmax_factor", maximum=2 * self.lmax)
        exact = -(-(2 * self.lmax + self.lmax_factor) // 2)
        grid = glq_grid(exact if grid_degree is None else check_degree(grid_degree, "grid_degree", minimum=exact))
        self.grid = grid
        lp = max(self.lmax, self.lmax_factor)
        plm = legendre_at_nodes(grid, lp)  # (nlat, nplm)
        lon = grid.lon
        self._basis = [self._order_block(plm, self.lmax, m) for m in range(-self.lmax, self.lmax + 1)]
        self._trig_basis = np.stack([_trig(m, lon) for m in range(-self.lmax, self.lmax + 1)])  # (2Lb+1, nlon)
        # the quadrature weights: 2π/nlon per longitude, the Gauss weight per latitude
        self._trig_factor = np.ascontiguousarray(
            np.stack([_trig(m, lon) for m in range(-self.lmax_factor, self.lmax_factor + 1)]).T * (2 * np.pi / lon.size))
        self._factor = [(idx, np.ascontiguousarray((p * grid.w[:, None]).T))
                        for idx, p in (self._order_block(plm, self.lmax_factor, m)
                                       for m in range(-self.lmax_factor, self.lmax_factor + 1))]
        self.nbasis = ncoeffs(self.lmax)
        self.nfactor = ncoeffs(self.lmax_factor)

    @staticmethod
    def _order_block(plm: np.ndarray, lmax: int, m: int) -> tuple[np.ndarray, np.ndarray]:
        """Flat indices (nl,) of the (l, m), l = |m| … lmax, and their Legendre values (nlat, nl)."""
        ls = np.arange(abs(m), lmax + 1)
        return ls * ls + ls + m, np.ascontiguousarray(plm[:, ls * (ls + 1) // 2 + abs(m)])

    def __call__(self, vecs: np.ndarray, weight: np.ndarray | None = None) -> np.ndarray:
        """Q (nfactor, nq) for the columns of ``vecs`` (nbasis, nq); with ``weight`` (grid values, (nlat, nlon)),
        the quadrature of w·Y_k·f_q² instead."""
        values = self._squares(vecs, weight)  # (nlat, nq, nlon)
        nlat, nq, nlon = values.shape
        proj = (values.reshape(nlat * nq, nlon) @ self._trig_factor).reshape(nlat, nq, -1)  # (nlat, nq, 2La+1)
        proj = np.ascontiguousarray(proj.transpose(2, 0, 1))
        result = np.empty((self.nfactor, nq))
        for block, (idx, pw) in zip(proj, self._factor):
            result[idx] = pw @ block
        return result

    def weighted(self, vecs: np.ndarray, coef: np.ndarray, weight: np.ndarray | None = None) -> np.ndarray:
        """Σ_q coef_q v_qᵀ G_k v_q (nfactor,): Q @ coef without forming Q (one function Σ_q coef_q f_q² to
        project); ``weight`` as in :meth:`__call__`."""
        values = self._squares(vecs, weight)
        coef = np.asarray(coef, dtype=float)
        if coef.shape != (values.shape[1],):
            raise InvalidArgumentError(f"coef must have shape ({values.shape[1]},), got {coef.shape}")
        field = np.einsum("tqp,q->tp", values, coef)  # (nlat, nlon)
        proj = field @ self._trig_factor  # (nlat, 2La+1)
        result = np.empty(self.nfactor)
        for col, (idx, pw) in zip(proj.T, self._factor):
            result[idx] = pw @ col
        return result

    def _squares(self, vecs: np.ndarray, weight: np.ndarray | None = None) -> np.ndarray:
        """f_q² (times ``weight``, (nlat, nlon), if given) on the grid, (nlat, nq, nlon), for the columns of
        ``vecs`` (nbasis, nq)."""
        vecs = np.asarray(vecs, dtype=float)
        if vecs.ndim != 2 or vecs.shape[0] != self.nbasis:
            raise InvalidArgumentError(f"vectors must have shape ({self.nbasis}, q), got {vecs.shape}")
        nq = check_int(vecs.shape[1], "the number of vectors", minimum=1)
        nlat = self.grid.zero.size
        legendre = np.empty((len(self._basis), nlat, nq))
        for out, (idx, p) in zip(legendre, self._basis):
            np.matmul(p, vecs[idx], out=out)
        values = legendre.reshape(len(self._basis), nlat * nq).T @ self._trig_basis  # (nlat·nq, nlon)
        np.square(values, out=values)
        values = values.reshape(nlat, nq, -1)
        if weight is not None:
            weight = np.asarray(weight, dtype=float)
            if weight.shape != (nlat, values.shape[2]):
                raise InvalidArgumentError(f"weight must be grid values of shape {(nlat, values.shape[2])}, got "
                                           f"{weight.shape}")
            values *= weight[:, None, :]
        return values


def _trig(m: int, lon: np.ndarray) -> np.ndarray:
    return np.cos(m * lon) if m >= 0 else np.sin(-m * lon)
