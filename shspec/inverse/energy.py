"""The fit energy, its gradient and the Jacobian of its residuals, over the free parameters of a gauge.

E(p) = ½ Σ_i w_i (λ_i(p) − λ*_i)² + ½ ‖D p‖²,

with D the regularizer's square root: in the harmonic basis ½‖Dp‖² = R ‖Δρ‖² = R Σ (l(l+1))² a_lm², i.e.
D = √(2R) diag(l(l+1)); on a mesh ½‖Dc‖² = R (Lc)ᵀ M₀⁻¹ (Lc), i.e. D = √(2R) M₀^{-1/2} L (MeshModel's
bi-Laplacian penalty).  Written as a sum of squares of residuals r = [√w (λ − λ*); D p], Gauss–Newton and
Levenberg–Marquardt use its Jacobian [√w ∂λ/∂p; D] directly.

The gauge keeps a subset of the parameters free (the others fixed at their current value): in a harmonic fit the
three a_1m (Möbius centering) and, unless the area is fitted, a_00.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidArgumentError
from ..sphere.harmonics import degrees
from ..model import SpectralModel, Spectrum

__all__ = ["eigenvalue_weights", "regularizer_matrix", "harmonic_free_indices", "relative_residual", "Evaluation",
           "Objective"]


def eigenvalue_weights(target, kind: str = "relative") -> np.ndarray:
    """Weights w_i (k,) of the squared eigenvalue errors.

    Parameters
    ----------
    target : (k,) array
        Target eigenvalues λ*, ascending, λ*₀ = 0.
    kind : {"relative", "absolute"}
        "relative": w_i = 1/λ*_i² (so that E is half the sum of squared relative errors); "absolute": w_i = 1.
        λ₀ = 0 gets weight 0 either way: it is 0 for every metric.

    Returns
    -------
    (k,) array
    """
    lam = np.asarray(target, dtype=float)
    if lam.ndim != 1 or lam.size < 2 or not np.all(np.isfinite(lam)):
        raise InvalidArgumentError(f"target eigenvalues must be a finite (k,) array with k >= 2, got {lam.shape}")
    if kind not in ("relative", "absolute"):
        raise InvalidArgumentError(f"kind must be 'relative' or 'absolute', got {kind!r}")
    w = np.zeros(lam.size)
    if kind == "absolute":
        w[1:] = 1.0
    else:
        if np.any(lam[1:] <= 0):
            raise InvalidArgumentError("relative weights need positive target eigenvalues after λ₀")
        w[1:] = 1.0 / lam[1:] ** 2
    return w


def relative_residual(eigenvalues, target) -> float:
    """max_{i≥1} |λ_i − λ*_i| / λ*_i of two (k,) arrays."""
    lam = np.asarray(eigenvalues, dtype=float)
    ref = np.asarray(target, dtype=float)
    if lam.shape != ref.shape or lam.size < 2:
        raise InvalidArgumentError(f"eigenvalue arrays of different shapes {lam.shape} and {ref.shape}")
    return float(np.max(np.abs(lam[1:] - ref[1:]) / np.abs(ref[1:])))


def regularizer_matrix(model: SpectralModel, reg: float):
    """The square root D of the regularizer, ½‖D p‖² = R‖Δρ‖², as a sparse (nrows, nparams) matrix, or None if R = 0.

    Harmonic models: D = √(2R) diag(l(l+1)).  Mesh models: D = √(2R) M₀^{-1/2} L with the cotan stiffness L and
    the reference vertex areas M₀ (the same quadratic form as :meth:`MeshModel.bilaplacian_penalty`).
    """
    from ..galerkin.solver import HarmonicModel
    from ..mesh.model import MeshModel

    reg = float(reg)
    if not np.isfinite(reg) or reg < 0:
        raise InvalidArgumentError(f"the regularization weight must be finite and >= 0, got {reg}")
    if reg == 0:
        return None
    if isinstance(model, HarmonicModel):
        l = degrees(model.lmax_factor).astype(float)
        return sp.diags(np.sqrt(2 * reg) * l * (l + 1)).tocsr()
    if isinstance(model, MeshModel):
        return (sp.diags(np.sqrt(2 * reg / model.vertex_areas)) @ model.stiffness).tocsr()
    raise InvalidArgumentError(f"no regularizer is defined for {type(model).__name__}")


def harmonic_free_indices(lmax_factor: int, fit_area: bool) -> np.ndarray:
    """Free flat indices of a harmonic fit of degree ``lmax_factor``: every (l, m) but a_1m, and a_00 if not fitted."""
    l = degrees(lmax_factor)
    keep = l != 1
    if not fit_area:
        keep[0] = False
    return np.flatnonzero(keep)


@dataclass(frozen=True)
class Evaluation:
    """Energy and derivatives at one point.

    Attributes
    ----------
    energy : float
    residuals : (k + nreg,) array
        r = [√w (λ − λ*); D p].
    gradient : (nfree,) array
        ∂E/∂x over the free parameters.
    jacobian : (k + nreg, nfree) array or None
        ∂r/∂x, when asked for.
    eigenvalues : (k,) array
    relative_residual : float
        max_{i≥1} |λ_i − λ*_i| / λ*_i.
    """

    energy: float
    residuals: np.ndarray
    gradient: np.ndarray
    jacobian: np.ndarray | None
    eigenvalues: np.ndarray
    relative_residual: float


class Objective:
    """E over the free parameters x of a model: p = base with p[free] = x.

    Parameters
    ----------
    model : SpectralModel
    target : (k,) array
        Target eigenvalues, λ*₀ = 0.
    weights : (k,) array
        w_i ≥ 0 (see :func:`eigenvalue_weights`).
    base : (nparams,) array
        Values of the fixed parameters.
    free : (nfree,) int array
        Indices of the free parameters.
    reg : float
        Regularization weight R ≥ 0.

    Notes
    -----
    :meth:`evaluate` raises :class:`~shspec.errors.NotPositiveError` where ρ ≤ 0 somewhere (c ≤ 0 at a vertex);
    the optimizers treat that as an infinitely bad point and shorten or reject the step.
    """

    def __init__(self, model: SpectralModel, target, weights, base, free, reg: float = 0.0):
        if not isinstance(model, SpectralModel):
            raise InvalidArgumentError(f"model must be a SpectralModel, got {type(model).__name__}")
        self.model = model
        self.target = np.asarray(target, dtype=float)
        self.weights = np.asarray(weights, dtype=float)
        if self.weights.shape != self.target.shape or np.any(self.weights < 0):
            raise InvalidArgumentError("weights must be >= 0 and shaped like the target")
        self.base = np.array(base, dtype=float)
        if self.base.shape != (model.nparams,):
            raise InvalidArgumentError(f"base must have shape ({model.nparams},), got {self.base.shape}")
        self.free = np.asarray(free, dtype=np.int64)
        if self.free.ndim != 1 or self.free.size == 0 or np.any(self.free < 0) or np.any(self.free >= model.nparams):
            raise InvalidArgumentError("free must be a non-empty array of parameter indices")
        self.sqrt_w = np.sqrt(self.weights)
        self.reg_matrix = regularizer_matrix(model, reg)
        self.evaluations = 0

    @property
    def nfree(self) -> int:
        return self.free.size

    def params(self, x) -> np.ndarray:
        """Full parameters (nparams,) for free values x (nfree,)."""
        p = self.base.copy()
        p[self.free] = x
        return p

    def initial(self) -> np.ndarray:
        """Free values (nfree,) of ``base``."""
        return self.base[self.free].copy()

    def evaluate(self, x, jacobian: bool = False) -> Evaluation:
        """Energy, residuals, gradient (and Jacobian if asked) at free values x (nfree,)."""
        p = self.params(x)
        spec: Spectrum = self.model.spectrum(p, self.target.size)
        self.evaluations += 1
        lam = spec.eigenvalues
        diff = lam - self.target
        res = self.sqrt_w * diff
        grad = self.model.contract(spec, self.weights * diff)[self.free]
        jac = None
        if jacobian:
            jac = self.sqrt_w[:, None] * self.model.jacobian(spec)[:, self.free]
        if self.reg_matrix is not None:
            dp = self.reg_matrix @ p
            dfree = self.reg_matrix[:, self.free]
            grad = grad + dfree.T @ dp
            res = np.concatenate([res, dp])
            if jacobian:
                jac = np.vstack([jac, dfree.toarray()])
        return Evaluation(0.5 * float(res @ res), res, np.asarray(grad), jac, lam,
                          relative_residual(lam, self.target))
