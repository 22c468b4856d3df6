"""The Galerkin forward solver: the Laplace–Beltrami spectrum of g = ρ g₀ in the spherical-harmonic basis.

In the basis {Y_i : l_i <= Lb} the stiffness is S = diag(l_i(l_i+1)) for every ρ (the Dirichlet energy is conformally
invariant in 2D) and the mass is M(a) = Σ_k a_k G_k.  We want the first k eigenpairs of S v = λ M v.

How it is solved.  The constant Y_00 spans the kernel of S (λ₀ = 0, v₀ = e₀/√M₀₀).  Every other eigenvector is
M-orthogonal to it, which eliminates its first coordinate, v₀ = −m·v_r/M₀₀ with m = M[0, 1:]; what is left is
S_r v_r = λ K v_r with the Schur complement K = M_rr − m mᵀ/M₀₀ (SPD).  Scaling by D = S_r^{1/2} (diagonal, positive)
turns it into the *standard* symmetric problem H u = μ u, H = D⁻¹ K D⁻¹, μ = 1/λ, of which we want the largest k−1
eigenvalues.  This skips the Cholesky factorization and the two-sided reduction of a generalized solver; LAPACK's MRRR
subset driver or its full divide and conquer, whichever is faster for the share wanted, solves it
(:mod:`shspec.galerkin.eigen`), or a certified Rayleigh–Ritz step from the eigenvectors of a nearby ρ (a warm start).
Then v_r = √λ D⁻¹ u is M-normalized.  The derivatives' quadratic forms v_iᵀ G_k v_i come from an exact quadrature
(:mod:`shspec.galerkin.gridforms`).

What the two band limits leave out, :func:`spectrum` estimates from these eigenvectors without a second solve: ρ's
dropped degrees bound the first part, and the eigenfunctions' first-order content above Lb, one quadrature of ρ·v
(:mod:`shspec.galerkin.truncation`), the second.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..core.checks import check_float, real_array
from ..errors import InvalidArgumentError, NotPositiveError, ShspecError, TruncationWarning, warn
from ..gaunt.table import MAX_BASIS_DEGREE, GauntTable
from ..sphere.factor import ConformalFactor, as_factor
from ..sphere.harmonics import check_degree
from ..core.threads import reproducible_call
from .model import HarmonicModel, SpectrumResult
from .truncation import DEFAULT_TRUNCATION_TOL, TruncationEstimate, basis_truncation, factor_truncation, tail_bound

__all__ = ["spectrum", "MAX_BASIS_DEGREE"]

@reproducible_call
def spectrum(rho, lmax: int, k: int, *, lmax_factor: int | None = None, table: GauntTable | None = None,
             cache_dir=None, build: bool = True, truncation_tol: float | None = DEFAULT_TRUNCATION_TOL,
             ) -> SpectrumResult:
    """The first k Laplace–Beltrami eigenpairs of g = ρ g₀ in the harmonic basis of degree <= ``lmax``.

    Parameters
    ----------
    rho : ConformalFactor, (N,) flat coefficients, cilm array (2, L+1, L+1) or ``pyshtools.SHCoeffs``
        The conformal factor.
    lmax : int
        Basis band limit Lb; the basis has (Lb+1)**2 functions, so k <= (Lb+1)**2.
    k : int
        Number of eigenpairs, λ₀ = 0 included.
    lmax_factor : int, optional
        Truncate ρ to this degree La (default: its own band limit, at most 2·Lb).
    table : GauntTable, optional
        Gaunt table to use (default: from the cache, built if missing and ``build``).
    truncation_tol : float or None
        Estimate the truncation error of ρ's band limit and of the basis (from the eigenvectors at hand, a few per
        cent of the solve; see :mod:`shspec.galerkin.truncation`) and emit a :class:`~shspec.errors.TruncationWarning`
        when the larger exceeds this relative error (default 1e-6).  None: no estimate.

    Returns
    -------
    SpectrumResult
        ``eigenvalues`` (k,) ascending, M-orthonormal ``eigenvectors`` (N, k) and the ``truncation`` estimate.

    Raises
    ------
    NotPositiveError
        ρ cut to La is not positive; the message says when the cut is the cause (ρ itself positive, or its
        coefficients not decayed at their last degree).

    Examples
    --------
    >>> from shspec import ConformalFactor, spectrum
    >>> rho = ConformalFactor.mobius_boost(2.0, lmax=20)   # isometric to the unit sphere: l(l + 1) exactly
    >>> spectrum(rho, lmax=20, k=9).eigenvalues.round(8)
    array([0., 2., 2., 2., 6., 6., 6., 6., 6.])
    """
    factor = _as_input_factor(rho)
    la = factor.lmax if lmax_factor is None else check_degree(lmax_factor, "lmax_factor")
    lmax = check_degree(lmax, "lmax", minimum=1, maximum=MAX_BASIS_DEGREE)
    if truncation_tol is not None:
        truncation_tol = check_float(truncation_tol, "truncation_tol (None or finite and > 0)", positive=True)
    # degrees above 2·Lb do not couple two basis functions: dropping them changes nothing
    # the positivity of the cut factor is checked below (with the cause in the message): the model need not again
    model = HarmonicModel(lmax, min(la, 2 * lmax), table=table, cache_dir=cache_dir, build=build,
                          check_positive=False)
    cut = factor.truncated(model.lmax_factor)
    try:
        low = cut.check_positive()
    except NotPositiveError as exc:
        raise NotPositiveError(f"{exc}{_truncation_cause(factor, model.lmax_factor)}") from None
    result = model.spectrum(cut, k, guards=False)  # a single solve: nothing warm-starts from it
    if truncation_tol is None:
        return result
    errors, decays = basis_truncation(result.eigenvalues, result.eigenvectors, cut.coefficients)
    estimate = TruncationEstimate(factor_truncation(factor.coefficients, model.lmax_factor, low.value),
                                  float(errors[1:].max()) if errors.size > 1 else float("nan"),
                                  factor_truncation(factor.coefficients, model.lmax_factor, low.value,
                                                    extrapolate=True))
    if estimate.total > truncation_tol:
        warn(f"the spectrum of {factor.name} at Lb = {lmax}, La = {model.lmax_factor} may be off by "
             f"{_percent(estimate.total)} (relative): "
             + _truncation_advice(estimate, factor, lmax, model.lmax_factor, (errors, decays, truncation_tol)),
             TruncationWarning)
    return dataclasses.replace(result, truncation=estimate)


def _as_input_factor(rho) -> ConformalFactor:
    if isinstance(rho, (str, bytes, list, tuple, np.ndarray)):
        real_array(rho, "rho")  # named as the argument it is, not as the coefficients inside a factor
    try:
        return as_factor(rho)
    except ShspecError:
        raise
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"rho must be a ConformalFactor, flat coefficients, a cilm array or SHCoeffs "
                                   f"of numbers; got {type(rho).__name__}: {exc}") from None


def _truncation_advice(estimate: TruncationEstimate, factor: ConformalFactor, lmax: int, la: int,
                       basis: tuple[np.ndarray, np.ndarray, float]) -> str:
    """Which band limit to raise, and to what, in words: the larger of the two estimated errors decides.

    ``basis``: the per-eigenvalue errors and decays of :func:`basis_truncation`, and the tolerance exceeded.
    """
    if not estimate.basis >= estimate.factor:  # NaN basis (k = 1: no nonzero eigenvalue) counts as the smaller
        wanted = min(factor.lmax, 2 * lmax)
        more = (f"raise lmax_factor from {la} to {wanted}, rho's own degree" if wanted > la else
                f"rho has degree {factor.lmax} but a basis of degree Lb couples degrees up to 2*Lb only: raise lmax "
                f"to at least {-(-factor.lmax // 2)}")
        return (f"cutting rho at degree {la} drops a part that moves the eigenvalues by up to "
                f"{_percent(estimate.factor)}; {more}")
    wanted_basis = _wanted_basis(lmax, *basis)
    beyond = (f" (more than the largest basis, {MAX_BASIS_DEGREE}: ask for fewer eigenvalues or a smoother rho)"
              if wanted_basis > MAX_BASIS_DEGREE else "")
    return (f"the basis of degree {lmax} leaves out a part of the eigenfunctions that moves the eigenvalues by about "
            f"{_percent(estimate.basis)} (estimated from what rho couples into the degrees {lmax + 1} and {lmax + 2}): "
            f"raise lmax from {lmax} to about {wanted_basis}{beyond}")


def _wanted_basis(lmax: int, errors: np.ndarray, decays: np.ndarray, tol: float) -> int:
    """The basis degree at which every estimate of :func:`basis_truncation` above ``tol`` (one at least) would be
    below it, each falling by its own decay per two degrees (a guide: the decay at Lb is not the asymptotic one)."""
    over = errors > tol
    steps = np.log(tol / errors[over]) / np.log(decays[over])
    return lmax + 2 * int(np.ceil(steps.max()))


def _percent(x: float) -> str:
    if np.isnan(x):
        return "(not estimated)"
    if not np.isfinite(x) or x >= 1:
        return ">= 100 %"
    return f"{100 * x:.2g} %" if x >= 1e-4 else f"{x:.1e}"


def _truncation_cause(factor: ConformalFactor, la: int) -> str:
    """A sentence naming truncation as the cause of a negative cut factor, or '' when it is not."""
    if factor.lmax > la:
        try:
            factor.check_positive()
        except NotPositiveError:
            pass
        else:
            return (f". The given rho (degree {factor.lmax}) is positive: cutting it at La = {la} made it negative; "
                    f"raise lmax_factor (at most 2*lmax)")
    mean = factor.area / (4 * np.pi)
    if not mean > 0:  # a zero or negative mean is no truncation artefact: no positive function has it
        return (f". Its mean value is {mean:.3g}: no positive rho has a mean <= 0, so this is not the truncation of "
                "a positive function; a metric needs rho > 0 everywhere")
    tail = tail_bound(factor.coefficients, factor.lmax)
    if not tail < 0.01 * mean:
        values, _ = factor.evaluate()
        low, high = float(values.min()), float(values.max())
        if -low > _RIPPLE * high:
            return (f". It dips below zero by {-low / high:.0%} of its maximum, far deeper than the ripple the "
                    "truncation of a positive function leaves: rho is negative there, whatever its higher degrees")
        return (f". Its coefficients have not decayed at their last degree {factor.lmax} (the part above it is "
                f"estimated at {tail:.3g}, against a mean of {mean:.3g}), and its negative part is a shallow ripple "
                f"({-low / high:.1%} of its maximum): this is probably the truncation of a positive function, not a "
                "negative one; expand rho to a higher degree")
    return ""


#: The deepest negative ripple, relative to the maximum, that a truncated positive function plausibly has (Gibbs'
#: undershoot is 9 % of the jump it smooths; the boost k = 20 cut at degree 20 dips to 3.6 % of its maximum).
_RIPPLE = 0.1
