"""Before fitting a mesh's spectrum with log ρ in harmonics: the degree La and the number K of eigenvalues that the
target's own errors allow, what error they leave, and where the harmonic basis cannot go.

A fit of ρ = exp(u), u of degree La, to a mesh target misses the mesh's cMCF factors c for two reasons, and both
are measured here before any fit:

* the *floor* f(La): the best degree-La log expansion of c (least squares of log c on the cMCF sphere, area
  weights) misses c by f, whatever the spectrum says (relative area-weighted L2 of c);
* the *noise* e(La, K): the target's eigenvalue errors σ_i (a mesh's discretization error) leave, to first order,
  the error bar of :func:`~shspec.inverse.identifiability.identifiability` at that best expansion, in the relative
  L2 error of ρ (:meth:`LogHarmonicModel.error_root <shspec.galerkin.log_model.LogHarmonicModel.error_root>`).

The floor falls with La and the noise grows with it, so the plan takes the La that minimizes √(f² + e²), and the
smallest candidate K whose √(f² + e²) is within 10 % of the best (each eigenvalue costs basis and time; the last
ones, the least accurate, add little).  The basis Lb is the smallest on which each of those K eigenvalues of the
best expansion agrees with Lb + 2 to a tenth of its own error, so that the basis adds nothing the target's errors
would notice.

The factors c are themselves a discretization (of the mesh's conformal map), and the best expansion's spectrum
misses the target by δ_i, which no fit of degree La need beat: the fit is held to √(σ_i² + δ_i²).  A fit anywhere
within those errors is as good as the target and the basis allow, so the error predicted against c is √(f² + e'²),
e' the error bar of those errors at the chosen (La, K).  On the star of ``benchmarks/bench_surface.py`` the
Richardson-refined eigenvalues have σ/λ of a median 5e-5, while the best expansions of c miss them by 1.5e-3 … 1e-2
(La 11 … 5): the factors, not the spectrum, then set the error against them.

When the predicted error exceeds the accuracy asked for, :meth:`SurfacePlan.diagnosis` says why in one line: the
dynamic range of c, the floor at the largest La that K eigenvalues determine, the La the floor alone would need,
and that the mesh model (:class:`~shspec.mesh.MeshModel`, ``--model mesh``) fits per-vertex factors instead.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..core.checks import check_float
from ..errors import InvalidArgumentError
from ..gaunt.table import MAX_BASIS_DEGREE
from ..galerkin.log_model import LogHarmonicModel, log_expansion
from ..galerkin.truncation import basis_degree_for
from ..mesh.bridge import mesh_band_limit
from ..mesh.cotan import vertex_areas
from .targets import MeshTarget
from ..inverse.identifiability import identifiability_by_numeig

__all__ = ["SurfacePlan", "PlanRow", "log_floor", "plan_surface_fit", "default_numeig", "DEFAULT_ACCURACY",
           "TRUTH_DEGREE"]

#: Relative L2 error of ρ that a mesh target's plan aims for by default.
DEFAULT_ACCURACY = 0.05

#: Degree of the harmonic expansion of a mesh target's cMCF factors that its fits are aligned with (its truth).
TRUTH_DEGREE = 16


def default_numeig(nvertices: int) -> int:
    """K₀ = min(n/4, 300): the eigenvalues a plan starts from on a mesh of n vertices (a 4-to-1 subdivision of it
    still resolves them, and the solves stay seconds)."""
    return max(2, min(nvertices // 4, 300))


#: A candidate K is taken when its predicted error is within this factor of the best candidate's.
_K_SLACK = 1.1

#: The largest La the floor is searched to when it says what La the harmonic basis would need.
_FLOOR_SEARCH = 40


@dataclass(frozen=True)
class PlanRow:
    """One candidate (La, K): its floor, the noise's error bar and the predicted error (relative L2 of ρ)."""

    lmax_factor: int
    numeig: int
    floor: float
    noise: float

    @property
    def predicted(self) -> float:
        return float(np.hypot(self.floor, self.noise))

    def to_dict(self) -> dict:
        return {"lmax_factor": self.lmax_factor, "numeig": self.numeig, "floor": self.floor,
                "noise": None if not np.isfinite(self.noise) else self.noise, "predicted": self.predicted}


