"""The harmonic discretization behind the inverse solver: :class:`HarmonicModel`, ρ = Σ a_k Y_k up to La in the
basis {Y_i : l_i ≤ Lb}, and its :class:`SpectrumResult`.

How a spectrum is solved is in :mod:`shspec.galerkin.solver`'s notes; this model holds the table, the assembly and
the derivatives, and answers what :class:`~shspec.spectral_model.SpectralModel` asks of a discretization.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass

import numba as nb
import numpy as np
import scipy.sparse as sp
from scipy.spatial.transform import Rotation

from ..core.checks import check_float, check_int
from ..errors import BandLimitError, InvalidArgumentError, NotPositiveError
from ..gaunt.cache import get_table
from ..gaunt.table import MAX_BASIS_DEGREE, GauntTable, plan_bytes, table_size
from ..spectral_model import SpectralModel, Spectrum, regularization_weight
from ..core.resources import Need, check_need
from ..sphere.evaluate import weighted_expansion
from ..sphere.factor import ConformalFactor
from ..sphere.harmonics import check_degree, degree_order, degrees, lmax_of_size, ncoeffs
from ..sphere.random import random_centred_coefficients, random_coefficients
from ..sphere.rotate import power_spectrum, rotate_coefficients
from ..core.threads import reproducible_call, serialized
from .eigen import cold_eigh, guard_count, solve_cost, warm_eigh
from .gridforms import GridQuadraticForms
from .truncation import TruncationEstimate, basis_degree_for

__all__ = ["HarmonicModel", "SpectrumResult", "WARM_GATE", "forward_need"]

#: A warm start is tried only when ‖a − a_start‖ ≤ WARM_GATE · ‖a‖: beyond it Rayleigh–Ritz on the old vectors
#: cannot reach 1e-14 (its eigenvalue error is ~250·δ² at (30, 15, 256), :mod:`shspec.galerkin.eigen`), and the
#: attempt would cost a fifth of a cold solve for nothing.
WARM_GATE = 1e-8


@serialized
@nb.njit(cache=True, parallel=True)
def _schur_scaled_upper(m_upper, dinv, out):
    """Upper triangle of H = D⁻¹ (M_rr − m mᵀ/M₀₀) D⁻¹ from the upper triangle of M, into out (N−1, N−1)."""
    n = out.shape[0]
    m00 = m_upper[0, 0]
    for r in nb.prange(n):
        mr = m_upper[0, r + 1] / m00
        for c in range(r, n):
            out[r, c] = (m_upper[r + 1, c + 1] - mr * m_upper[0, c + 1]) * dinv[r] * dinv[c]


@dataclass(frozen=True)
class SpectrumResult(Spectrum):
    """First k eigenpairs of S v = λ M(a) v for a conformal factor.

    Attributes
    ----------
    eigenvalues : (k,) float array
        Ascending, λ₀ = 0 first (units 1/area: eigenvalues of the unit sphere are l(l+1)).
    eigenvectors : (N, k) float array
        Coefficients of the eigenfunctions in the basis Y_i, i < N = (Lb+1)**2, M-orthonormal.
    lmax : int
        Basis band limit Lb.
    lmax_factor : int
        Band limit La of the factor used.
    truncation : TruncationEstimate or None
        Estimated relative errors from the two band limits (:mod:`shspec.galerkin.truncation`); set by
        :func:`spectrum`, None from :meth:`HarmonicModel.spectrum`.
    coefficients : (nparams,) float array or None
        The factor coefficients a solved for (what a warm start compares with).
    reduced_vectors : (N−1, k−1+g) float array or None
        Orthonormal eigenvectors u of the reduced problem H u = μ u (module docstring), μ descending, with g guard
        vectors beyond the k−1 wanted: the seed of a warm start (:func:`shspec.galerkin.eigen.warm_eigh`); g = 0
        from :func:`spectrum`, which no solve warm-starts from.
    solver : str
        How it was solved: 'evr' or 'evd' (the cold LAPACK driver), 'warm' (certified Rayleigh–Ritz), '' (k = 1).

    Examples
    --------
    >>> from shspec import ConformalFactor, spectrum
    >>> result = spectrum(ConformalFactor.mobius_boost(2.0, lmax=20), lmax=20, k=4)
    >>> type(result).__name__, result.eigenvalues.round(6), result.eigenvectors.shape
    ('SpectrumResult', array([0., 2., 2., 2.]), (441, 4))
    """

    lmax: int = 0
    lmax_factor: int = 0
    truncation: TruncationEstimate | None = None
    coefficients: np.ndarray | None = dataclasses.field(default=None, repr=False)
    reduced_vectors: np.ndarray | None = dataclasses.field(default=None, repr=False)
    solver: str = ""


class HarmonicModel(SpectralModel):
    """The Galerkin discretization of a basis band limit Lb and a factor band limit La.

    Parameters are the flat coefficients a (nparams = (La+1)**2) of ρ; M(a) = Σ_k a_k G_k is linear in them.

    Parameters
    ----------
    lmax : int
        Basis band limit Lb.
    lmax_factor : int
        Factor band limit La (<= 2·Lb).
    table : GauntTable, optional
        A table covering (Lb, La); by default taken from the cache (built there if missing and ``build``).
    cache_dir : path-like, optional
        Cache directory for the table.
    build : bool
        Allow building a missing table.
    check_positive : bool
        Check ρ > 0 before each solve (a certified bound: a clear error instead of a non-SPD mass matrix).

    Raises
    ------
    ResourceLimitError
        The table, its plan and the two dense N × N matrices of a solve would not fit in the available memory
        (:mod:`shspec.core.resources`); checked before anything is allocated or built.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import HarmonicModel
    >>> model = HarmonicModel(12, 4)                 # basis degree Lb = 12, rho of degree La = 4
    >>> rho = np.zeros(model.nparams); rho[0] = np.sqrt(4 * np.pi)   # rho = 1: the unit sphere
    >>> model.describe(), model.eigenvalues(rho, 4).round(10)
    ('harmonic Lb=12 La=4', array([0., 2., 2., 2.]))
    """

    def __init__(self, lmax: int, lmax_factor: int, *, table: GauntTable | None = None, cache_dir=None,
                 build: bool = True, check_positive: bool = True):
        lmax = check_degree(lmax, "lmax", minimum=1, maximum=MAX_BASIS_DEGREE)
        lmax_factor = check_degree(lmax_factor, "lmax_factor", maximum=2 * lmax)
        check_need(forward_need(lmax, lmax_factor, with_table=table is None), limits=(lmax, lmax_factor),
                   estimate=forward_need)
        if table is None:
            table = get_table(lmax, lmax_factor, cache_dir=cache_dir, build=build)
        elif not isinstance(table, GauntTable):
            raise InvalidArgumentError(f"table must be a GauntTable, got {type(table).__name__}")
        elif not table.covers(lmax, lmax_factor):
            raise BandLimitError(f"the table ({table.lmax},{table.lmax_factor}) does not cover ({lmax},{lmax_factor})")
        self.table = table.restrict(lmax, lmax_factor)
        self.lmax = lmax
        self.lmax_factor = lmax_factor
        self.nparams = ncoeffs(lmax_factor)
        self.nbasis = ncoeffs(lmax)
        self.check_positive = bool(check_positive)
        ls = degrees(lmax)[1:].astype(float)
        self._dinv = 1.0 / np.sqrt(ls * (ls + 1.0))
        self._restricted: dict[int, HarmonicModel] = {}
        self._grid_forms: GridQuadraticForms | None = None

    def __repr__(self) -> str:
        return f"HarmonicModel(lmax={self.lmax}, lmax_factor={self.lmax_factor})"

    def _params(self, params) -> np.ndarray:
        if isinstance(params, ConformalFactor):
            if params.lmax > self.lmax_factor and np.any(params.coefficients[self.nparams:] != 0):
                raise BandLimitError(f"{params.name} has degree {params.lmax} > lmax_factor = {self.lmax_factor}")
            return params.truncated(self.lmax_factor).coefficients
        a = np.asarray(params, dtype=float)
        if a.shape != (self.nparams,):
            raise InvalidArgumentError(f"expected {self.nparams} coefficients (La = {self.lmax_factor}), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise InvalidArgumentError("the coefficients of rho contain NaN or inf")
        return a

    def mass_matrix(self, params) -> np.ndarray:
        """The full symmetric mass matrix M(a), (N, N)."""
        return self.table.mass_matrix(self._params(params))

    @reproducible_call
    def spectrum(self, params, k: int, *, start: Spectrum | None = None, guards: bool = True) -> SpectrumResult:
        """First k eigenpairs (λ₀ = 0 included) for the factor coefficients ``params`` or a ConformalFactor.

        ``start``: the spectrum of a nearby ρ from this model (the previous evaluation of a fit).  Its eigenvectors
        and guard vectors seed a certified Rayleigh–Ritz step (:func:`shspec.galerkin.eigen.warm_eigh`), used when
        ρ moved by at most :data:`WARM_GATE` (relative, in the coefficients) and the residual bound certifies the
        eigenvalues to 1e-14 relative; otherwise, and for a ``start`` of another model or size, the cold solve.
        The result says which in ``solver``.  ``guards`` False: solve for the k eigenpairs alone, not the guard
        vectors a later warm start needs (a result that cannot be a ``start``; the MRRR driver is faster by their
        share).
        """
        if start is not None and not isinstance(start, Spectrum):
            raise InvalidArgumentError(f"start must be a Spectrum or None, got {type(start).__name__}")
        a, k, m = self._mass(params, k)
        n = self.nbasis
        vals = np.zeros(k)
        vecs = np.zeros((n, k))
        vecs[0, 0] = 1.0 / np.sqrt(m[0, 0])
        if k == 1:
            return SpectrumResult(vals, vecs, lmax=self.lmax, lmax_factor=self.lmax_factor, coefficients=a.copy())
        h = np.empty((n - 1, n - 1))
        _schur_scaled_upper(m, self._dinv, h)
        ritz, solver = None, "warm"
        if self._warm_usable(start, a, k):
            ritz = warm_eigh(h, start.reduced_vectors, k - 1)
        if ritz is None:
            mu, u, solver = cold_eigh(h, k - 1 + (guard_count(k - 1, n - 1) if guards else 0))
        else:
            mu, u = ritz
        self._check_reduced(mu[k - 2])
        lam = 1.0 / mu[:k - 1]
        vr = (u[:, :k - 1] * self._dinv[:, None]) * np.sqrt(lam)[None, :]
        vecs[1:, 1:] = vr
        vecs[0, 1:] = -(m[0, 1:] @ vr) / m[0, 0]
        vals[1:] = lam
        return SpectrumResult(vals, vecs, lmax=self.lmax, lmax_factor=self.lmax_factor, coefficients=a.copy(),
                              reduced_vectors=np.ascontiguousarray(u), solver=solver)

    @reproducible_call
    def eigenvalues(self, params, k: int) -> np.ndarray:
        """The first k eigenvalues (k,) alone, as :meth:`spectrum` gives them cold; about half its time without the
        eigenvectors (what the truncation estimate of :func:`spectrum`, the probe of LM's geodesic acceleration and
        the screening of basin-hop moves need)."""
        a, k, m = self._mass(params, k)
        vals = np.zeros(k)
        if k > 1:
            h = np.empty((self.nbasis - 1, self.nbasis - 1))
            _schur_scaled_upper(m, self._dinv, h)
            mu = cold_eigh(h, k - 1, vectors=False)[0]
            self._check_reduced(mu[k - 2])
            vals[1:] = 1.0 / mu
        return vals

    def _mass(self, params, k) -> tuple[np.ndarray, int, np.ndarray]:
        """Checked coefficients, k, and the upper triangle of M (N, N)."""
        a = self._params(params)
        k = check_int(k, "k (number of eigenpairs)", minimum=1)
        if k > self.nbasis:
            raise BandLimitError(f"k = {k} eigenpairs asked of a basis of {self.nbasis} functions (Lb = {self.lmax}); "
                                 f"raise lmax to at least {int(np.ceil(np.sqrt(k))) - 1}")
        if self.check_positive:
            ConformalFactor(a).check_positive()
        m = self.table.mass_matrix(a, symmetrize=False)
        if not m[0, 0] > 0:
            raise NotPositiveError(f"the area a_00*sqrt(4pi) = {a[0] * np.sqrt(4 * np.pi):.6g} is not positive")
        return a, k, m

    @staticmethod
    def _check_reduced(mu_min: float) -> None:
        if not mu_min > 0:
            raise NotPositiveError(
                f"the mass matrix is not positive definite (reduced eigenvalue {mu_min:.3g}); rho is negative "
                "or nearly so somewhere")

    def _warm_usable(self, start, a: np.ndarray, k: int) -> bool:
        """Whether ``start`` comes from this model with as many eigenpairs and from a ρ within the gate of a."""
        if not (isinstance(start, SpectrumResult) and start.reduced_vectors is not None and start.k == k
                and start.coefficients is not None and start.coefficients.shape == a.shape
                and start.reduced_vectors.shape[0] == self.nbasis - 1 and start.reduced_vectors.shape[1] > k - 1):
            return False
        return bool(np.linalg.norm(a - start.coefficients) <= WARM_GATE * np.linalg.norm(a))

    @property
    def grid_forms(self) -> GridQuadraticForms:
        """The quadrature of the quadratic forms v_qᵀ G_k v_q (built on first use)."""
        if self._grid_forms is None:
            self._grid_forms = GridQuadraticForms(self.lmax, self.lmax_factor)
        return self._grid_forms

    @reproducible_call
    def jacobian(self, spec: Spectrum) -> np.ndarray:
        """∂λ_i/∂a_k = −λ_i v_iᵀ G_k v_i, as a (k, nparams) array.

        The quadratic forms come from the exact GLQ quadrature (:mod:`shspec.galerkin.gridforms`), equal to the
        Gaunt-table contraction to rounding and 6-20× faster than it at the sizes of a fit (:doc:`/benchmarks`)."""
        if not isinstance(spec, Spectrum):
            raise InvalidArgumentError(f"jacobian needs the Spectrum of a solve (model.spectrum(...)), got "
                                       f"{type(spec).__name__}")
        q = self.grid_forms(spec.eigenvectors)
        return -(q * spec.eigenvalues[None, :]).T

    @reproducible_call
    def contract(self, spec: Spectrum, coef: np.ndarray) -> np.ndarray:
        """Σ_i c_i ∂λ_i/∂a = −∫ Y_k Σ_i c_i λ_i f_i² dΩ (f_i the eigenfunctions), by the same quadrature as
        :meth:`jacobian`, (nparams,)."""
        coef = np.asarray(coef, dtype=float)
        if coef.shape != spec.eigenvalues.shape:
            raise InvalidArgumentError(f"coef must have shape {spec.eigenvalues.shape}, got {coef.shape}")
        return -self.grid_forms.weighted(spec.eigenvectors, coef * spec.eigenvalues)

    # -- what the inverse solver asks of a model (shspec.spectral_model.SpectralModel) -------------------------------------

    def describe(self) -> str:
        return f"harmonic Lb={self.lmax} La={self.lmax_factor}"

    def scaled(self, params: np.ndarray, factor: float) -> np.ndarray:
        """factor·a: ρ is linear in its coefficients."""
        return np.asarray(params, dtype=float) * factor

    def free_parameters(self, fit_area: bool) -> np.ndarray:
        """Every a_lm but the gauge a_1m = 0 (Möbius centering), and a_00 (the area) only if ``fit_area``."""
        keep = degrees(self.lmax_factor) != 1
        keep[0] = bool(fit_area)
        return np.flatnonzero(keep)

    def random_start(self, rng: np.random.Generator, amplitude: float, area: float, level: int | None = None,
                     ) -> np.ndarray:
        """a_00 from the area, a_1m = 0, degrees 2 … level random (odd ones included, so that the fit is not
        trapped in the even subspace, :doc:`/theory`) with RMS ∝ amplitude/l relative to the mean; the amplitude is
        halved until the minimum of ρ is at least a quarter of its mean."""
        la = self.lmax_factor if level is None else self.restrict(level).lmax_factor
        a00 = area / np.sqrt(4 * np.pi)
        noise = random_coefficients(rng, la, amplitude * a00)
        params = np.zeros(self.nparams)
        params[0] = a00
        for _ in range(30):
            params[1:ncoeffs(la)] = noise[1:]
            if _minimum(params) >= 0.25 * a00 / np.sqrt(4 * np.pi):
                return params
            noise = noise * 0.5
        raise InvalidArgumentError("could not draw a positive random start")  # pragma: no cover

    def regularizer(self, reg: float):
        """D = √(2R) diag(l(l+1)), so that ½‖Da‖² = R‖Δρ‖² = R Σ (l(l+1))² a_lm²."""
        return laplacian_regularizer(reg, self.lmax_factor)

    def levels(self) -> tuple[int, ...]:
        """The factor degrees 2 … La (degree 1 is the gauge)."""
        return tuple(range(2, self.lmax_factor + 1))

    def restrict(self, level: int | None, basis: int | None = None) -> "HarmonicModel":
        """The model of factor degree ``level`` ≤ La (None: La) on the basis of degree ``basis`` ≤ Lb (None: Lb),
        sharing (a restriction of) the table."""
        la = self.lmax_factor if level is None else check_degree(level, "level (factor degree)",
                                                                 maximum=self.lmax_factor)
        lb = self.lmax if basis is None else check_degree(basis, "basis degree", minimum=max(1, (la + 1) // 2),
                                                          maximum=self.lmax)
        if (la, lb) == (self.lmax_factor, self.lmax):
            return self
        if (la, lb) not in self._restricted:
            self._restricted[(la, lb)] = HarmonicModel(lb, la, table=self.table, check_positive=self.check_positive)
        return self._restricted[(la, lb)]

    def solve_cost(self, k: int) -> float:
        """:func:`~shspec.galerkin.eigen.solve_cost` of the basis: the dense solve dominates, whatever ``k``."""
        return solve_cost(ncoeffs(self.lmax))

    def stage_basis(self, level: int | None, numeig: int, tol: float) -> int | None:
        """The smallest basis degree Lb' < Lb on which the first ``numeig`` eigenvalues of a reference ρ of degree
        ``level`` agree with those on Lb to ``tol`` (relative), or None if only Lb does.

        The reference is the planner's (:func:`~shspec.fitting.numeig_plan.plan_numeig`): a random centred ρ (seed 0,
        amplitude 0.2) of the law of a fit's random starts, so that the choice depends on the stage only, not on
        the start.  Bisection from the floor (Lb' + 1)² ≥ 1.5·numeig (:func:`~shspec.galerkin.truncation.
        basis_degree_for`); the agreement grows with Lb'.  An early stage of a degree ramp matches few eigenvalues,
        and a solve on its own basis costs a fraction of one on Lb: for the blob's degree ramp at La = 15, K = 704
        (Lb 42) and tol 1e-5, the stage of degree 8 and 100 eigenvalues gets Lb' = 18 (361 basis functions instead
        of 1849) and that of 400 eigenvalues Lb' = 35; choosing all 18 took about 18 s.
        """
        return smallest_agreeing_basis(
            self, level, numeig, tol,
            # an unregistered table: the probes of the bisection are not kept in the shared one
            lambda lb, la: HarmonicModel(lb, la, table=self.table.restrict(lb, la, keep=False)))

    def enter_level(self, params: np.ndarray, old: int | None, new: int | None, rng: np.random.Generator,
                    amplitude: float) -> np.ndarray:
        """The degrees old+1 … new get a small random perturbation of RMS ∝ amplitude/l relative to the mean: at an
        even ρ the gradient along odd degrees is exactly 0 (the parity saddle, :doc:`/theory`)."""
        old = self.lmax_factor if old is None else old
        new = self.lmax_factor if new is None else new
        if new <= old:
            return params
        part = np.zeros(ncoeffs(new), dtype=bool)
        part[ncoeffs(old):] = True
        return _perturbed(params, part, random_coefficients(rng, new, amplitude * params[0], low=old + 1))

    def odd_parameters(self) -> np.ndarray:
        """The a_lm of odd degree l ≥ 3 (degree 1 is the gauge, always 0)."""
        return np.flatnonzero((degrees(self.lmax_factor) % 2 == 1) & (degrees(self.lmax_factor) >= 3))

    def release_odd(self, params: np.ndarray, level: int | None, rng: np.random.Generator,
                    amplitude: float) -> np.ndarray:
        """The odd degrees 3 … ``level`` get a small random perturbation, as in :meth:`enter_level`."""
        la = self.restrict(level).lmax_factor
        part = np.zeros(ncoeffs(la), dtype=bool)
        part[self.restrict(level).odd_parameters()] = True
        return _perturbed(params, part, random_coefficients(rng, la, amplitude * params[0], low=3))

    def invariant(self, params: np.ndarray, level: int | None = None) -> np.ndarray:
        """Per-degree power Σ_m a_lm² (La+1,): invariant under O(3)."""
        return power_spectrum(np.asarray(params, dtype=float))

    def symmetry_directions(self, params: np.ndarray) -> np.ndarray:
        """The three rotation generators applied to ρ, (nparams, 3): L_z exactly (a_{l,m} ↦ −m a_{l,−m},
        a_{l,−m} ↦ m a_{l,m}), and L_z conjugated by the exact rotations (pyshtools) that take z to two other axes.
        Each column is in the null space of the Jacobian: rotations leave the spectrum unchanged.  A column is 0
        where ρ is symmetric about that axis."""
        a = np.asarray(params, dtype=float)
        if a.shape != (self.nparams,):
            raise InvalidArgumentError(f"expected {self.nparams} coefficients, got shape {a.shape}")
        return rotation_generators(a)

    def escape_moves(self, params: np.ndarray, level: int | None = None, *, newest: bool = False) -> list:
        """Power-preserving moves of one degree block l ≥ 2 (l ≤ level).

        Default: for every block its half-turns about the z, y and x axes, and for odd l also these composed with
        the sign −1 and the sign alone (the point reflection of that block).  The failed fits of the blob end in
        local minima whose per-degree power is already right (to ~1e-4) while the degree blocks are wrongly placed
        relative to each other; for even l the mirror z ↦ −z of a block is its half-turn about z, for odd l the
        negated one.

        ``newest``: only the block of degree ``level``, turned by the 23 non-trivial rotations of the octahedral
        group (a grid of SO(3) 90° apart) and, for odd degrees, by the 24 improper ones (the point reflection acts
        on degree l as (−1)^l) — its orientation relative to the blocks fitted before it.
        """
        la = self.lmax_factor if level is None else self.restrict(level).lmax_factor
        return block_moves(np.asarray(params, dtype=float), la, newest=newest)

    def approximation(self, points, weights, values) -> tuple[np.ndarray, float]:
        """ρ's weighted least-squares expansion to degree La and its relative misfit
        (:func:`~shspec.sphere.evaluate.weighted_expansion`)."""
        return weighted_expansion(points, weights, values, self.lmax_factor)

    def to_factor(self, params: np.ndarray) -> ConformalFactor:
        return ConformalFactor(np.array(params, dtype=float), name="fit")


def _octahedral_euler() -> list:
    """z-y-z Euler angles (3,) of the 24 rotations of the octahedral group, the identity first."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # gimbal lock: any of the equivalent angle triples will do
        group = Rotation.create_group("O")
        angles = [group[i].as_euler("zyz") for i in range(len(group))]
    angles.sort(key=lambda a: float(np.sum(np.abs(Rotation.from_euler("zyz", a).as_rotvec()))))
    return [np.asarray(a, dtype=float) for a in angles]


_OCTAHEDRAL_EULER = _octahedral_euler()


def laplacian_regularizer(reg, lmax_factor: int):
    """D = √(2R) diag(l(l+1)) over the coefficients of degree ≤ ``lmax_factor`` (sparse), so that ½‖Dc‖² = R‖Δf‖²
    for the function f of coefficients c; None for R = 0."""
    reg = regularization_weight(reg)
    if reg == 0:
        return None
    l = degrees(lmax_factor).astype(float)
    return sp.diags(np.sqrt(2 * reg) * l * (l + 1)).tocsr()


def smallest_agreeing_basis(model, level: int | None, numeig: int, tol: float, probe) -> int | None:
    """The smallest basis degree Lb' < Lb of ``model`` on which the first ``numeig`` eigenvalues at a reference of
    degree ``level`` agree with those on Lb to ``tol`` (relative), or None if only Lb does: the bisection behind
    :meth:`HarmonicModel.stage_basis`.  ``probe(lb, la)`` gives the model of factor degree la on the basis lb."""
    sub = model.restrict(level)
    la = sub.lmax_factor
    numeig = check_int(numeig, "numeig", minimum=2)
    tol = check_float(tol, "tol", positive=True)
    ref = random_centred_coefficients(0, la, 0.2)
    want = sub.eigenvalues(ref, numeig)[1:]

    def agrees(lb):
        return np.max(np.abs(probe(lb, la).eigenvalues(ref, numeig)[1:] / want - 1.0)) <= tol

    lo, hi = basis_degree_for(numeig, la), model.lmax  # agrees(hi) holds; find the smallest that agrees
    if lo >= hi:
        return None
    if agrees(lo):
        hi = lo
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if agrees(mid):
            hi = mid
        else:
            lo = mid
    return None if hi == model.lmax else hi


def rotation_generators(a: np.ndarray) -> np.ndarray:
    """The three rotation generators applied to the function with flat coefficients ``a`` (n,), as (n, 3): L_z
    exactly, and L_z conjugated by the exact rotations that take z to two other axes."""
    l, m = degree_order(lmax_of_size(a.size))
    partner = np.arange(a.size) - 2 * m  # the index of (l, −m)

    def lz(v):
        return np.where(m > 0, -m * v[partner], 0.0) + np.where(m < 0, -m * v[partner], 0.0)

    out = [lz(a)]
    for angles in ((0.0, np.pi / 2, 0.0), (0.0, np.pi / 2, np.pi / 2)):
        inverse = (-angles[2], -angles[1], -angles[0])
        out.append(rotate_coefficients(lz(rotate_coefficients(a, np.array(inverse))), np.array(angles)))
    return np.stack(out, axis=1)


def block_moves(params: np.ndarray, la: int, *, newest: bool = False) -> list:
    """The power-preserving moves of single degree blocks 2 … ``la`` of flat coefficients (see
    :meth:`HarmonicModel.escape_moves`); ``newest``: the octahedral grid of the block of degree ``la`` alone."""
    l_all = degrees(la)
    blocks = [la] if newest else range(2, la + 1)
    moves = []
    for l in blocks:
        if l < 2:
            continue
        sel = l_all == l
        sub = np.where(sel, params[:l_all.size], 0.0)
        if newest:
            turns = [rotate_coefficients(sub, angles) for angles in _OCTAHEDRAL_EULER[1:]]
            if l % 2:
                turns += [-rotate_coefficients(sub, angles) for angles in _OCTAHEDRAL_EULER]
        else:
            turns = [rotate_coefficients(sub, np.array(ang)) for ang in ((np.pi, 0, 0), (0, np.pi, 0),
                                                                           (np.pi, np.pi, 0))]
            if l % 2:
                turns += [-t for t in turns] + [-sub]
        for turn in turns:
            q = params.copy()
            q[:l_all.size][sel] = turn[sel]
            moves.append(q)
    return moves


def _minimum(params) -> float:
    return ConformalFactor(np.array(params)).minimum().value  # a copy: ConformalFactor freezes its array


def _perturbed(params: np.ndarray, part: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """``params`` with its entries in ``part`` (a mask of the first ``noise.size``) set to ``noise``, halved until
    ρ is certified positive."""
    out = np.array(params, dtype=float)
    for _ in range(30):
        out[:part.size][part] = noise[part]
        # certified as the solves certify it: a start that is positive but cannot be certified would end the fit
        if _certified(out[:part.size]):
            return out
        noise = noise * 0.5
    # a positive ρ stays positive under a small enough change
    return np.asarray(params, dtype=float)  # pragma: no cover


def _certified(params) -> bool:
    """Whether ρ passes the certified positivity check of a solve (:meth:`ConformalFactor.check_positive`)."""
    try:
        ConformalFactor(np.array(params)).check_positive()
    except NotPositiveError:
        return False
    return True


def forward_need(lmax: int, lmax_factor: int, *, with_table: bool = True) -> Need:
    """A forward solve at (Lb, La): table values (if ``with_table``), plan and two dense N × N matrices."""
    n = (lmax + 1) ** 2
    memory = plan_bytes(lmax, lmax_factor) + 2 * 8 * n * n
    if with_table:
        memory += 8 * table_size(lmax, lmax_factor)
    return Need(f"a forward solve at Lb = {lmax}, La = {lmax_factor}", memory)

