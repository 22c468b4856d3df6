"""How well K eigenvalues determine the parameters: the singular values of the relative Jacobian, symmetries out.

At parameters p with eigenvalues λ the relative Jacobian J_ij = (∂λ_i/∂p_j)/λ_i (i ≥ 1; λ₀ = 0 says nothing) over
the free parameters tells what the spectrum sees to first order.  The continuous symmetries the spectrum cannot see
(:meth:`~shspec.spectral_model.SpectralModel.symmetry_directions`: the rotations of a harmonic ρ) lie in its null space by
construction; they are projected out first, so that the numbers below describe only what could be determined.
With the singular values s₁ ≥ … of J on the remaining d directions:

* ``rank``: how many exceed ``rank_tol``·s₁; ``underdetermined`` when rank < d (fewer informative eigenvalues than
  parameters, K − 1 < d, or directions the first K eigenvalues do not see);
* ``condition`` = s₁ / s_d: a relative eigenvalue error r leaves p uncertain by about κ·r in the worst direction;
* ``noise_gain`` g = ‖R J⁺‖_F: the expected relative error of ρ per unit of independent relative noise σ on each
  eigenvalue (E‖δp‖ ≈ σ ‖J⁺‖_F), with R the model's :meth:`~shspec.spectral_model.SpectralModel.error_root`
  (‖R δp‖ = ‖δρ‖/‖ρ‖: I/‖p‖ for harmonic coefficients, whose basis is orthonormal; the ρ²-weighted Gram root for
  log ρ, where δρ = ρ δu; the area weights for per-vertex factors);
* ``estimated_error`` for the relative residuals r of a fit: √(‖R J⁺ r‖² + (g σ̂)²).  The first term is the step
  that would still remove the residual's part in the range of J; at a fit's minimum it vanishes (Jᵀr = 0), and
  ‖R J⁺ r‖ alone printed 1e-12 where ρ was off by 9e-11 (degree 8, K = 100, a target solved on Lb 34 and fitted
  on Lb 30).  The second is the error the data's own errors leave, σ̂ = ‖r⊥‖/√ν estimated from the part r⊥ of the
  residual outside the range of J, over ν = K − 1 − rank degrees of freedom (the regression's residual standard
  error); it gave 1.2e-10 there.  It assumes errors that are independent across eigenvalues.

Where the first K eigenvalues determine fewer directions than there are parameters, the parameters with exactly
the spectrum of p form a set through p, curved, not the flat null space of J: :func:`isospectral_point` walks it
(a step along an undetermined direction, then minimum-norm Gauss–Newton back to the spectrum).  The error of such a
point over the directions determined *at p* (:func:`determined_directions`) grows as the square of the step, so no
fit that sees only those K eigenvalues can be held to an error over them that is below that square.

Numbers over the free parameters of the model's gauge (harmonic: a_1m = 0, a_00 when the area is fitted).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..core.checks import check_float, check_int, finite_array
from ..errors import InvalidArgumentError, NotPositiveError
from ..spectral_model import SpectralModel
from .parametrization import Parametrization

__all__ = ["Identifiability", "identifiability", "identifiability_by_numeig", "determined_directions",
           "IsospectralPoint", "isospectral_point"]

#: Halvings of a return step of :func:`isospectral_point` before it gives up.
_HALVINGS = 10


@dataclass(frozen=True)
class Identifiability:
    """What the first K eigenvalues determine at one point (module notes).

    Attributes
    ----------
    numeig : int
        K, λ₀ included.
    free : int
        Free parameters d₀ of the gauge.
    symmetries : int
        Symmetry directions counted out (3 for a generic harmonic ρ, fewer for a symmetric one).
    directions : int
        d = free − symmetries: what could be determined.
    rank : int
    condition : float
        s₁ / s_d (inf when underdetermined).
    estimated_error : float or None
        Linearized relative L2 error of ρ that the residual implies (module notes; None without one).
    noise_gain : float
        Relative error of ρ per unit relative eigenvalue noise (over the determined directions).
    singular_values : (min(K−1, d),) array
    underdetermined : bool
    noise_error : float or None
        The error bar the target's own errors leave: the expected relative error of ρ, √trace(R(JᵀWJ)⁻¹Rᵀ) with
        W = diag(1/σ_rel²) over the determined directions (weighted least squares, Gaussian errors); inf when
        underdetermined; None when no errors were given.
    converged : bool or None
        For the end point of a fit: whether it reached its target (residual within the success tolerance).  The
        linearized ``estimated_error`` holds only there: a local minimum is no noisy solution, and the residual
        it leaves says nothing about its distance to the truth (one off by 2.6 % gave 0.6 %); it is then reported
        as unknown (:attr:`error_estimate`).  None: an analysis at a given point, not a fit's end.
    """

    numeig: int
    free: int
    symmetries: int
    directions: int
    rank: int
    condition: float
    estimated_error: float | None
    noise_gain: float
    singular_values: np.ndarray
    underdetermined: bool
    noise_error: float | None = None
    converged: bool | None = None

    @property
    def error_estimate(self) -> float | None:
        """The relative error of p that the final residual leaves, where that estimate holds; None where it is
        unknown: a fit that did not converge, parameters the eigenvalues do not determine (a zero residual is then
        reached anywhere on a set of solutions), or no residual."""
        return None if self.converged is False or self.underdetermined else self.estimated_error

    def to_dict(self) -> dict:
        """JSON-ready (singular values as a list); ``estimated_error`` is None where the error is unknown."""
        out = {"numeig": self.numeig, "free": self.free, "symmetries": self.symmetries,
               "directions": self.directions, "rank": self.rank,
               "condition": None if not np.isfinite(self.condition) else float(self.condition),
               "estimated_error": self.error_estimate, "noise_gain": float(self.noise_gain),
               "underdetermined": self.underdetermined, "singular_values": self.singular_values.tolist()}
        if self.noise_error is not None:
            out["error_bar"] = self.noise_error if np.isfinite(self.noise_error) else None
        if self.converged is not None:
            out["converged"] = self.converged
        if self.converged is False:
            out["error"] = ("unknown: the fit did not converge to its target, and a residual left at a local "
                            "minimum says nothing about the distance to the truth")
        return out

    def statement(self) -> str:
        """One sentence for the console: what K eigenvalues say about the parameters."""
        if self.underdetermined:
            return (f"{self.numeig} eigenvalues cannot determine the {self.directions} free directions of the "
                    f"parameters (rank {self.rank}): part of the fitted shape is not heard; use more eigenvalues")
        text = (f"{self.numeig} eigenvalues determine all {self.directions} free directions (condition "
                f"{self.condition:.2g}); relative noise sigma on the eigenvalues gives a relative error of about "
                f"{self.noise_gain:.2g}*sigma")
        if self.converged is False:
            text += ("; the fit did not converge to its target, so the error of the fitted parameters is unknown "
                     "(a residual at a local minimum says nothing about the distance to the truth)")
        elif self.noise_error is not None:
            text += f"; the target's own errors leave an error bar of {self.noise_error:.2g} (expected relative error)"
        elif self.estimated_error is not None:
            text += f"; the final residual leaves an estimated relative error of {self.estimated_error:.2g}"
        return text


def _checked(model, params, numeig, rank_tol):
    """The validated arguments of the two analyses, and the spectrum at ``params``."""
    if not isinstance(model, SpectralModel):
        raise InvalidArgumentError(f"model must be a SpectralModel, got {type(model).__name__}")
    p = np.asarray(params, dtype=float)
    if p.shape != (model.nparams,):
        raise InvalidArgumentError(f"params must have shape ({model.nparams},), got {p.shape}")
    numeig = check_int(numeig, "numeig", minimum=2)
    rank_tol = check_float(rank_tol, "rank_tol", positive=True)
    return p, numeig, rank_tol, model.spectrum(p, numeig)


def identifiability(model: SpectralModel, params, numeig: int, *, fit_area: bool = False, residuals=None,
                    noise=None, rank_tol: float = 1e-12) -> Identifiability:
    """The identifiability of ``params`` (nparams,) by the first ``numeig`` eigenvalues of ``model``.

    Parameters
    ----------
    model : SpectralModel
    params : (nparams,) array
    numeig : int
        K ≥ 2, λ₀ included.
    fit_area : bool
        Whether the gauge frees the area (see :meth:`~shspec.spectral_model.SpectralModel.free_parameters`).
    residuals : (K,) array, optional
        Relative eigenvalue residuals (λ_i − λ*_i)/λ*_i of a fit (entry 0 ignored), for ``estimated_error``.
    noise : (K,) array, optional
        Relative one-sigma errors σ_i/λ*_i of the target's eigenvalues (entry 0 ignored), for ``noise_error``.
    rank_tol : float
        Singular values below rank_tol·s₁ count as zero.

    Raises
    ------
    InvalidArgumentError
        For a model that is not a SpectralModel, parameters of the wrong shape, or bad K.
    """
    p, numeig, rank_tol, spec = _checked(model, params, numeig, rank_tol)
    if residuals is not None:
        residuals = finite_array(residuals, "residuals", (numeig,))
    return _analyse(model, p, spec, (numeig,), fit_area, rank_tol, residuals, _checked_noise(noise, numeig))[0]


def _checked_noise(noise, numeig: int):
    if noise is None:
        return None
    noise = finite_array(noise, "noise", (numeig,))
    if np.any(noise[1:] <= 0):
        raise InvalidArgumentError("noise must be > 0 for every eigenvalue after lambda_0")
    return noise


def identifiability_by_numeig(model: SpectralModel, params, numeigs, *, fit_area: bool = False, noise=None,
                              rank_tol: float = 1e-12) -> list[Identifiability]:
    """:func:`identifiability` for several K from one spectrum of max(numeigs) eigenpairs (the Jacobian's first
    K rows are those of K eigenvalues).

    Parameters
    ----------
    model, params, fit_area, rank_tol
        As in :func:`identifiability`.
    numeigs : sequence of int
        The K values, each ≥ 2.
    noise : (max(numeigs),) array, optional
        Relative one-sigma errors of the eigenvalues (entry 0 ignored), for each K's ``noise_error``.

    Returns
    -------
    list of Identifiability
        One per K, in the order given.
    """
    ks = [check_int(k, "numeig", minimum=2) for k in numeigs]
    if not ks:
        raise InvalidArgumentError("numeigs must name at least one K")
    p, _, rank_tol, spec = _checked(model, params, max(ks), rank_tol)
    return _analyse(model, p, spec, ks, fit_area, rank_tol, None, _checked_noise(noise, max(ks)))


def _analyse(model, p, spec, ks, fit_area, rank_tol, residuals, noise=None) -> list[Identifiability]:
    free = model.free_parameters(fit_area)
    jac_all = (model.jacobian(spec)[1:] / spec.eigenvalues[1:, None])[:, free]
    sym = model.symmetry_directions(p)[free]
    basis = np.eye(free.size)
    nsym = 0
    if sym.shape[1]:
        q, sv, _ = scipy.linalg.svd(sym, full_matrices=True)
        nsym = int(np.sum(sv > 1e-10 * max(sv[0], 1e-300)))
        basis = q[:, nsym:]  # orthonormal complement of the symmetry directions
    d = basis.shape[1]
    root = model.error_root(p)[:, free] @ basis  # errors of the parameters, measured as relative errors of rho
    out = []
    for numeig in ks:
        u, s, vt = np.linalg.svd(jac_all[:numeig - 1] @ basis, full_matrices=False)
        rank = int(np.sum(s > rank_tol * s[0])) if s.size and s[0] > 0 else 0
        under = rank < d
        condition = float(s[0] / s[rank - 1]) if not under else float("inf")
        pinv = (vt[:rank].T / s[:rank]) @ u[:, :rank].T
        gain = float(np.linalg.norm(root @ pinv))
        estimated = None
        if residuals is not None:
            r = residuals[1:numeig]
            moved = pinv @ r
            # the residual's part outside the range of J is what the data's own error shows (module notes)
            outside, nu = r - u[:, :rank] @ (u[:, :rank].T @ r), numeig - 1 - rank
            sigma = float(np.linalg.norm(outside)) / np.sqrt(nu) if nu > 0 else 0.0
            estimated = float(np.hypot(np.linalg.norm(root @ moved), gain * sigma))
        noise_error = None
        if noise is not None:
            _, sw, vw = np.linalg.svd(jac_all[:numeig - 1] @ basis / noise[1:numeig, None], full_matrices=False)
            # the weighted least-squares covariance is V diag(1/s²) Vᵀ: its trace in the metric of rho's error
            noise_error = float("inf") if under else float(np.linalg.norm(root @ (vw[:d].T / sw[:d])))
        out.append(Identifiability(numeig=numeig, free=int(free.size), symmetries=nsym, directions=d, rank=rank,
                                   condition=condition, estimated_error=estimated,
                                   noise_gain=gain, singular_values=s,
                                   underdetermined=under, noise_error=noise_error))
    return out


def determined_directions(model: SpectralModel, params, numeig: int, *, rank_tol: float = 1e-6) -> np.ndarray:
    """An orthonormal basis (nparams, r) of the directions of the model's *variables* u (p = u, or s = log p for
    ``transform="exp"``) that the first ``numeig`` eigenvalues determine at ``params``: the right singular vectors
    of the relative Jacobian (∂λ_i/∂u_j)/λ_i (i ≥ 1) whose singular values exceed ``rank_tol``·s₁.

    An error e of the variables is then measured where the spectrum sees it by ‖Bᵀe‖ (the rest of e, in the null
    space, no spectrum of K eigenvalues can correct; e.g. K − 1 < n eigenvalues for n per-vertex factors).

    Raises
    ------
    InvalidArgumentError
        For a model that is not a SpectralModel, parameters of the wrong shape, or bad K or tolerance.
    """
    p, numeig, rank_tol, spec = _checked(model, params, numeig, rank_tol)
    par = Parametrization.at(p, np.arange(p.size), model.transform)  # every variable, the gauge's too
    jac = par.pullback(par.initial(), model.jacobian(spec)[1:] / spec.eigenvalues[1:, None])
    _, s, vt = np.linalg.svd(jac, full_matrices=False)
    rank = int(np.sum(s > rank_tol * s[0])) if s.size and s[0] > 0 else 0
    return vt[:rank].T


@dataclass(frozen=True)
class IsospectralPoint:
    """Parameters with the first K eigenvalues of the parameters they started from (:func:`isospectral_point`).

    Attributes
    ----------
    params : (nparams,) array
    relative_residual : float
        max over i ≥ 1 of |λ_i − λ*_i| / λ*_i, the start's spectrum λ*.
    iterations : int
        Gauss–Newton steps taken back to the spectrum.
    converged : bool
        Whether ``relative_residual`` ≤ the tolerance.
    """

    params: np.ndarray
    relative_residual: float
    iterations: int
    converged: bool


def isospectral_point(model: SpectralModel, params, direction, numeig: int, *, tol: float = 1e-12,
                      max_iter: int = 30, rank_tol: float = 1e-6) -> IsospectralPoint:
    """Step from ``params`` along ``direction`` and return to the first ``numeig`` eigenvalues of ``params``.

    The step is taken in the model's variables u (p = u, or s = log p for ``transform="exp"``).  Each return step is
    the minimum-norm Gauss–Newton correction δu = −J⁺ r of the relative residuals r_i = (λ_i − λ*_i)/λ*_i (i ≥ 1),
    J⁺ the pseudo-inverse of the relative Jacobian over the free parameters truncated at ``rank_tol``·s₁, so that
    the result lies near the point of the isospectral set closest to the step.  A ``direction`` in the null space
    of J (the complement of :func:`determined_directions`) leaves the spectrum unchanged to first order; the return
    then removes the second-order change.

    At a multiple eigenvalue of ``params`` (a symmetric ρ) the sorted eigenvalues are not differentiable and the
    return converges slowly or not at all; the point is then returned with ``converged`` False.

    Parameters
    ----------
    model : SpectralModel
    params : (nparams,) array
        The point whose spectrum λ* (its first ``numeig`` eigenvalues, 1/area) is kept.
    direction : (nparams,) array
        The step in the variables u; zero on the parameters the gauge fixes.
    numeig : int
        K ≥ 2, λ₀ included.
    tol : float
        Largest relative residual accepted.
    max_iter : int
        Most Gauss–Newton steps.
    rank_tol : float
        Relative singular value below which a direction counts as undetermined.

    Returns
    -------
    IsospectralPoint
        Not converged when ``max_iter`` steps did not reach ``tol`` or a step halved ten times still did not lower
        the largest residual (a step too long for the sorted eigenvalues to stay paired with their modes).

    Raises
    ------
    InvalidArgumentError
        For a model that is not a SpectralModel, arrays of the wrong shape, a direction that moves a gauge-fixed
        parameter or is not finite, or bad K, tolerances or iteration count.
    NotPositiveError
        When the step along ``direction`` itself leaves the model's valid parameters (e.g. factors below 0, or
        vertex masses spanning more than double precision resolves); a return step that would is halved instead.
    """
    p, numeig, rank_tol, spec = _checked(model, params, numeig, rank_tol)
    tol = check_float(tol, "tol", positive=True)
    max_iter = check_int(max_iter, "max_iter", minimum=1)
    step = finite_array(direction, "direction", p.shape)
    par = Parametrization.at(p, model.free_parameters(False), model.transform)
    _check_gauge(step, par)
    lam_star = spec.eigenvalues[1:]

    def residuals(x):
        q = par.params(x)
        spec = model.spectrum(q, numeig)
        return spec, (spec.eigenvalues[1:] - lam_star) / lam_star

    x = par.initial() + step[par.free]
    spec, r = residuals(x)
    iteration = 0
    while np.max(np.abs(r)) > tol and iteration < max_iter:
        iteration += 1
        jac = par.pullback(x, model.jacobian(spec)[1:] / lam_star[:, None])
        taken = _halved_step(residuals, x, _min_norm_step(jac, r, rank_tol), r)
        if taken is None:
            break
        x, (spec, r) = taken
    residual = float(np.max(np.abs(r)))
    return IsospectralPoint(params=par.params(x), relative_residual=residual, iterations=iteration,
                            converged=residual <= tol)


def _check_gauge(step, par) -> None:
    """Refuse a step that moves a parameter the gauge fixes."""
    fixed = np.ones(step.size, dtype=bool)
    fixed[par.free] = False
    if np.any(step[fixed] != 0):
        raise InvalidArgumentError(f"direction moves {int(np.count_nonzero(step[fixed]))} parameters the gauge fixes")


def _min_norm_step(jac, r, rank_tol: float) -> np.ndarray:
    """The minimum-norm Gauss–Newton correction −J⁺ r, J⁺ truncated at ``rank_tol``·s₁."""
    u_svd, s, vt = np.linalg.svd(jac, full_matrices=False)
    rank = int(np.sum(s > rank_tol * s[0]))
    return -vt[:rank].T @ ((u_svd[:, :rank].T @ r) / s[:rank])


def _halved_step(residuals, x, delta, r):
    """``(x + δ, residuals there)`` for the first δ of delta, delta/2, … that lowers the largest residual; None if
    none of :data:`_HALVINGS` does."""
    # far from the set the sorted eigenvalues cross and a full step can overshoot: halve until it helps
    for _ in range(_HALVINGS):
        try:
            trial = residuals(x + delta)
        except NotPositiveError:
            trial = None
        if trial is not None and np.max(np.abs(trial[1])) < np.max(np.abs(r)):
            return x + delta, trial
        delta = delta / 2
    return None