@dataclass(frozen=True)
class SurfacePlan:
    """The plan of a log-ρ fit of a mesh target (module notes).

    Attributes
    ----------
    lmax_factor, numeig, lmax : int
        The chosen La, K and basis Lb.
    predicted : float
        Predicted relative L2 error of ρ against the cMCF factors at (La, K): √(floor² + e'²), e' the error bar of
        :attr:`fit_errors` (module notes).
    floor : float
        The floor f(La) alone.
    noise : float
        The error bar of the target's own errors σ alone at (La, K): what the spectrum determines.
    reference_misfit : float
        max_i δ_i / λ_i: how far the best expansion's spectrum is from the target (relative).
    accuracy : float
        The error asked for.
    factor_range : (float, float)
        Smallest and largest cMCF factor.
    floor_degree : int or None
        The smallest La whose floor is below ``accuracy`` (None: none up to 40).
    rows : tuple of PlanRow
        Every candidate analysed.
    reference : (ncoeffs(La),) array
        The best degree-La log expansion of the factors, scaled to the target's area.
    fit_errors : (K,) array
        The errors a fit of degree La should be held to: √(σ_i² + δ_i²), the target's own errors σ_i and the misfit
        δ_i = |λ_i(reference) − λ*_i| of the reference on the basis Lb (the floor seen in the spectrum: no ρ of
        degree La need match the target closer than the best expansion does).

    Examples
    --------
    >>> from shspec.fitting import mesh_target, plan_surface_fit, refined_target
    >>> from shspec.mesh.shapes import star_surface
    >>> plan = plan_surface_fit(refined_target(mesh_target(star_surface(2, 1, 0.3, 1), 10, 30, 4)))
    >>> plan.lmax_factor, plan.numeig, plan.lmax, plan.feasible, plan.diagnosis()
    (2, 7, 5, True, None)
    """

    lmax_factor: int
    numeig: int
    lmax: int
    predicted: float
    floor: float
    noise: float
    reference_misfit: float
    accuracy: float
    factor_range: tuple
    floor_degree: int | None
    rows: tuple
    reference: np.ndarray
    fit_errors: np.ndarray

    @property
    def feasible(self) -> bool:
        """Whether the predicted error is within the accuracy asked for."""
        return self.predicted <= self.accuracy

    @property
    def beyond_basis(self) -> bool:
        """Whether the floor alone, at every La analysed, misses the accuracy: the basis, not the target's errors,
        is what fails (conformal factors spanning decades)."""
        return min(r.floor for r in self.rows) > self.accuracy

    def statement(self) -> str:
        """One sentence for the console."""
        return (f"plan: log rho of degree La = {self.lmax_factor} from K = {self.numeig} eigenvalues on the basis "
                f"Lb = {self.lmax}; predicted error of rho against the cMCF factors {self.predicted:.2g} (floor of "
                f"the degree-{self.lmax_factor} expansion {self.floor:.2g}; the target's errors alone "
                f"{self.noise:.2g}; the expansion's spectrum misses the target by up to {self.reference_misfit:.2g})")

    def diagnosis(self) -> str | None:
        """None when the plan reaches its accuracy; else one line: why not, and what it would take."""
        if self.feasible:
            return None
        heard = float(np.hypot(self.floor, self.noise))
        if not self.beyond_basis and heard > self.accuracy:
            return (f"the target's errors allow rho to about {heard:.2g} only, not {self.accuracy:g}: the "
                    "floor of the basis is below it, the eigenvalues' errors are not; more accurate eigenvalues (a "
                    "finer mesh) would lower it")
        if not self.beyond_basis:
            return (f"the eigenvalues determine rho to about {heard:.2g}, but the best degree-{self.lmax_factor} "
                    f"expansion of the cMCF factors misses their spectrum by up to {self.reference_misfit:.2g} "
                    f"(relative), which leaves about {self.predicted:.2g} between a fit and the factors, not "
                    f"{self.accuracy:g}: the factors' own discretization (a finer mesh) would lower it")
        lo, hi = self.factor_range
        need = (f"the floor alone would need La = {self.floor_degree} ({(self.floor_degree + 1) ** 2} coefficients, "
                f"at least {2 * (self.floor_degree + 1) ** 2} accurate eigenvalues)" if self.floor_degree is not None
                else f"no La up to {_FLOOR_SEARCH} brings the floor below it")
        return (f"the harmonic basis cannot reach {self.accuracy:g}: the cMCF factors span {lo:.2g} ... {hi:.2g} "
                f"({hi / lo:.2g}:1); the best plan (La = {self.lmax_factor}, K = {self.numeig}) predicts "
                f"{self.predicted:.2g}, of which the floor is {self.floor:.2g}; {need}; fit per-vertex factors "
                "instead (--model mesh)")

    def fitted_target(self, target: MeshTarget) -> MeshTarget:
        """``target`` cut to the plan's K, with :attr:`fit_errors` as its errors."""
        return dataclasses.replace(target.first(self.numeig), errors=self.fit_errors)

    def to_dict(self) -> dict:
        """JSON-ready."""
        return {"lmax_factor": self.lmax_factor, "numeig": self.numeig, "lmax": self.lmax,
                "predicted": self.predicted, "floor": self.floor, "noise": self.noise,
                "reference_misfit": self.reference_misfit, "accuracy": self.accuracy,
                "factor_range": list(self.factor_range), "floor_degree": self.floor_degree,
                "feasible": self.feasible, "beyond_basis": self.beyond_basis, "diagnosis": self.diagnosis(),
                "rows": [r.to_dict() for r in self.rows]}


