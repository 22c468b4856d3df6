"""How far a harmonic spectrum is from the spectrum of the surface meant: the truncations of a forward solve.

1. **ρ's band limit La.**  If ρ is replaced by ρ + δρ with |δρ| <= ε·ρ everywhere, every eigenvalue moves by a factor
   within [1/(1+ε), 1/(1−ε)] (min–max: the Rayleigh quotient ∫|∇u|² / ∫ρu² changes by that factor for every u), so
   |Δλ/λ| <= ε/(1−ε) with ε = sup|δρ| / min ρ.  When shspec cuts the given ρ at La, δρ is the dropped part, bounded
   exactly by Σ_{l>La} ‖a_l‖ √((2l+1)/4π) (addition theorem): :attr:`TruncationEstimate.factor`.
2. **The basis band limit Lb.**  The Galerkin eigenvalues decrease monotonically to the true ones as Lb grows
   (min–max on nested spaces); what they miss is the part of the eigenfunctions above Lb.  An eigenpair (λ, u)
   satisfies l(l+1) u_lm = λ (ρu)_lm in every degree, so from the Galerkin eigenfunction v the content above Lb is,
   to first order, λ r_lm / (l(l+1)) with r = (ρv)_lm, and second-order perturbation theory gives the eigenvalue
   shift Σ (λ r_lm)² / (l(l+1) − λρ̄) (ρ̄ the mean of ρ standing in for the mass matrix's diagonal up there).
   :func:`basis_truncation` computes it for the degrees Lb + 1 and Lb + 2 by an exact quadrature of ρv from the
   eigenvectors already at hand (about 5 ms at (Lb, La, K) = (30, 15, 256), a few per cent of the solve) and adds the
   degrees above as a geometric series, with the decay from the energy of v in the degrees Lb − 1, Lb to the shift
   (at most 0.81 per two degrees): :attr:`TruncationEstimate.basis`.  Measured against solves at Lb + 20 for Möbius
   boosts (k = 2, 3, 5), a random ρ of degree 15, an even one of degree 16 and the blob, at Lb = 12 … 30 and
   K = 16 … 256 (``python -m benchmarks run bench_spectrum``), it was 0.34 to 2.6 times the true error, below half
   of it only where that was above 1e-2: an eigenfunction so far from resolved also lacks part of its content inside
   the basis, which first order does not see.  (The change of the eigenvalues from Lb − 2 to Lb, which cost a
   second solve, was 0.14 to 116 times the true error: it measures the content of the degrees Lb − 1 and Lb, which
   for a band-limited ρ can be far above what lies beyond them.)
3. **Degrees ρ was never given.**  A band-limited ρ is a metric in its own right, and shspec cannot know whether
   the coefficients are the whole of ρ or the truncation of a smooth function (a Möbius boost expanded to degree
   20).  For the second reading the part above the last degree L is extrapolated from the decay of the last six
   degrees, ‖a_l‖ ≈ ‖a_L‖ q^(l−L) (q >= 1: not resolved, infinite), and turned into ε as in 1:
   :attr:`TruncationEstimate.unresolved`.  It is an estimate, not a bound, and it is only reported: it would warn
   about every exactly band-limited ρ.  It names truncation as the likely cause when a given ρ is negative.

:func:`~shspec.galerkin.solver.spectrum` computes all three and emits a :class:`~shspec.errors.TruncationWarning`
when 1 or 2 exceeds its tolerance (a boost k = 5 at Lb = La = 20 with K = 10 is caught by 2: estimated 1.3e-3, its
true error 1.6e-3); the fit's hot path (:meth:`HarmonicModel.spectrum`) pays for none of them, but may call
:func:`factor_truncation` (microseconds).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..core.checks import check_int, finite_array, real_array
from ..errors import InvalidArgumentError
from ..sphere.grid import evaluate_on_grid, glq_grid, legendre_at_nodes
from ..sphere.harmonics import degrees, lmax_of_size, ncoeffs
from .gridforms import _trig

__all__ = ["TruncationEstimate", "tail_bound", "factor_truncation", "basis_truncation", "basis_degree_for",
           "DEFAULT_TRUNCATION_TOL"]

#: Relative eigenvalue error above which :func:`~shspec.galerkin.solver.spectrum` warns.
DEFAULT_TRUNCATION_TOL = 1e-6

_DECAY_DEGREES = 6

#: The degrees above the basis whose first-order content :func:`basis_truncation` computes; the rest is extrapolated.
_OUTER_DEGREES = 2
#: Largest decay per two degrees the extrapolation beyond Lb + 2 assumes: a slower one (an eigenfunction whose
#: content has not started to fall at Lb) counts at most 1/(1 − 0.81) ≈ 5 times the first two degrees.
_MAX_DECAY = 0.81
#: Smallest gap 1 − λρ̄/(l(l+1)) of the second-order shift: near 0 the eigenfunction's own degree reaches the missing
#: ones and perturbation theory no longer applies (measured: with 0.3 the estimate is 0.34–2.6 times the true error).
_MIN_GAP = 0.3
#: Columns per block of :class:`_OuterProjection`.
_BLOCK = 64


@dataclass(frozen=True)
class TruncationEstimate:
    """Estimated relative eigenvalue errors of a forward solve (NaN where not estimated; see the module notes).

    Attributes
    ----------
    factor : float
        Bound ε/(1−ε) from the degrees of the given ρ that were cut (ε = sup|dropped part| / min ρ); 0 if none.
    basis : float
        The largest estimated relative error of an eigenvalue from the degrees the basis leaves out (their
        first-order content, :func:`basis_truncation`); NaN for k = 1.
    unresolved : float
        Estimate as for ``factor`` of the degrees above the given ones, extrapolated from the decay of the last
        coefficients (inf when they do not decay); reported, not warned about.
    """

    factor: float
    basis: float
    unresolved: float = float("nan")

    @property
    def total(self) -> float:
        """The larger of ``factor`` and ``basis``, the two that :func:`~shspec.galerkin.solver.spectrum` warns about."""
        both = [x for x in (self.factor, self.basis) if not np.isnan(x)]
        return float(max(both)) if both else float("nan")


def _degree_norms(coefficients: np.ndarray) -> np.ndarray:
    lmax = lmax_of_size(np.size(coefficients))
    sq = np.asarray(coefficients, dtype=float) ** 2
    return np.sqrt(np.add.reduceat(sq, (np.arange(lmax + 1) ** 2).astype(int)))


def tail_bound(coefficients: np.ndarray, lmax_factor: int, *, extrapolate: bool = True) -> float:
    """sup|ρ − ρ_La| over the sphere, in units of ρ (module notes): exact for the given degrees above La, plus,
    if ``extrapolate``, an estimate of the degrees above the given ones.

    Parameters
    ----------
    coefficients : (N,) float array
        ρ's flat coefficients up to its own degree L (N = (L+1)²).
    lmax_factor : int
        The band limit La that ρ is cut to.
    """
    norms = _degree_norms(coefficients)
    top = norms.size - 1
    l = np.arange(norms.size)
    sup = np.sqrt((2 * l + 1) / (4 * np.pi))
    dropped = float(norms[lmax_factor + 1:] @ sup[lmax_factor + 1:]) if top > lmax_factor else 0.0
    if not extrapolate or top < 1:
        return dropped
    # degrees of one parity only (an even ρ) leave zeros between: pair the neighbours before measuring the decay
    paired = np.maximum(norms[1:], norms[:-1])
    last = paired[-min(_DECAY_DEGREES, paired.size):]
    if last[-1] == 0 or last.size < 3:
        return dropped  # nothing above, or too few degrees to see a decay: take ρ as given
    if last[0] == 0:
        return float("inf")
    q = (last[-1] / last[0]) ** (1.0 / (last.size - 1))
    if q >= 1:
        return float("inf")
    # Σ_{l>L} ‖a_L‖ q^(l−L) √((2l+1)/4π), with √((2L+2j+1)/(2L+3)) <= √(1+j) for j >= 1
    j = np.arange(1, 400)
    unseen = last[-1] * np.sqrt((2 * top + 3) / (4 * np.pi)) * float(np.sum(q ** j * np.sqrt(1.0 + j)))
    return dropped + unseen


def factor_truncation(coefficients: np.ndarray, lmax_factor: int, minimum: float, *,
                      extrapolate: bool = False) -> float:
    """Relative eigenvalue error from cutting ρ at ``lmax_factor``, ε/(1−ε) with ε = :func:`tail_bound` / ``minimum``.

    ``minimum`` is min ρ of the cut factor (:meth:`~shspec.sphere.factor.ConformalFactor.check_positive`); the result
    is inf when ε >= 1 (the tail may be as large as ρ itself).
    """
    tail = tail_bound(coefficients, lmax_factor, extrapolate=extrapolate)
    if tail == 0:
        return 0.0
    eps = tail / minimum if minimum > 0 else float("inf")
    return float(eps / (1.0 - eps)) if eps < 1 else float("inf")
def basis_truncation(eigenvalues, eigenvectors, coefficients) -> tuple[np.ndarray, np.ndarray]:
    """Estimated relative error of each Galerkin eigenvalue from the basis band limit Lb, and its decay.

    The part of each eigenfunction above Lb, to first order, and the eigenvalue shift it causes (module notes, 2).

    Parameters
    ----------
    eigenvalues : (k,) float array
        The Galerkin eigenvalues, >= 0 (λ₀ = 0 first, as :func:`~shspec.galerkin.solver.spectrum` gives them).
    eigenvectors : (N, k) float array
        Their M-orthonormal eigenvectors in the basis of degree Lb, N = (Lb+1)².
    coefficients : (P,) float array
        The flat coefficients of the ρ they were solved for, of degree La <= 2·Lb (P = (La+1)²).

    Returns
    -------
    error : (k,) float array
        Estimated relative error |λ_i(Lb) − λ_i| / λ_i (0 for λ_i = 0: the constant is in every basis).
    decay : (k,) float array
        The factor by which ``error`` is expected to fall for each two degrees added to the basis (<= 0.81).

    Raises
    ------
    InvalidArgumentError
        Shapes that do not fit together, a degree La > 2·Lb, negative or non-finite values.
    """
    lam = real_array(eigenvalues, "eigenvalues")
    if lam.ndim != 1 or lam.size == 0:
        raise InvalidArgumentError(f"eigenvalues must be a non-empty 1-D array, got shape {lam.shape}")
    vecs = real_array(eigenvectors, "eigenvectors")
    if vecs.ndim != 2 or vecs.shape[1] != lam.size:
        raise InvalidArgumentError(f"eigenvectors must have shape (N, {lam.size}), got {vecs.shape}")
    lmax = _degree_of(vecs.shape[0])
    if lmax < 1:
        raise InvalidArgumentError(f"eigenvectors must have (Lb+1)**2 rows with Lb >= 1, got {vecs.shape[0]}")
    a = real_array(coefficients, "coefficients")
    lmax_factor = _degree_of(a.size) if a.ndim == 1 else -1
    if not 0 <= lmax_factor <= 2 * lmax:
        raise InvalidArgumentError(f"coefficients must be the (La+1)**2 flat coefficients of rho with La <= 2*Lb = "
                                   f"{2 * lmax}, got shape {a.shape}")
    lam = finite_array(lam, "eigenvalues", lam.shape)
    vecs = finite_array(vecs, "eigenvectors", vecs.shape)
    a = finite_array(a, "coefficients", a.shape)
    if np.any(lam < 0):
        raise InvalidArgumentError(f"eigenvalues must be >= 0, got {lam.min():.3g}")
    live = lam > 0
    if lmax_factor == 0 or not live.any():  # a constant ρ: the harmonics are its eigenfunctions, nothing is missing
        return np.zeros(lam.size), np.zeros(lam.size)
    projection = _outer_projection(lmax, lmax_factor)
    outer = projection(vecs, evaluate_on_grid(a, projection.grid))
    l_out = degrees(lmax + _OUTER_DEGREES)[ncoeffs(lmax):].astype(float)
    s_out = (l_out * (l_out + 1.0))[:, None]
    # the first-order content of the degrees above Lb, t = λ (ρv)_lm / (l(l+1)), as energy l(l+1) t² per coefficient,
    # and the eigenvalue shift Σ (λ r)² / (l(l+1) − λ ρ̄) of second-order perturbation theory (ρ̄: the mean of ρ
    # standing in for the diagonal of the mass matrix there)
    energy = (lam[None, :] * outer) ** 2 / s_out
    gap = np.maximum(1.0 - lam[None, :] * (a[0] / np.sqrt(4 * np.pi)) / s_out, _MIN_GAP)
    shift = np.sum(energy / gap, axis=0)
    # the energy of the two top degrees inside the basis (of Σ_l = λ: the eigenvectors are M-normalized); its
    # ratio to the shift is the decay per two degrees, and the degrees above Lb + 2 follow it geometrically.  Pairs
    # of degrees, not single ones: for a ρ of one parity the eigenfunctions live on every other degree.
    l_in = degrees(lmax)
    top = l_in >= lmax - 1
    inside = np.sum(vecs[top] ** 2 * (l_in[top] * (l_in[top] + 1.0))[:, None], axis=0)
    ratio = np.divide(shift, inside, out=np.full_like(shift, _MAX_DECAY), where=inside > 0)
    decay = np.where(live, np.minimum(ratio, _MAX_DECAY), 0.0)
    return np.divide(shift, (1.0 - decay) * lam, out=np.zeros_like(shift), where=live), decay


def _degree_of(size: int) -> int:
    """L for (L+1)² entries, −1 for a size that is no square."""
    root = int(np.sqrt(size) + 0.5)
    return root - 1 if root * root == size else -1


@lru_cache(maxsize=8)
def _outer_projection(lmax: int, lmax_factor: int) -> _OuterProjection:
    """The projection of (Lb, La), built once per process (milliseconds, but a repeated solve need not pay them)."""
    return _OuterProjection(lmax, lmax_factor)


class _OuterProjection:
    """r = (ρ f_q) projected onto the degrees Lb+1 … Lb+2 for many f_q of degree <= Lb, by exact GLQ quadrature.

    The steps of :mod:`~shspec.galerkin.gridforms`: per order m the Legendre sums of f_q on the grid, one GEMM for
    the longitudes, the product with ρ, one GEMM back to the orders |m'| <= Lb + 2, and one batch of latitude
    projections onto the two degrees; the grid is held longitude first so that no step transposes.  Degrees of f
    below Lb + 1 − La are skipped: ρ of degree La does not couple them to Lb + 1.  At (Lb, La, k) = (30, 15, 256)
    that is about 0.2 GFlop, a few ms.
    """

    def __init__(self, lmax: int, lmax_factor: int):
        top = lmax + _OUTER_DEGREES
        # the integrand Y_l' ρ f has degree <= Lb + 2 + La + Lb
        self.grid = grid = glq_grid(-(-(2 * lmax + _OUTER_DEGREES + lmax_factor) // 2))
        plm = legendre_at_nodes(grid, top)  # (nlat, nplm)
        low = lmax + 1 - lmax_factor
        blocks = [_order_block(plm, m, max(abs(m), low), lmax) for m in range(-lmax, lmax + 1)]
        # the rows of f that reach Lb + 1, gathered once per call order by order: each order's rows are then one
        # slice, not a scattered gather per block of columns
        self._gather = np.concatenate([idx for idx, _ in blocks])
        ends = np.cumsum([idx.size for idx, _ in blocks])
        self._synthesis = [(slice(end - p.shape[1], end), p) for end, (_, p) in zip(ends, blocks)]
        self._trig_in = np.ascontiguousarray(
            np.stack([_trig(m, grid.lon) for m in range(-lmax, lmax + 1)]).T)  # (nlon, 2Lb+1)
        # the quadrature weights: 2π/nlon per longitude, the Gauss weight per latitude
        self._trig_out = np.stack([_trig(m, grid.lon) for m in range(-top, top + 1)]) * (2 * np.pi / grid.lon.size)
        # per order m' the rows of the degrees Lb+1 … Lb+2; a degree below |m'| has none, its row goes to a spare
        # last row of the result with zero weights
        outer = np.arange(lmax + 1, top + 1)
        first, self.nout = ncoeffs(lmax), ncoeffs(top) - ncoeffs(lmax)
        orders = np.arange(-top, top + 1)[:, None]
        exists = outer[None, :] >= np.abs(orders)
        self._rows = np.where(exists, outer * outer + outer + orders - first, self.nout)  # (2top+1, 2)
        columns = np.where(exists, outer * (outer + 1) // 2 + np.abs(orders), 0)
        self._weights = np.where(exists[:, :, None], plm.T[columns] * grid.w, 0.0)  # (2top+1, 2, nlat)

    def __call__(self, vecs: np.ndarray, rho_values: np.ndarray) -> np.ndarray:
        """r (nout, q) for the columns of ``vecs`` (nbasis, q) and ρ's values on the grid (nlat, nlon)."""
        nlat, nlon = rho_values.shape
        rho_values = rho_values.T[:, :, None]
        result = np.empty((self.nout + 1, vecs.shape[1]))
        # in blocks of columns, through the same work arrays: those of a block stay in cache, and neither they nor
        # the memory grow with k (at (30, 15, 256) twice as fast as all columns at once, measured)
        width = min(_BLOCK, vecs.shape[1])
        norders = len(self._synthesis), self._trig_out.shape[0]
        work = np.empty((norders[0] + nlon + norders[1]) * nlat * width)
        for start in range(0, vecs.shape[1], width):
            block = vecs[self._gather, start:start + width]  # a copy: each order's rows one contiguous slice
            nq = block.shape[1]
            n = nlat * nq
            # contiguous views of the work array, also for a last, narrower block
            legendre = work[:norders[0] * n].reshape(norders[0], nlat, nq)
            values = work[norders[0] * n:(norders[0] + nlon) * n].reshape(nlon, nlat, nq)
            orders = work[(norders[0] + nlon) * n:(norders[0] + nlon + norders[1]) * n].reshape(norders[1], nlat, nq)
            for out, (rows, p) in zip(legendre, self._synthesis):
                np.matmul(p, block[rows], out=out)
            np.matmul(self._trig_in, legendre.reshape(norders[0], n), out=values.reshape(nlon, n))
            values *= rho_values
            np.matmul(self._trig_out, values.reshape(nlon, n), out=orders.reshape(norders[1], n))
            result[self._rows.ravel(), start:start + nq] = np.matmul(self._weights, orders).reshape(-1, nq)
        return result[:self.nout]


def _order_block(plm: np.ndarray, m: int, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices (nl,) of the (l, m), l = lo … hi, and their Legendre values (nlat, nl)."""
    ls = np.arange(lo, hi + 1)
    return ls * ls + ls + m, np.ascontiguousarray(plm[:, ls * (ls + 1) // 2 + abs(m)])


def basis_degree_for(numeig: int, lmax_factor: int) -> int:
    """The smallest basis degree Lb ≥ La with (Lb + 1)² ≥ 1.5·K: the floor below which K eigenvalues of ρ of degree
    La are not resolved (:func:`~shspec.fitting.numeig_plan.converged_basis_degree` scans upwards from it)."""
    numeig = check_int(numeig, "numeig", minimum=2)
    lmax_factor = check_int(lmax_factor, "lmax_factor", minimum=0)
    return max(int(np.ceil(np.sqrt(1.5 * numeig))) - 1, lmax_factor)

