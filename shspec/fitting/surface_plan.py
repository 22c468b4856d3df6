"""Before fitting a mesh's spectrum with log ρ in harmonics: the degree La and the number K of eigenvalues that the
target's own errors allow, what error they leave, and where the harmonic basis cannot go.

A fit of ρ = exp(u), u of degree La, to a mesh target misses the mesh's cMCF factors c for two reasons, and both
are measured here before any fit:

* the *floor* f(La): the best degree-La log expansion of c (least squares of log c on the cMCF sphere, area
  weights) misses c by f, whatever the spectrum says (relative area-weighted L2 of c);
* the *noise* e(La, K): the target's eigenvalue errors σ_i (a mesh's discretization error) leave, to first order,
  the error bar of :func:`~shspec.inverse.identifiability.identifiability` at that best expansion, in the relative
  L2 error of ρ (:meth:`LogHarmonicModel.error_root <shspec.galerkin.log_model.LogHarmonicModel.error_root>`).

Each La is given the fewest candidate K with :data:`~shspec.fitting.numeig_plan.SEARCH_NUMEIG_FACTOR` (2.5)
eigenvalues per coefficient, the count at which harmonic searches were measured to succeed (all of K₀ if fewer).
The basis Lb is the smallest on which each of those K eigenvalues of the best expansion agrees with Lb + 2 to a tenth
of its own error, so that the basis adds nothing the target's errors would notice.

The factors c are themselves a discretization (of the mesh's conformal map), and the best expansion's spectrum
misses the target by δ_i, which no fit of degree La need beat.  On the star of ``benchmarks/bench_surface.py`` the
Richardson-refined eigenvalues have σ/λ of a median 5e-5, while the best expansions of c miss them by 1.5e-3 … 1e-2
(La 11 … 5): the factors, not the spectrum, then set the error against them, and it stops falling with La.

So the floor falls with La and the noise grows with it: the plan finds the La whose √(f² + e²) is the lowest,
predicts its error with the misfit, √(f² + e'²), e' the error bar of √(σ_i² + δ_i²) at (La, K), and takes the
smallest La whose prediction with the misfit is within 10 % of that.  On a 10k-vertex star of factors 0.70 … 3.0
(``bench_surface``'s ``stars-a``) the lowest √(f² + e²) is at La 9 (0.0049), but with the misfit La 9 predicts
0.022 and La 7 0.021: La 7 and K 225 (64 coefficients) hear as much as La 9 and K 300 (100), in a search that is
far easier.

The least-squares expansion of log c is not the best fit of the spectrum near c: polished against the target's
eigenvalues (a local fit from it, :func:`~shspec.inverse.fit`), the reference of that star at La 7 goes from
χ²/(K − 1) 0.88 to 0.16 in the errors √(σ_i² + δ_i²).  Held to those errors, searches from random starts stopped in
other basins at χ²/(K − 1) 0.94 … 1.26, 6 … 9 % from c, and called it a success.  So the plan polishes the chosen
reference (``polish``), holds the fit to √(σ_i² + δ'_i²) with δ' the misfit of the polished reference, and predicts
√(max(f, b)² + e'²), b the polished reference's own error against c (the *bias*: a fit of the spectrum, not of c).
On that star: b 0.032, and a search from random starts held to those errors reached 0.039 from c.

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
from ..inverse.align import align
from ..inverse.identifiability import identifiability_by_numeig
from ..inverse.multistart import fit
from ..inverse.options import FitOptions
from ..mesh.bridge import mesh_band_limit
from ..mesh.cotan import vertex_areas
from ..sphere.evaluate import sample_harmonic, weighted_misfit
from .numeig_plan import SEARCH_NUMEIG_FACTOR
from .targets import MeshTarget

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


#: A candidate of fewer coefficients is taken when its predicted error is within this factor of the best one.
_SLACK = 1.1

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
        Predicted relative L2 error of ρ against the cMCF factors at (La, K): √(max(floor, bias)² + e'²), e' the
        error bar of :attr:`fit_errors` (module notes).
    floor : float
        The floor f(La) alone.
    noise : float
        The error bar of the target's own errors σ alone at (La, K): what the spectrum determines.
    bias : float or None
        How far the polished reference is from the factors (relative L2 over the cMCF sphere's vertices, area
        weights): the error a fit of this degree in the factors' own basin keeps, against them; None unpolished or
        for a target without a truth to align with.
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
        The best degree-La log expansion of the factors, scaled to the target's area, polished against the target's
        spectrum (unless ``polish`` was False).
    fit_errors : (K,) array
        The errors a fit of degree La should be held to: √(σ_i² + δ_i²), the target's own errors σ_i and the misfit
        δ_i = |λ_i(reference) − λ*_i| of the reference on the basis Lb (the floor seen in the spectrum: no ρ of
        degree La need match the target closer than the reference does).
    best_predicted : float
        The predicted error of the candidate whose error bar without the misfit is the lowest; :attr:`predicted`
        is within 10 % of it, at fewer coefficients where it can be.

    Examples
    --------
    >>> from shspec.fitting import mesh_target, plan_surface_fit, refined_target
    >>> from shspec.mesh.shapes import star_surface
    >>> plan = plan_surface_fit(refined_target(mesh_target(star_surface(2, 1, 0.3, 1), 10, 30, 4)))
    >>> plan.lmax_factor, plan.numeig, plan.lmax, plan.feasible   # 42 vertices: 5 % is beyond its discretization
    (2, 30, 6, False)
    """

    lmax_factor: int
    numeig: int
    lmax: int
    predicted: float
    floor: float
    noise: float
    bias: float | None
    reference_misfit: float
    accuracy: float
    factor_range: tuple
    floor_degree: int | None
    rows: tuple
    reference: np.ndarray
    fit_errors: np.ndarray
    best_predicted: float

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
                f"{self.noise:.2g}; the expansion's spectrum misses the target by up to {self.reference_misfit:.2g}"
                + ("" if self.bias is None else f"; polished against the spectrum, it is {self.bias:.2g} from the "
                   "factors") + ")")

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
                "predicted": self.predicted, "floor": self.floor, "noise": self.noise, "bias": self.bias,
                "reference_misfit": self.reference_misfit, "accuracy": self.accuracy,
                "factor_range": list(self.factor_range), "floor_degree": self.floor_degree,
                "best_predicted": self.best_predicted,
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
                     numeigs=None, polish: bool = True) -> SurfacePlan:
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
    polish : bool
        Polish the chosen best expansion against the target's spectrum, and hold the fit to its misfit (module
        notes; a local fit, seconds to a minute), unless the floor misses ``accuracy`` at every La (beyond the
        basis).  False: the best expansion's own misfit, looser.

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
    (2, 30, 0.076)
    >>> plan.fitted_target(target).numeig
    30
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
    pick, best = _choose(target, rows, refs, noise)
    if polish and min(r.floor for r in rows) <= accuracy:  # a plan beyond the basis is refused: no polish needed
        pick = _polished(target, pick)
    return SurfacePlan(lmax_factor=pick.row.lmax_factor, numeig=pick.row.numeig, lmax=pick.lmax,
                       predicted=pick.predicted, floor=pick.row.floor, noise=pick.row.noise, bias=pick.bias,
                       reference_misfit=pick.reference_misfit, accuracy=accuracy,
                       factor_range=(float(c.min()), float(c.max())),
                       floor_degree=_floor_degree(target.sphere, c, accuracy), rows=tuple(rows),
                       reference=pick.reference, fit_errors=pick.fit_errors, best_predicted=best.predicted)