def log_floor(sphere, factors, lmax_factor: int) -> tuple[np.ndarray, float]:
    """The best degree-La log expansion u of per-vertex factors c on a unit-sphere mesh (a cMCF sphere), and
    ‖exp(u) − c‖ / ‖c‖ over its vertices with their areas as weights (:func:`~shspec.galerkin.log_model.log_expansion`).
    """
    return log_expansion(sphere.vertices, vertex_areas(sphere), factors, lmax_factor)


def _floor_degree(sphere, c, accuracy: float) -> int | None:
    """The smallest La ≤ 40 (and ≤ the mesh's band limit) whose floor is below ``accuracy``."""
    top = min(_FLOOR_SEARCH, mesh_band_limit(sphere.nvertices))
    lo, hi = 1, top
    if log_floor(sphere, c, hi)[1] > accuracy:
        return None
    while hi - lo > 1:  # the floor falls with La (nested least squares)
        mid = (lo + hi) // 2
        if log_floor(sphere, c, mid)[1] <= accuracy:
            hi = mid
        else:
            lo = mid
    return hi


def _basis(u: np.ndarray, la: int, tol: np.ndarray) -> tuple[int, np.ndarray]:
    """The smallest Lb >= :func:`basis_degree_for` on which each of the first K eigenvalues of exp(u) agrees with
    Lb + 2 to its own relative tolerance tol (K − 1,), and those K eigenvalues on Lb."""
    numeig = tol.size + 1
    lb = basis_degree_for(numeig, la)
    previous = LogHarmonicModel(lb, la).eigenvalues(u, numeig)
    while lb + 2 <= MAX_BASIS_DEGREE:
        ev = LogHarmonicModel(lb + 2, la).eigenvalues(u, numeig)
        if np.all(np.abs(previous[1:] / ev[1:] - 1) <= tol):
            return lb, previous
        previous, lb = ev, lb + 2
    return lb, previous


