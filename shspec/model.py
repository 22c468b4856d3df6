"""The one interface the inverse solver sees: a fixed stiffness and a mass matrix linear in the parameters.

Both discretizations of shspec fit it.  In the harmonic basis the parameters are the coefficients a_k of ρ and
M(a) = Σ_k a_k G_k; on a triangle mesh they are per-vertex conformal factors c and M(c) = diag(c) M_lumped.  In both
cases ∂λ_i/∂p_j = −λ_i v_iᵀ (∂M/∂p_j) v_i for M-orthonormal eigenvectors, so a model only has to say how to solve and
how to contract eigenvector products against ∂M/∂p.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

__all__ = ["Spectrum", "SpectralModel"]


@dataclass(frozen=True)
class Spectrum:
    """First k eigenpairs of S v = λ M v.

    Attributes
    ----------
    eigenvalues : (k,) float array, ascending, λ₀ = 0 first (units: 1 / area of the surface).
    eigenvectors : (n, k) float array, M-orthonormal: ``V.T @ M @ V = I``.
    """

    eigenvalues: np.ndarray
    eigenvectors: np.ndarray

    @property
    def k(self) -> int:
        return self.eigenvalues.size


class SpectralModel(ABC):
    """A discretized Laplace–Beltrami operator with a fixed stiffness and a mass linear in ``nparams`` parameters."""

    #: number of parameters p that the mass matrix depends on (linearly)
    nparams: int

    @abstractmethod
    def spectrum(self, params: np.ndarray, k: int) -> Spectrum:
        """First k eigenpairs for the parameters ``params`` (nparams,); raises NotPositiveError if M(params) is not SPD."""

    @abstractmethod
    def contract(self, spec: Spectrum, coef: np.ndarray) -> np.ndarray:
        """Σ_i coef_i ∂λ_i/∂p, shape (nparams,), for coef of shape (k,): the adjoint gradient in one pass."""

    @abstractmethod
    def jacobian(self, spec: Spectrum) -> np.ndarray:
        """∂λ_i/∂p_j as a (k, nparams) array."""

    def energy(self, params: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None,
               ) -> tuple[float, np.ndarray, Spectrum]:
        """E = ½ Σ_i w_i (λ_i − λ*_i)² and its gradient (nparams,), for a target spectrum (k,)."""
        target = np.asarray(target, dtype=float)
        spec = self.spectrum(params, target.size)
        w = np.ones(target.size) if weights is None else np.asarray(weights, dtype=float)
        r = spec.eigenvalues - target
        return 0.5 * float(np.sum(w * r * r)), self.contract(spec, w * r), spec