def _choose(target: MeshTarget, rows: list, refs: dict, noise: np.ndarray) -> tuple:
    """(the chosen candidate, the best one): the fewest coefficients whose prediction with the misfit is within
    :data:`_SLACK` of that of the La whose error bar without it is the lowest (module notes)."""
    searched = [row for row in (_search_row(rows, la) for la in sorted(refs)) if row is not None]
    first = min(searched, key=lambda r: r.predicted)
    best = _misfit_included(target, first, refs[first.lmax_factor], noise)
    for row in searched:  # by La ascending
        if row.lmax_factor >= first.lmax_factor:
            break
        if row.predicted <= _SLACK * best.predicted:  # the row's error is a lower bound of its own with the misfit
            cheaper = _misfit_included(target, row, refs[row.lmax_factor], noise)
            if cheaper.predicted <= _SLACK * best.predicted:
                return cheaper, best
    return best, best


def _search_row(rows, la: int) -> PlanRow | None:
    """The candidate of degree La that a search is given: the fewest eigenvalues at :data:`SEARCH_NUMEIG_FACTOR`
    per coefficient (the most there are, if fewer), among those with a finite error bar (the most eigenvalues when
    none has one: an error bar of infinity)."""
    own = [r for r in rows if r.lmax_factor == la]
    finite = [r for r in own if np.isfinite(r.predicted)]
    if not finite:
        return max(own, key=lambda r: r.numeig) if own else None
    enough = [r for r in finite if r.numeig >= SEARCH_NUMEIG_FACTOR * (la + 1) ** 2]
    return min(enough, key=lambda r: r.numeig) if enough else max(finite, key=lambda r: r.numeig)