def plan_surface_fit(target: MeshTarget, *, accuracy: float = DEFAULT_ACCURACY, candidates=None,
                     numeigs=None) -> SurfacePlan:
    """Plan a log-ρ fit of a mesh target with errors (module notes).

    Parameters
    ----------
    target : MeshTarget
        A mesh target (``target.sphere`` and ``target.factors``: its cMCF) whose ``errors`` are set (e.g.
        :func:`~shspec.fitting.targets.with_discretization_errors`), K₀ eigenvalues.
    accuracy : float
        Relative L2 error of ρ asked for, > 0.
    candidates : sequence of int, optional
        La values to analyse (default 2, 3, … up to the largest with 2 (La + 1)² <= K₀ − 1).
    numeigs : sequence of int, optional
        K values (default K₀/4, K₀/2, 3K₀/4, K₀).

    Returns
    -------
    SurfacePlan

    Raises
    ------
    InvalidArgumentError
        For a target without cMCF factors or errors, or too few eigenvalues for any candidate.

    Examples
    --------
    >>> from shspec.fitting import mesh_target, plan_surface_fit, refined_target
    >>> from shspec.mesh.shapes import star_surface
    >>> target = refined_target(mesh_target(star_surface(2, 1, 0.3, 1), lmax=10, numeig=30, lmax_factor=4))
    >>> plan = plan_surface_fit(target)
    >>> plan.lmax_factor, plan.numeig, round(plan.predicted, 3)
    (2, 7, 0.028)
    >>> plan.fitted_target(target).numeig
    7
    """
    if not isinstance(target, MeshTarget):
        raise InvalidArgumentError(f"plan_surface_fit needs a MeshTarget (a mesh's spectrum with its cMCF factors), "
                                   f"got {type(target).__name__}")
    if target.errors is None:
        raise InvalidArgumentError(f"the target {target.name!r} has no errors: give them (with_discretization_errors "
                                   "or with_noise) before planning by them")
    accuracy = check_float(accuracy, "accuracy", positive=True)
    k0 = target.numeig
    ks = sorted({int(k) for k in (numeigs if numeigs is not None else (k0 // 4, k0 // 2, 3 * k0 // 4, k0))
                 if 2 <= int(k) <= k0})
    top = mesh_band_limit(target.sphere.nvertices, int(np.sqrt((k0 - 1) / 2)) - 1)
    las = sorted({int(la) for la in (candidates if candidates is not None else range(2, top + 1)) if 2 <= la <= top})
    if not ks or not las:
        raise InvalidArgumentError(f"{k0} eigenvalues are too few to plan a fit (K >= 2 and La >= 2 with "
                                   "2 (La + 1)^2 <= K - 1)")
    c = target.factors
    noise = np.r_[1.0, target.errors[1:] / target.eigenvalues[1:]]
    rows, refs = [], {}
    for la in las:
        u, floor = log_floor(target.sphere, c, la)
        refs[la] = u
        model = LogHarmonicModel(basis_degree_for(max(ks), la), la)
        for r in identifiability_by_numeig(model, u, ks, fit_area=True, noise=noise[:max(ks)]):
            rows.append(PlanRow(la, r.numeig, floor, r.noise_error))
    best = min(r.predicted for r in rows)
    pick = min((r for r in rows if r.predicted <= _K_SLACK * best), key=lambda r: (r.numeig, r.predicted))
    u = refs[pick.lmax_factor]
    scaled = u.copy()
    model = LogHarmonicModel(basis_degree_for(pick.numeig, pick.lmax_factor), pick.lmax_factor)
    scaled[0] += np.sqrt(4 * np.pi) * np.log(target.area_estimate() / model.area(u))
    lb, reference_eigenvalues = _basis(scaled, pick.lmax_factor, 0.1 * noise[1:pick.numeig])
    lam = target.eigenvalues[:pick.numeig]
    misfit = reference_eigenvalues - lam
    fit_errors = np.hypot(target.errors[:pick.numeig], misfit)
    fit_errors[0] = 0.0
    bar = identifiability_by_numeig(LogHarmonicModel(lb, pick.lmax_factor), scaled, [pick.numeig], fit_area=True,
                                    noise=np.r_[1.0, fit_errors[1:] / lam[1:]])[0].noise_error
    return SurfacePlan(lmax_factor=pick.lmax_factor, numeig=pick.numeig, lmax=lb,
                       predicted=float(np.hypot(pick.floor, bar)), floor=pick.floor, noise=pick.noise,
                       reference_misfit=float(np.max(np.abs(misfit[1:]) / lam[1:])), accuracy=accuracy,
                       factor_range=(float(c.min()), float(c.max())),
                       floor_degree=_floor_degree(target.sphere, c, accuracy), rows=tuple(rows), reference=scaled,
                       fit_errors=fit_errors)
