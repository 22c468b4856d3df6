"""How far a harmonic spectrum is from the spectrum of the surface meant: the truncations of a forward solve.

1. **ρ's band limit La.**  If ρ is replaced by ρ + δρ with |δρ| <= ε·ρ everywhere, every eigenvalue moves by a factor
   within [1/(1+ε), 1/(1−ε)] (min–max: the Rayleigh quotient ∫|∇u|² / ∫ρu² changes by that factor for every u), so
   |Δλ/λ| <= ε/(1−ε) with ε = sup|δρ| / min ρ.  When shspec cuts the given ρ at La, δρ is the dropped part, bounded
   exactly by Σ_{l>La} ‖a_l‖ √((2l+1)/4π) (addition theorem): :attr:`TruncationEstimate.factor`.
2. **The basis band limit Lb.**  The Galerkin eigenvalues decrease monotonically to the true ones as Lb grows
   (min–max on nested spaces), so the change from Lb − 2 to Lb is a computable measure of the error left; for the
   geometric convergence of smooth ρ it overestimates the error at Lb by the convergence factor of two degrees.
   It costs one more solve at Lb − 2 (about 0.6 times the first at Lb = 20): :attr:`TruncationEstimate.basis`.
3. **Degrees ρ was never given.**  A band-limited ρ is a metric in its own right, and shspec cannot know whether
   the coefficients are the whole of ρ or the truncation of a smooth function (a Möbius boost expanded to degree
   20).  For the second reading the part above the last degree L is extrapolated from the decay of the last six
   degrees, ‖a_l‖ ≈ ‖a_L‖ q^(l−L) (q >= 1: not resolved, infinite), and turned into ε as in 1:
   :attr:`TruncationEstimate.unresolved`.  It is an estimate, not a bound, and it is only reported: it would warn
   about every exactly band-limited ρ.  It names truncation as the likely cause when a given ρ is negative.

:func:`~shspec.galerkin.solver.spectrum` computes all three and emits a :class:`~shspec.errors.TruncationWarning`
when 1 or 2 exceeds its tolerance (a boost k = 5 at Lb = La = 20 is caught by 2: the change from Lb = 18 is
2.7e-3, its true error 1.6e-3); the fit's hot path (:meth:`HarmonicModel.spectrum`) pays for none of them, but may
call :func:`factor_truncation` (microseconds).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..checks import check_int
from ..sphere.harmonics import lmax_of_size

__all__ = ["TruncationEstimate", "tail_bound", "factor_truncation", "basis_degree_for", "DEFAULT_TRUNCATION_TOL"]

#: Relative eigenvalue error above which :func:`~shspec.galerkin.solver.spectrum` warns.
DEFAULT_TRUNCATION_TOL = 1e-6

_DECAY_DEGREES = 6


@dataclass(frozen=True)
class TruncationEstimate:
    """Estimated relative eigenvalue errors of a forward solve (NaN where not estimated; see the module notes).

    Attributes
    ----------
    factor : float
        Bound ε/(1−ε) from the degrees of the given ρ that were cut (ε = sup|dropped part| / min ρ); 0 if none.
    basis : float
        max_i |λ_i(Lb−2) − λ_i(Lb)| / λ_i(Lb) over the eigenvalues both bases hold.
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
def basis_degree_for(numeig: int, lmax_factor: int) -> int:
    """The smallest basis degree Lb ≥ La with (Lb + 1)² ≥ 1.5·K: the floor below which K eigenvalues of ρ of degree
    La are not resolved (:func:`~shspec.inverse.planning.converged_basis_degree` scans upwards from it)."""
    numeig = check_int(numeig, "numeig", minimum=2)
    lmax_factor = check_int(lmax_factor, "lmax_factor", minimum=0)
    return max(int(np.ceil(np.sqrt(1.5 * numeig))) - 1, lmax_factor)

