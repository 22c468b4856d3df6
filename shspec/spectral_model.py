"""The one interface the inverse solver sees: a fixed stiffness, a mass matrix in the parameters, and what a fit needs
to know about them.

Both discretizations of shspec implement it.  In the harmonic basis the parameters are the coefficients a_k of ρ and
M(a) = Σ_k a_k G_k (:class:`~shspec.galerkin.HarmonicModel`); on a triangle mesh they are per-vertex conformal
factors c and M(c) = diag(c) M_lumped (:class:`~shspec.mesh.MeshModel`).  In both cases
∂λ_i/∂p_j = −λ_i v_iᵀ (∂M/∂p_j) v_i for M-orthonormal eigenvectors, so a model only has to say how to solve and how
to contract eigenvector products against ∂M/∂p.

A fit asks more of a model, and everything that differs between discretizations lives here rather than in
:mod:`shspec.inverse`:

* the *variables* the optimizer moves: :meth:`SpectralModel.free_parameters` (the gauge: which parameters are free)
  and :attr:`SpectralModel.transform` (p = u, or p = exp(u) for positive per-vertex factors);
* :meth:`~SpectralModel.random_start`, :meth:`~SpectralModel.regularizer` (on the variables u);
* *levels*, coarse to fine, that a schedule may restrict a stage to (:meth:`~SpectralModel.levels`,
  :meth:`~SpectralModel.restrict`, :meth:`~SpectralModel.enter_level`): the factor's degree for harmonic models,
  none for meshes;
* :meth:`~SpectralModel.invariant` (what tells two solutions apart up to the spectrum's symmetries),
  :meth:`~SpectralModel.symmetry_directions` (the continuous symmetries, counted out of identifiability),
  :meth:`~SpectralModel.escape_moves` (moves between local minima that keep the invariant),
  :meth:`~SpectralModel.to_factor` (the parameters as a harmonic ρ), :meth:`~SpectralModel.compare` and
  :meth:`~SpectralModel.figures` (model-specific comparison with a known truth), :meth:`~SpectralModel.describe`.

A third discretization implements this class and touches no file of :mod:`shspec.inverse`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from .core.checks import check_float, real_array
from .errors import InvalidArgumentError

__all__ = ["Spectrum", "SpectralModel", "TRANSFORMS", "regularization_weight"]

#: How the optimizer's variables u map to the model's parameters p: "identity" (p = u) or "exp" (p = exp(u), for
#: parameters that must stay positive and span decades, such as per-vertex conformal factors).
TRANSFORMS = ("identity", "exp")


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
    #: map from the optimizer's variables u to the parameters p, one of :data:`TRANSFORMS`
    transform: str = "identity"
    #: the optimizer a fit uses when its options name none (measured per discretization)
    default_optimizer: str = "lm"

    # -- the forward problem ----------------------------------------------------------------------------------------

    @abstractmethod
    def spectrum(self, params: np.ndarray, k: int, *, start: Spectrum | None = None) -> Spectrum:
        """First k eigenpairs for the parameters ``params`` (nparams,); raises NotPositiveError if M(params) is not SPD.

        ``start``: optionally, a spectrum this model returned for nearby parameters (a fit passes its previous
        evaluation).  A model may use it to warm-start its eigensolver, but the result must be the one of a cold
        solve to the solver's accuracy; models may ignore it (:class:`~shspec.mesh.MeshModel` does)."""

    def eigenvalues(self, params: np.ndarray, k: int) -> np.ndarray:
        """The first k eigenvalues (k,) alone, equal to :meth:`spectrum`'s to the solver's accuracy: what an
        evaluation needs when it wants the energy only (the probe of a geodesic acceleration, the screening of a
        basin hop's moves).  Default: :meth:`spectrum`'s; a model overrides it where the eigenvalues come cheaper
        without the eigenvectors (:class:`~shspec.galerkin.HarmonicModel`: about half the time)."""
        return self.spectrum(params, k).eigenvalues

    @abstractmethod
    def contract(self, spec: Spectrum, coef: np.ndarray) -> np.ndarray:
        """Σ_i coef_i ∂λ_i/∂p, shape (nparams,), for coef of shape (k,): the adjoint gradient in one pass."""

    @abstractmethod
    def jacobian(self, spec: Spectrum) -> np.ndarray:
        """∂λ_i/∂p_j as a (k, nparams) array."""

    def energy(self, params: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None,
               ) -> tuple[float, np.ndarray, Spectrum]:
        """E = ½ Σ_i w_i (λ_i − λ*_i)² and its gradient (nparams,), for a target spectrum (k,)."""
        target = real_array(target, "target spectrum")
        if target.ndim != 1 or target.size == 0:
            raise InvalidArgumentError(f"the target spectrum must be a non-empty (k,) array, got shape {target.shape}")
        if not np.all(np.isfinite(target)):
            bad = np.flatnonzero(~np.isfinite(target))
            raise InvalidArgumentError(f"the target spectrum holds {target.flat[bad[0]]} at index {bad[0]} "
                                       f"({bad.size} value(s) not finite): the energy would be NaN")
        w = np.ones(target.size) if weights is None else real_array(weights, "weights")
        if w.shape != target.shape:
            raise InvalidArgumentError(f"weights must have the target's shape {target.shape}, got {w.shape}")
        spec = self.spectrum(params, target.size)
        r = spec.eigenvalues - target
        return 0.5 * float(np.sum(w * r * r)), self.contract(spec, w * r), spec

    # -- what a fit needs --------------------------------------------------------------------------------------------

    @abstractmethod
    def describe(self) -> str:
        """A short, stable description ("harmonic Lb=30 La=15"), printed."""

    def scaled(self, params: np.ndarray, factor: float) -> np.ndarray:
        """The parameters (nparams,) of the metric ``factor``·ρ (the surface scaled by √factor in length, its
        eigenvalues divided by ``factor``), for a fit run on a rescaled spectrum (:func:`shspec.inverse.fit`).

        Raises
        ------
        InvalidArgumentError
            For a model that cannot scale its metric (the default).
        """
        raise InvalidArgumentError(f"the model {self.describe()} cannot scale its metric, so it cannot fit a "
                                   "spectrum that far from eigenvalues of order 1: rescale the spectrum")

    def identity(self) -> str:
        """Everything of the model that changes a fit's arithmetic, as a stable string (part of a checkpoint's
        fingerprint, :func:`shspec.inverse.checkpoint.fingerprint`): :meth:`describe` unless a model's description
        leaves something out (a mesh's vertices, say)."""
        return self.describe()

    @abstractmethod
    def free_parameters(self, fit_area: bool) -> np.ndarray:
        """Indices (nfree,) of the parameters a fit moves (the gauge fixes the others); ``fit_area``: whether the
        overall scale is free (models whose parameters fix the area only implicitly may ignore it)."""

    @abstractmethod
    def random_start(self, rng: np.random.Generator, amplitude: float, area: float, level: int | None = None,
                     ) -> np.ndarray:
        """A random symmetry-broken, valid start (nparams,) of the given total ``area``, of relative size
        ``amplitude``, restricted to ``level`` (see :meth:`levels`)."""

    @abstractmethod
    def regularizer(self, reg: float):
        """The square root D of the regularizer, ½‖D u‖² on the variables u, as a sparse (nrows, nparams) matrix, or
        None for ``reg`` = 0."""

    def solve_cost(self, k: int) -> float:
        """The cost of one spectrum of ``k`` eigenvalues, relative to this model's others: the unit of a fit start's
        work (:mod:`shspec.inverse.race`), which must grow with its time but not depend on the machine.  Default:
        ``k``."""
        return float(k)

    def levels(self) -> tuple[int, ...]:
        """Levels, coarse to fine, that a stage may restrict the model to (empty: none)."""
        return ()

    def restrict(self, level: int | None, basis: int | None = None) -> "SpectralModel":
        """The model restricted to ``level`` (None: the model itself); its parameters are a prefix of this model's
        (see :meth:`to_level`).  ``basis``: a coarser discretization of the same parameters, as chosen by
        :meth:`stage_basis` (None: this model's own)."""
        if basis is not None:
            raise InvalidArgumentError(f"{self.describe()} has no coarser discretization (asked for {basis})")
        if level is None:
            return self
        raise InvalidArgumentError(f"{self.describe()} has no levels (a stage asked for level {level})")

    def stage_basis(self, level: int | None, numeig: int, tol: float) -> int | None:
        """The coarsest discretization (a ``basis`` for :meth:`restrict`) on which the first ``numeig`` eigenvalues
        at ``level`` agree with this model's to ``tol`` (relative), for the stages of a fit before its last; None:
        this model's own, the only one of models without coarser ones."""
        return None

    def to_level(self, params: np.ndarray, level: int | None) -> np.ndarray:
        """The parameters of :meth:`restrict` (level) taken from full parameters (nparams,)."""
        return np.asarray(params, dtype=float)[:self.restrict(level).nparams]

    def from_level(self, sub_params: np.ndarray, params: np.ndarray, level: int | None) -> np.ndarray:
        """Full parameters (nparams,): ``params`` with the part of ``level`` replaced by ``sub_params``."""
        out = np.array(params, dtype=float)
        out[:self.restrict(level).nparams] = sub_params
        return out

    def enter_level(self, params: np.ndarray, old: int | None, new: int | None, rng: np.random.Generator,
                    amplitude: float) -> np.ndarray:
        """Parameters at the start of a stage that raises the level from ``old`` to ``new``: the parameters the new
        level adds may need a small random perturbation (to leave a symmetric saddle).  Default: unchanged."""
        return params

    def odd_parameters(self) -> np.ndarray | None:
        """Indices of the parameters that are odd under the antipodal map (harmonic models: those of odd degree),
        which an even stage (:attr:`~shspec.inverse.Stage.even`) holds at 0; None: the model has no parity, and no
        stage may be even.  Default: None."""
        return None

    def release_odd(self, params: np.ndarray, level: int | None, rng: np.random.Generator,
                    amplitude: float) -> np.ndarray:
        """Parameters at the start of the first stage after an even one: the odd parameters of ``level`` get a
        small random perturbation, as :meth:`enter_level` gives the ones a level adds (at an even ρ the gradient
        along them is exactly 0).  Default: unchanged."""
        return params

    def invariant(self, params: np.ndarray, level: int | None = None) -> np.ndarray:
        """What identifies a solution up to the spectrum's symmetries (default: the parameters themselves)."""
        return np.asarray(params, dtype=float)

    def symmetry_directions(self, params: np.ndarray) -> np.ndarray:
        """Tangent vectors (nparams, r) at ``params`` of the continuous symmetries the spectrum cannot see (the
        rotations of a harmonic ρ); the identifiability analysis counts them out.  Default: none, (nparams, 0)."""
        return np.zeros((self.nparams, 0))

    def escape_moves(self, params: np.ndarray, level: int | None = None, *, newest: bool = False) -> list:
        """Parameter vectors (nparams,) that keep :meth:`invariant` but may lie in another basin (basin hops); with
        ``newest``, the moves of only the part that ``level`` adds to the level below (tried when a stage first fits
        it).  Default: none."""
        return []

    def to_factor(self, params: np.ndarray):
        """The parameters as a harmonic :class:`~shspec.sphere.factor.ConformalFactor` (for alignment with a truth,
        and for plots)."""
        raise InvalidArgumentError(f"{self.describe()} cannot express its parameters as a harmonic rho")

    def approximation(self, points, weights, values) -> tuple[np.ndarray, float] | None:
        """The model's best parameters for a positive ρ known by its values (n,) at points (n, 3) of the unit sphere
        with quadrature weights (n,), and the relative weighted L2 error of ρ they leave: the model's floor for that
        ρ, what no spectrum can improve.  None: the model cannot say (default)."""
        return None

    def error_root(self, params: np.ndarray) -> np.ndarray:
        """R (r, nparams) with ‖R δp‖ the relative L2 error of ρ that a small change δp of the parameters makes at
        ``params``: what :mod:`~shspec.inverse.identifiability` measures its errors in.  Default: I / ‖p‖, exact for
        the coefficients of ρ in an orthonormal basis."""
        p = np.asarray(params, dtype=float)
        return np.eye(p.size) / np.linalg.norm(p)

    def compare(self, params: np.ndarray, target) -> dict:
        """Model-specific errors against what the target knows of its truth (JSON-ready); default: none."""
        return {}

    def figures(self, params: np.ndarray, target) -> dict:
        """Model-specific figures of a fit, {file name: matplotlib Figure}; default: none."""
        return {}

    def write_files(self, params: np.ndarray, directory) -> list:
        """Write model-specific result files (a mesh model: its per-vertex factors and sphere mesh) into the existing
        ``directory``; returns their names.  Default: none."""
        return []


def regularization_weight(reg) -> float:
    """A regularization weight R as a float, checked to be finite and ≥ 0 (InvalidArgumentError otherwise)."""
    return check_float(reg, "the regularization weight", minimum=0.0)
