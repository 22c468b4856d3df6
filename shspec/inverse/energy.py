"""The fit energy, its gradient and the Jacobian of its residuals, over the free variables of a parametrization.

E(x) = ½ Σ_i w_i (λ_i(p(x)) − λ*_i)² + ½ ‖D u(x)‖²,

with p(x) and u(x) the :class:`~shspec.inverse.parametrization.Parametrization`'s parameters and variables and D the
model's regularizer (:meth:`~shspec.spectral_model.SpectralModel.regularizer`; for harmonic coefficients
½‖Da‖² = R‖Δρ‖², on a mesh the cotan bi-Laplacian of c or of log c).  Written as a sum of squares of residuals
r = [√w (λ − λ*); D u], Gauss–Newton and Levenberg–Marquardt use its Jacobian [√w ∂λ/∂x; D ∂u/∂x] directly.

**Multiple target eigenvalues.**  Where the target repeats an eigenvalue (an axisymmetric ρ: the orders ±m of a
degree-l mode; a round sphere: 2l + 1 at once), the sorted λ_i of a cluster are not differentiable at the solution:
they split like |δ| for a smooth δ of the parameters, and Gauss–Newton on them converges linearly at best (the
many-law benchmark's axisymmetric truths stalled at residuals 1e-6 … 1e-5 within 1e-3 of ρ).  The cluster's part of
the energy is ½ w̄ ‖H − λ*I‖²_F for H the operator restricted to the cluster's eigenvectors, which is smooth; so each
pair (a, b) of a cluster adds a residual √(2w̄)·H_ab, zero in the current eigenbasis, whose Jacobian row is the
first-order change of that entry, −λ̄ v_aᵀ (∂M/∂p) v_b (λ̄ the pair's mean).  The energy and gradient are unchanged;
the Gauss–Newton model becomes that of the smooth matrix entries (S. Friedland, J. Nocedal, M. L. Overton, "The
formulation and analysis of numerical methods for inverse eigenvalue problems", SIAM J. Numer. Anal. 24 (1987)).
The rows come from the model's own Jacobian of the vectors (v_a ± v_b)/√2 (polarization), so every model whose
∂λ_i is −λ_i times a quadratic form in v_i has them.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InvalidArgumentError
from ..spectral_model import SpectralModel, Spectrum
from .parametrization import Parametrization

__all__ = ["eigenvalue_weights", "relative_residual", "rms_relative_residual", "target_pairs", "Evaluation",
           "Objective", "CLUSTER_RTOL"]

#: Target eigenvalues i ≥ 1 closer than this, relative, are one multiple eigenvalue (module notes).
CLUSTER_RTOL = 1e-9


def eigenvalue_weights(target, kind: str = "relative", errors=None) -> np.ndarray:
    """Weights w_i (k,) of the squared eigenvalue errors.

    Parameters
    ----------
    target : (k,) array
        Target eigenvalues λ*, ascending, λ*₀ = 0.
    kind : {"relative", "absolute"}
        "relative": w_i = 1/λ*_i² (so that E is half the sum of squared relative errors), or w_i = 1/σ_i² when the
        target's ``errors`` σ are given (E is then half its χ²); "absolute": w_i = 1.  λ₀ = 0 gets weight 0 either
        way: it is 0 for every metric.
    errors : (k,) array, optional
        The target's absolute one-sigma errors (:attr:`~shspec.inverse.Target.errors`; entry 0 ignored).

    Returns
    -------
    (k,) array

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.inverse import eigenvalue_weights
    >>> eigenvalue_weights(np.array([0.0, 2.0, 6.0]), "relative")   # 1 / lambda^2; lambda_0 carries none
    array([0.        , 0.25      , 0.02777778])
    """
    lam = np.asarray(target, dtype=float)
    if lam.ndim != 1 or lam.size < 2 or not np.all(np.isfinite(lam)):
        raise InvalidArgumentError(f"target eigenvalues must be a finite (k,) array with k >= 2, got {lam.shape}")
    if kind not in ("relative", "absolute"):
        raise InvalidArgumentError(f"kind must be 'relative' or 'absolute', got {kind!r}")
    w = np.zeros(lam.size)
    if kind == "absolute":
        w[1:] = 1.0
    elif errors is not None:
        err = np.asarray(errors, dtype=float)
        if err.shape != lam.shape or not np.all(err[1:] > 0):
            raise InvalidArgumentError(f"errors must be positive and of the target's shape {lam.shape}")
        w[1:] = 1.0 / err[1:] ** 2
    else:
        if np.any(lam[1:] <= 0):
            raise InvalidArgumentError("relative weights need positive target eigenvalues after λ₀")
        w[1:] = 1.0 / lam[1:] ** 2
    return w


def _relative_errors(eigenvalues, target) -> np.ndarray:
    """|λ_i − λ*_i| / λ*_i for i ≥ 1 of two (k,) arrays, (k − 1,)."""
    lam = np.asarray(eigenvalues, dtype=float)
    ref = np.asarray(target, dtype=float)
    if lam.shape != ref.shape or lam.size < 2:
        raise InvalidArgumentError(f"eigenvalue arrays of different shapes {lam.shape} and {ref.shape}")
    return np.abs(lam[1:] - ref[1:]) / np.abs(ref[1:])


def relative_residual(eigenvalues, target) -> float:
    """max_{i≥1} |λ_i − λ*_i| / λ*_i of two (k,) arrays.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.inverse import relative_residual
    >>> target = np.array([0.0, 2.0, 6.0])
    >>> round(relative_residual(np.array([0.0, 2.002, 5.994]), target), 6)   # the largest, over i >= 1
    0.001
    """
    return float(np.max(_relative_errors(eigenvalues, target)))


def rms_relative_residual(eigenvalues, target) -> float:
    """RMS over i ≥ 1 of (λ_i − λ*_i) / λ*_i of two (k,) arrays."""
    return float(np.sqrt(np.mean(_relative_errors(eigenvalues, target) ** 2)))


def target_pairs(target, weights) -> np.ndarray:
    """The pairs (a, b), a < b, of indices ≥ 1 within one multiple eigenvalue of ``target`` (k,): runs of
    consecutive eigenvalues that differ by at most :data:`CLUSTER_RTOL` relative and carry weights > 0 (module notes).

    Returns
    -------
    (npairs, 2) int array

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.inverse import target_pairs
    >>> l = np.repeat(np.arange(3), 2 * np.arange(3) + 1)
    >>> lam = l * (l + 1.0)                     # the round sphere: 0, 2 (three times), 6 (five times)
    >>> pairs = target_pairs(lam, np.r_[0.0, np.ones(8)])
    >>> len(pairs), pairs[:3].tolist()          # 3 pairs in degree 1, 10 in degree 2
    (13, [[1, 2], [1, 3], [2, 3]])
    """
    lam, w = np.asarray(target, dtype=float), np.asarray(weights, dtype=float)
    # runs from index 1 on (λ₀ = 0 is fixed, never fitted), cut where neighbours differ or one is unweighted
    joined = (np.abs(np.diff(lam[1:])) <= CLUSTER_RTOL * np.abs(lam[2:])) & (w[1:-1] > 0) & (w[2:] > 0)
    bounds = np.concatenate([[1], np.flatnonzero(~joined) + 2, [max(lam.size, 1)]])
    pairs = [pair for lo, hi in zip(bounds[:-1], bounds[1:]) for pair in itertools.combinations(range(lo, hi), 2)]
    return np.array(pairs, dtype=int).reshape(-1, 2)


@dataclass(frozen=True)
class Evaluation:
    """Energy and derivatives at one point.

    Attributes
    ----------
    energy : float
    residuals : (k + npairs + nreg,) array
        r = [√w (λ − λ*); 0 for each pair of a multiple eigenvalue (module notes); D p].
    gradient : (nfree,) array or None
        ∂E/∂x over the free parameters (None from :meth:`Objective.values`).
    jacobian : (k + npairs + nreg, nfree) array or None
        ∂r/∂x, when asked for.
    eigenvalues : (k,) array
    relative_residual : float
        max_{i≥1} |λ_i − λ*_i| / λ*_i.
    """

    energy: float
    residuals: np.ndarray
    gradient: np.ndarray | None
    jacobian: np.ndarray | None
    eigenvalues: np.ndarray
    relative_residual: float


class Objective:
    """E over the free variables x of a parametrization of a model's parameters.

    Parameters
    ----------
    model : SpectralModel
    target : (k,) array
        Target eigenvalues, λ*₀ = 0.
    weights : (k,) array
        w_i ≥ 0 (see :func:`eigenvalue_weights`).
    parametrization : Parametrization
        Free variables x ↦ parameters p (size ``model.nparams``).
    reg : float
        Regularization weight R ≥ 0.

    Notes
    -----
    :meth:`evaluate` raises :class:`~shspec.errors.NotPositiveError` where ρ ≤ 0 somewhere (c ≤ 0 at a vertex);
    the optimizers treat that as an infinitely bad point and shorten or reject the step.

    Examples
    --------
    >>> from shspec import HarmonicModel
    >>> from shspec.fitting import blob_factor, harmonic_target
    >>> from shspec.inverse import Objective, Parametrization, eigenvalue_weights
    >>> model, rho = HarmonicModel(10, 2), blob_factor().truncated(2)
    >>> lam = harmonic_target(rho, 10, 16).eigenvalues
    >>> x = Parametrization.at(rho.coefficients, model.free_parameters(False))
    >>> objective = Objective(model, lam, eigenvalue_weights(lam, "relative"), x)
    >>> objective.nfree, objective.evaluate(objective.initial()).energy < 1e-20   # the truth: zero energy
    (5, True)
    """

    def __init__(self, model: SpectralModel, target, weights, parametrization: Parametrization, reg: float = 0.0):
        if not isinstance(model, SpectralModel):
            raise InvalidArgumentError(f"model must be a SpectralModel, got {type(model).__name__}")
        if not isinstance(parametrization, Parametrization):
            raise InvalidArgumentError(f"parametrization must be a Parametrization, got "
                                       f"{type(parametrization).__name__}")
        if parametrization.size != model.nparams:
            raise InvalidArgumentError(f"the parametrization has {parametrization.size} variables; the model "
                                       f"{model.nparams} parameters")
        self.model = model
        self.target = np.asarray(target, dtype=float)
        self.weights = np.asarray(weights, dtype=float)
        if self.weights.shape != self.target.shape or np.any(self.weights < 0):
            raise InvalidArgumentError("weights must be >= 0 and shaped like the target")
        self.parametrization = parametrization
        self.sqrt_w = np.sqrt(self.weights)
        self.pairs = target_pairs(self.target, self.weights)
        #: the residuals of the pairs of multiple eigenvalues, after the eigenvalues' (module notes): linear in the
        #: parameters, so a second-order correction (LM's acceleration) leaves them out
        self.pair_rows = slice(self.target.size, self.target.size + len(self.pairs))
        self._pair_scale = np.sqrt(self.weights[self.pairs].mean(axis=1))  # √w̄ of each pair
        self.reg_matrix = model.regularizer(reg)
        self._reg_free = None if self.reg_matrix is None else self.reg_matrix[:, parametrization.free]
        self.evaluations = 0
        self._last: Spectrum | None = None

    @property
    def nfree(self) -> int:
        return self.parametrization.nfree

    @property
    def cost(self) -> float:
        """The work of one iteration here (:mod:`~shspec.inverse.race`): the model's
        :meth:`~shspec.spectral_model.SpectralModel.solve_cost` for the target's eigenvalues."""
        return self.model.solve_cost(self.target.size)

    def params(self, x) -> np.ndarray:
        """Full parameters (nparams,) for free values x (nfree,)."""
        return self.parametrization.params(x)

    def initial(self) -> np.ndarray:
        """Free values (nfree,) of the parametrization's base."""
        return self.parametrization.initial()

    def evaluate(self, x, jacobian: bool = False) -> Evaluation:
        """Energy, residuals, gradient (and Jacobian if asked) at free values x (nfree,)."""
        par = self.parametrization
        # successive points of a fit are close: the last spectrum may warm-start the next (the model decides)
        spec: Spectrum = self.model.spectrum(par.params(x), self.target.size, start=self._last)
        self._last = spec
        self.evaluations += 1
        lam = spec.eigenvalues
        diff = lam - self.target
        jac = None
        if jacobian:
            # the gradient is then Jᵀ w (λ − λ*): one pass over the eigenvectors instead of two
            dlam = self.model.jacobian(spec)
            grad = par.pullback(x, (self.weights * diff) @ dlam)
            jac = self.sqrt_w[:, None] * par.pullback(x, dlam)
            if len(self.pairs):
                jac = np.vstack([jac, par.pullback(x, self._pair_jacobian(spec))])
        else:
            grad = par.pullback(x, self.model.contract(spec, self.weights * diff))
        return self._finish(x, lam, np.asarray(grad), jac)

    def values(self, x) -> Evaluation:
        """Energy and residuals alone at free values x (nfree,), from the model's eigenvalues without eigenvectors
        (:meth:`~shspec.spectral_model.SpectralModel.eigenvalues`); ``gradient`` and ``jacobian`` are None."""
        lam = self.model.eigenvalues(self.parametrization.params(x), self.target.size)
        self.evaluations += 1
        return self._finish(x, lam, None, None)

    def _pair_jacobian(self, spec: Spectrum) -> np.ndarray:
        """Rows √(2w̄)·∂H_ab/∂p of the pairs (npairs, nparams) by polarization: the model's ∂λ of the vectors
        (v_a ± v_b)/√2 at λ̄ differ by −2λ̄ v_aᵀ(∂M/∂p)v_b."""
        a, b = self.pairs.T
        v, lam = spec.eigenvectors, spec.eigenvalues
        mean = 0.5 * (lam[a] + lam[b])
        both = replace(spec, eigenvalues=np.repeat(mean, 2),
                       eigenvectors=np.stack([v[:, a] + v[:, b], v[:, a] - v[:, b]], axis=2).reshape(v.shape[0], -1)
                       / np.sqrt(2.0))
        d = self.model.jacobian(both)
        return self._pair_scale[:, None] * (d[0::2] - d[1::2]) / np.sqrt(2.0)

    def _finish(self, x, lam: np.ndarray, grad, jac) -> Evaluation:
        """The evaluation at x of eigenvalues ``lam`` (k,), with the pairs' residuals (zero in the current
        eigenbasis) and the regularizer's residuals and derivatives."""
        res = np.concatenate([self.sqrt_w * (lam - self.target), np.zeros(len(self.pairs))])
        if self.reg_matrix is not None:
            du = self.reg_matrix @ self.parametrization.variables(x)
            res = np.concatenate([res, du])
            if grad is not None:
                grad = grad + self._reg_free.T @ du
            if jac is not None:
                jac = np.vstack([jac, self._reg_free.toarray()])
        return Evaluation(0.5 * float(res @ res), res, grad, jac, lam, relative_residual(lam, self.target))
