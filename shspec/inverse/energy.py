"""The fit energy, its gradient and the Jacobian of its residuals, over the free variables of a parametrization.

E(x) = ½ Σ_i w_i (λ_i(p(x)) − λ*_i)² + ½ ‖D u(x)‖²,

with p(x) and u(x) the :class:`~shspec.inverse.parametrization.Parametrization`'s parameters and variables and D the
model's regularizer (:meth:`~shspec.spectral_model.SpectralModel.regularizer`; for harmonic coefficients
½‖Da‖² = R‖Δρ‖², on a mesh the cotan bi-Laplacian of c or of log c).  Written as a sum of squares of residuals
r = [√w (λ − λ*); D u], Gauss–Newton and Levenberg–Marquardt use its Jacobian [√w ∂λ/∂x; D ∂u/∂x] directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgumentError
from ..spectral_model import SpectralModel, Spectrum
from .parametrization import Parametrization

__all__ = ["eigenvalue_weights", "relative_residual", "rms_relative_residual", "Evaluation", "Objective"]


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


@dataclass(frozen=True)
class Evaluation:
    """Energy and derivatives at one point.

    Attributes
    ----------
    energy : float
    residuals : (k + nreg,) array
        r = [√w (λ − λ*); D p].
    gradient : (nfree,) array or None
        ∂E/∂x over the free parameters (None from :meth:`Objective.values`).
    jacobian : (k + nreg, nfree) array or None
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
        else:
            grad = par.pullback(x, self.model.contract(spec, self.weights * diff))
        return self._finish(x, lam, np.asarray(grad), jac)

    def values(self, x) -> Evaluation:
        """Energy and residuals alone at free values x (nfree,), from the model's eigenvalues without eigenvectors
        (:meth:`~shspec.spectral_model.SpectralModel.eigenvalues`); ``gradient`` and ``jacobian`` are None."""
        lam = self.model.eigenvalues(self.parametrization.params(x), self.target.size)
        self.evaluations += 1
        return self._finish(x, lam, None, None)

    def _finish(self, x, lam: np.ndarray, grad, jac) -> Evaluation:
        """The evaluation at x of eigenvalues ``lam`` (k,), with the regularizer's residuals and derivatives."""
        res = self.sqrt_w * (lam - self.target)
        if self.reg_matrix is not None:
            du = self.reg_matrix @ self.parametrization.variables(x)
            res = np.concatenate([res, du])
            if grad is not None:
                grad = grad + self._reg_free.T @ du
            if jac is not None:
                jac = np.vstack([jac, self._reg_free.toarray()])
        return Evaluation(0.5 * float(res @ res), res, grad, jac, lam, relative_residual(lam, self.target))