@dataclass(frozen=True)
class _Candidate:
    """A candidate (La, K) with the best expansion's own spectral misfit included (module notes)."""

    row: PlanRow
    lmax: int
    reference: np.ndarray
    fit_errors: np.ndarray
    reference_misfit: float
    predicted: float
    bias: float | None = None


def _misfit_included(target: MeshTarget, row: PlanRow, u: np.ndarray, noise: np.ndarray) -> _Candidate:
    """The basis, errors and predicted error of a fit of ``row``'s (La, K) held to the target's errors and the
    misfit of the best degree-La expansion ``u`` of the factors (scaled to the target's area)."""
    la, k = row.lmax_factor, row.numeig
    scaled = u.copy()
    model = LogHarmonicModel(basis_degree_for(k, la), la)
    scaled[0] += np.sqrt(4 * np.pi) * np.log(target.area_estimate() / model.area(u))
    lb, reference_eigenvalues = _basis(scaled, la, 0.1 * noise[1:k])
    fit_errors, misfit, bar = _held_to(target, LogHarmonicModel(lb, la), scaled, reference_eigenvalues)
    return _Candidate(row=row, lmax=lb, reference=scaled, fit_errors=fit_errors, reference_misfit=misfit,
                      predicted=float(np.hypot(row.floor, bar)))


def _held_to(target: MeshTarget, model: LogHarmonicModel, u: np.ndarray, eigenvalues: np.ndarray) -> tuple:
    """(the errors (K,) a fit is held to with the misfit of a reference ``u`` whose K eigenvalues are
    ``eigenvalues``, its largest relative misfit, the error bar of those errors at ``u``)."""
    k = eigenvalues.size
    lam = target.eigenvalues[:k]
    misfit = eigenvalues - lam
    fit_errors = np.hypot(target.errors[:k], misfit)
    fit_errors[0] = 0.0
    bar = identifiability_by_numeig(model, u, [k], fit_area=True,
                                    noise=np.r_[1.0, fit_errors[1:] / lam[1:]])[0].noise_error
    return fit_errors, float(np.max(np.abs(misfit[1:]) / lam[1:])), bar


#: Iterations of the polish of the chosen reference against the target's spectrum.
_POLISH_ITER = 200


def _polished(target: MeshTarget, cand: _Candidate) -> _Candidate:
    """``cand`` with its reference polished against the target's spectrum (module notes): the fit's errors from the
    polished reference's misfit, its error against the factors as the bias, and the prediction from both."""
    la, k = cand.row.lmax_factor, cand.row.numeig
    model = LogHarmonicModel(cand.lmax, la)
    held = dataclasses.replace(target.first(k), errors=cand.fit_errors)
    best = fit(held, model, FitOptions(starts=1, schedule=None, basin_hops=0, max_iter=_POLISH_ITER, progress=False),
               init=cand.reference).best
    fit_errors, misfit, bar = _held_to(target, model, best.params, best.eigenvalues)
    bias = None
    if target.truth is not None:
        # the fit's gauge moves rho by a Moebius map: compare as the fit's own surface record does, after alignment
        aligned = align(model.to_factor(best.params), target.truth)
        sphere = target.sphere
        bias = float(weighted_misfit(target.factors, sample_harmonic(aligned.aligned, sphere.vertices),
                                     vertex_areas(sphere)))
    return _Candidate(row=cand.row, lmax=cand.lmax, reference=best.params, fit_errors=fit_errors,
                      reference_misfit=misfit, predicted=float(np.hypot(max(cand.row.floor, bias or 0.0), bar)),
                      bias=bias)
