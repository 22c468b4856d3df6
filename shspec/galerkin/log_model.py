"""ρ = exp(u), u = Σ_k u_k Y_k up to degree La: a harmonic discretization whose ρ is positive by construction.

A ρ truncated at a low degree goes negative on any shape far from round; exp(u) spans decades with few coefficients
and never does.  The mass matrix is the Gauss–Legendre quadrature of exp(u) on a grid of degree G ≥ 2·Lb,

    M_ij = Σ_g w_g ρ_g Y_i(g) Y_j(g),   ρ_g = exp(u(g)),

assembled from the Gaunt table (Lb, 2·Lb) with a = the GLQ analysis of ρ_g up to degree 2·Lb: Y_i Y_j has degree
≤ 2·Lb, and the grid integrates its products with every Y_k, k ≤ 2·Lb, exactly, so the table assembly equals the
quadrature to rounding.  M is symmetric positive definite for every u (positive weights and values), so no
positivity check is needed and none can end a fit.  The discrete model differs from ∫ exp(u) Y_i Y_j only by the
aliasing of the degrees of exp(u) above 2G + 1 − 2·Lb, which decay faster than geometrically (exp(u) is an entire
function of a band-limited u); the default G = 2·Lb + La leaves it at rounding for the ρ of the tests.

Derivatives of the discrete model, exactly: ∂M_ij/∂u_k = Σ_g w_g ρ_g Y_k(g) Y_i(g) Y_j(g), so for M-orthonormal
eigenfunctions f_i, ∂λ_i/∂u_k = −λ_i Σ_g w_g ρ_g Y_k(g) f_i(g)²: the grid quadratic forms of
:class:`~shspec.galerkin.gridforms.GridQuadraticForms` on the same grid, weighted by ρ_g.

Rotations act on u as on any coefficient vector (they commute with exp), so the gauge, invariant, escape moves and
symmetry directions are those of :class:`~shspec.galerkin.model.HarmonicModel` applied to u; only the Möbius gauge
differs: u_1m = 0 is a slice through the Möbius orbits near the round sphere (a boost changes log ρ by a degree-1
function at first order), not the exact centring a_1m(exp u) = 0, which :func:`~shspec.inverse.align` applies before
any comparison.  The area ∫ exp(u) is not linear in u: it is always fitted, through u_00 (the spectrum's scale is the
best determined of all its features, Weyl's law).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.checks import finite_array
from ..errors import InvalidArgumentError, NotPositiveError
from ..gaunt.table import MAX_BASIS_DEGREE, GauntTable
from ..spectral_model import SpectralModel, Spectrum
from ..sphere.evaluate import harmonic_matrix, sample_harmonic, weighted_expansion, weighted_misfit
from ..sphere.factor import ConformalFactor
from ..sphere.grid import GLQGrid, evaluate_on_grid, expand_grid, glq_grid
from ..sphere.harmonics import check_degree, degrees, ncoeffs
from ..sphere.random import random_coefficients
from ..sphere.rotate import power_spectrum
from ..core.threads import reproducible_call
from .gridforms import GridQuadraticForms
from .model import (HarmonicModel, SpectrumResult, block_moves, laplacian_regularizer, rotation_generators,
                    smallest_agreeing_basis)

__all__ = ["LogHarmonicModel", "LogSpectrumResult", "log_expansion"]

#: The largest |log rho| on the grid that is evaluated; a trial point of the optimizer beyond it is rejected.  A
#: Levenberg-Marquardt step on a near-singular Jacobian proposes such points (log rho 83 on a star target's fit),
#: and a mass whose ρ spans e^±60 is far beyond what double precision resolves.
_MAX_LOG = 60.0


@dataclass(frozen=True)
class LogSpectrumResult(SpectrumResult):
    """A :class:`~shspec.galerkin.model.SpectrumResult` of a :class:`LogHarmonicModel`, with the values of ρ on the
    model's grid (what its derivatives weight the eigenfunctions' squares by).

    Attributes
    ----------
    rho_grid : (G+1, 2G+1) float array
        ρ = exp(u) at the nodes of the model's GLQ grid of degree G.
    """

    rho_grid: np.ndarray | None = field(default=None, repr=False)


class LogHarmonicModel(SpectralModel):
    """The Galerkin discretization of g = exp(u) g₀, u of degree La, on the basis of degree Lb (module notes).

    Parameters are the flat coefficients u (nparams = (La+1)**2) of log ρ.

    Parameters
    ----------
    lmax : int
        Basis band limit Lb.
    lmax_factor : int
        Degree La of u = log ρ.
    grid_degree : int, optional
        Degree G ≥ 2·Lb of the quadrature grid of exp(u) (default 2·Lb + La).
    table : GauntTable, optional
        A table covering (Lb, 2·Lb) (default: from the cache, built there if missing and ``build``).
    cache_dir : path-like, optional
    build : bool

    Raises
    ------
    InvalidArgumentError, BandLimitError, ResourceLimitError
        As :class:`~shspec.galerkin.model.HarmonicModel` for the mass model (Lb, 2·Lb).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import LogHarmonicModel
    >>> model = LogHarmonicModel(12, 4)
    >>> model.eigenvalues(np.zeros(model.nparams), 4).round(8)   # log rho = 0: the unit sphere
    array([0., 2., 2., 2.])
    """

    default_optimizer = "lm"

    def __init__(self, lmax: int, lmax_factor: int, *, grid_degree: int | None = None,
                 table: GauntTable | None = None, cache_dir=None, build: bool = True):
        lmax = check_degree(lmax, "lmax", minimum=1, maximum=MAX_BASIS_DEGREE)
        self.lmax_factor = check_degree(lmax_factor, "lmax_factor (the degree of log rho)")
        self.mass = HarmonicModel(lmax, 2 * lmax, table=table, cache_dir=cache_dir, build=build,
                                  check_positive=False)
        self.lmax = lmax
        self.nparams = ncoeffs(self.lmax_factor)
        self.nbasis = self.mass.nbasis
        degree = 2 * lmax + self.lmax_factor if grid_degree is None else grid_degree
        self.grid: GLQGrid = glq_grid(check_degree(degree, "grid_degree", minimum=2 * lmax))
        self._forms: GridQuadraticForms | None = None
        self._restricted: dict = {}

    def __repr__(self) -> str:
        return f"LogHarmonicModel(lmax={self.lmax}, lmax_factor={self.lmax_factor}, grid_degree={self.grid.lmax})"

    # -- the forward problem -----------------------------------------------------------------------------------------

    def _u(self, params) -> np.ndarray:
        return finite_array(params, f"the coefficients of log rho ({self.nparams}, La = {self.lmax_factor})",
                            (self.nparams,))

    def rho_on_grid(self, params) -> np.ndarray:
        """ρ = exp(u) on the model's grid, (G+1, 2G+1).

        Raises
        ------
        NotPositiveError
            Where u exceeds what exp can hold in double precision (a trial step of an optimizer, rejected).
        """
        values = evaluate_on_grid(self._u(params), self.grid)
        top = float(np.max(np.abs(values)))
        if not top <= _MAX_LOG:
            raise NotPositiveError(f"log rho reaches {top:.3g} in magnitude: a mass of that range is beyond double "
                                   f"precision (|log rho| <= {_MAX_LOG:g})")
        return np.exp(values)

    def mass_coefficients(self, params) -> np.ndarray:
        """The coefficients a (ncoeffs(2·Lb),) of exp(u) whose Gaunt assembly is the mass matrix: the GLQ analysis
        of ρ on the model's grid up to degree 2·Lb."""
        return expand_grid(self.rho_on_grid(params), self.grid, 2 * self.lmax)

    def mass_matrix(self, params) -> np.ndarray:
        """The full symmetric mass matrix M(u), (N, N)."""
        return self.mass.mass_matrix(self.mass_coefficients(params))

    @reproducible_call
    def spectrum(self, params, k: int, *, start: Spectrum | None = None) -> LogSpectrumResult:
        """First k eigenpairs (λ₀ = 0 included) for the coefficients u of log ρ; ``start`` as for
        :meth:`HarmonicModel.spectrum <shspec.galerkin.model.HarmonicModel.spectrum>`."""
        rho = self.rho_on_grid(params)
        a = expand_grid(rho, self.grid, 2 * self.lmax)
        spec = self.mass.spectrum(a, k, start=start)
        return LogSpectrumResult(**{f: getattr(spec, f) for f in spec.__dataclass_fields__}, rho_grid=rho)

    @reproducible_call
    def eigenvalues(self, params, k: int) -> np.ndarray:
        return self.mass.eigenvalues(self.mass_coefficients(params), k)

    @property
    def forms(self) -> GridQuadraticForms:
        """The ρ-weighted quadratic forms on the model's grid (built on first use)."""
        if self._forms is None:
            self._forms = GridQuadraticForms(self.lmax, self.lmax_factor, grid_degree=self.grid.lmax)
        return self._forms

    def _spectrum_of_mine(self, spec) -> LogSpectrumResult:
        if not isinstance(spec, LogSpectrumResult) or spec.rho_grid is None \
                or spec.rho_grid.shape != self.grid.weights.shape:
            raise InvalidArgumentError(f"expected the spectrum of a solve of this model (model.spectrum(...)), got "
                                       f"{type(spec).__name__}")
        return spec

    @reproducible_call
    def jacobian(self, spec: Spectrum) -> np.ndarray:
        """∂λ_i/∂u_k = −λ_i Σ_g w_g ρ_g Y_k f_i² (module notes), as a (k, nparams) array."""
        spec = self._spectrum_of_mine(spec)
        q = self.forms(spec.eigenvectors, spec.rho_grid)
        return -(q * spec.eigenvalues[None, :]).T

    @reproducible_call
    def contract(self, spec: Spectrum, coef: np.ndarray) -> np.ndarray:
        """Σ_i c_i ∂λ_i/∂u, (nparams,), in one weighted quadrature."""
        spec = self._spectrum_of_mine(spec)
        coef = np.asarray(coef, dtype=float)
        if coef.shape != spec.eigenvalues.shape:
            raise InvalidArgumentError(f"coef must have shape {spec.eigenvalues.shape}, got {coef.shape}")
        return -self.forms.weighted(spec.eigenvectors, coef * spec.eigenvalues, spec.rho_grid)

    # -- what the inverse solver asks of a model (shspec.spectral_model.SpectralModel) ---------------------------

    def describe(self) -> str:
        return f"log-harmonic Lb={self.lmax} La={self.lmax_factor} G={self.grid.lmax}"

    def scaled(self, params: np.ndarray, factor: float) -> np.ndarray:
        """u with log(factor) added to log ρ: to u_00, times √(4π) (Y_00 = 1/√(4π))."""
        out = np.array(params, dtype=float)
        out[0] += np.log(factor) * np.sqrt(4.0 * np.pi)
        return out

    def free_parameters(self, fit_area: bool) -> np.ndarray:
        """Every u_lm but the gauge u_1m = 0; u_00 always (the area ∫ exp(u) is not linear in u: module notes)."""
        return np.flatnonzero(degrees(self.lmax_factor) != 1)

    def area(self, params) -> float:
        """∫ exp(u) dΩ by the model's quadrature."""
        return float(np.sum(self.grid.weights * self.rho_on_grid(params)))

    def random_start(self, rng: np.random.Generator, amplitude: float, area: float, level: int | None = None,
                     ) -> np.ndarray:
        """u_1m = 0, degrees 2 … level random with RMS ∝ amplitude/l (odd ones included: the parity saddle), and
        u_00 so that ∫ exp(u) = ``area``."""
        la = self.lmax_factor if level is None else self.restrict(level).lmax_factor
        u = np.zeros(self.nparams)
        u[:ncoeffs(la)] = random_coefficients(rng, la, amplitude * np.sqrt(4 * np.pi))
        return self._with_area(u, area)

    def _with_area(self, u: np.ndarray, area: float) -> np.ndarray:
        """u with u_00 shifted so that ∫ exp(u) = area (a constant c added to u scales ρ by e^c)."""
        if not (np.isfinite(area) and area > 0):
            raise InvalidArgumentError(f"the area must be finite and > 0, got {area!r}")
        out = np.array(u, dtype=float)
        out[0] += np.sqrt(4 * np.pi) * np.log(area / self.area(out))
        return out

    def regularizer(self, reg: float):
        """D = √(2R) diag(l(l+1)), so that ½‖Du‖² = R‖Δ log ρ‖²."""
        return laplacian_regularizer(reg, self.lmax_factor)

    def levels(self) -> tuple[int, ...]:
        """The degrees 2 … La of u (degree 1 is the gauge)."""
        return tuple(range(2, self.lmax_factor + 1))

    def restrict(self, level: int | None, basis: int | None = None) -> "LogHarmonicModel":
        """The model of log-degree ``level`` ≤ La on the basis of degree ``basis`` ≤ Lb, sharing the table."""
        la = self.lmax_factor if level is None else check_degree(level, "level (degree of log rho)",
                                                                 maximum=self.lmax_factor)
        lb = self.lmax if basis is None else check_degree(basis, "basis degree", minimum=1, maximum=self.lmax)
        if (la, lb) == (self.lmax_factor, self.lmax):
            return self
        if (la, lb) not in self._restricted:
            self._restricted[(la, lb)] = LogHarmonicModel(lb, la, table=self.mass.table)
        return self._restricted[(la, lb)]

    solve_cost = HarmonicModel.solve_cost

    def stage_basis(self, level: int | None, numeig: int, tol: float) -> int | None:
        """As :meth:`HarmonicModel.stage_basis <shspec.galerkin.model.HarmonicModel.stage_basis>`, for exp(u)."""
        return smallest_agreeing_basis(
            self, level, numeig, tol,
            lambda lb, la: LogHarmonicModel(lb, la, table=self.mass.table.restrict(lb, 2 * lb, keep=False)))

    def enter_level(self, params: np.ndarray, old: int | None, new: int | None, rng: np.random.Generator,
                    amplitude: float) -> np.ndarray:
        """The degrees old+1 … new of u get a small random perturbation (RMS ∝ amplitude/l): the parity saddle."""
        old = self.lmax_factor if old is None else old
        new = self.lmax_factor if new is None else new
        if new <= old:
            return params
        out = np.array(params, dtype=float)
        noise = random_coefficients(rng, new, amplitude * np.sqrt(4 * np.pi), low=old + 1)
        out[ncoeffs(old):ncoeffs(new)] = noise[ncoeffs(old):]
        return out

    #: The u_lm of odd degree l ≥ 3, as the a_lm of :class:`HarmonicModel`: held at 0, ρ = exp(u) is even.
    odd_parameters = HarmonicModel.odd_parameters

    def release_odd(self, params: np.ndarray, level: int | None, rng: np.random.Generator,
                    amplitude: float) -> np.ndarray:
        """The odd degrees 3 … ``level`` of u get a small random perturbation (RMS ∝ amplitude/l)."""
        odd = self.restrict(level).odd_parameters()
        out = np.array(params, dtype=float)
        out[odd] = random_coefficients(rng, self.restrict(level).lmax_factor, amplitude * np.sqrt(4 * np.pi),
                                       low=3)[odd]
        return out

    def invariant(self, params: np.ndarray, level: int | None = None) -> np.ndarray:
        """Per-degree power Σ_m u_lm² (La+1,): invariant under O(3), as rotations commute with exp."""
        return power_spectrum(np.asarray(params, dtype=float))

    def symmetry_directions(self, params: np.ndarray) -> np.ndarray:
        """The three rotation generators applied to u, (nparams, 3)."""
        return rotation_generators(self._u(params))

    def escape_moves(self, params: np.ndarray, level: int | None = None, *, newest: bool = False) -> list:
        """The power-preserving moves of single degree blocks of u (see :meth:`HarmonicModel.escape_moves
        <shspec.galerkin.model.HarmonicModel.escape_moves>`)."""
        la = self.lmax_factor if level is None else self.restrict(level).lmax_factor
        return block_moves(np.asarray(params, dtype=float), la, newest=newest)

    def approximation(self, points, weights, values) -> tuple[np.ndarray, float]:
        """:func:`log_expansion` to degree La."""
        return log_expansion(points, weights, values, self.lmax_factor)

    def error_root(self, params: np.ndarray) -> np.ndarray:
        """R (nparams, nparams): δρ = ρ δu, so ‖δρ‖² / ‖ρ‖² = δuᵀ Q δu with Q_kl = ∫ ρ² Y_k Y_l / ∫ ρ², here by the
        model's quadrature and returned as the triangular root of Q (QR of the weighted harmonics at the nodes)."""
        rho = self.rho_on_grid(params)
        weight = self.grid.weights * rho ** 2
        y = harmonic_matrix(self.grid.unit_vectors().reshape(-1, 3), self.lmax_factor)
        return np.linalg.qr(np.sqrt(weight.ravel() / weight.sum())[:, None] * y, mode="r")

    def to_factor(self, params: np.ndarray) -> ConformalFactor:
        """ρ = exp(u) expanded to degree 2·Lb, all the degrees the spectrum sees (for alignment and plots)."""
        return ConformalFactor(self.mass_coefficients(params), name="fit (exp of log rho)")


def log_expansion(points, weights, values, lmax_factor: int) -> tuple[np.ndarray, float]:
    """u, the weighted least-squares expansion of log ρ to degree La, and ‖exp(u) − ρ‖_w / ‖ρ‖_w at the points.

    Parameters
    ----------
    points : (n, 3) array
        Points of the unit sphere (their directions).
    weights : (n,) array
        Quadrature weights > 0 (e.g. lumped vertex areas of a sphere mesh).
    values : (n,) array
        ρ > 0 at the points.
    lmax_factor : int
        La.

    Raises
    ------
    NotPositiveError
        If a value is <= 0.
    """
    rho = np.asarray(values, dtype=float)
    if not np.all(rho > 0):
        raise NotPositiveError("rho must be > 0 at every point to be expanded in log rho")
    u, _ = weighted_expansion(points, weights, np.log(rho), lmax_factor)
    fitted = np.exp(sample_harmonic(u, points))  # no second (n, (La + 1)²) matrix
    return u, weighted_misfit(rho, fitted, np.asarray(weights, dtype=float))
