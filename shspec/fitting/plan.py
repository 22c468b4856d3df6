"""Plan a fit from what a user has: :func:`prepare_fit` turns a :class:`~shspec.fitting.request.FitRequest` into a
:class:`FitPlan`, which :func:`shspec.inverse.fit` runs as ``fit(plan)``.  ``shspec fit`` is this call.

What is planned, and why:

* the model: log ρ for a mesh (its factors span decades), ρ's coefficients otherwise;
* a mesh's spectrum with a log model (La and K not given): the target is the mesh's eigenvalues refined on its
  4-to-1 subdivisions with their discretization errors, and La, K and Lb are those of
  :func:`~shspec.fitting.surface_plan.plan_surface_fit`, which predicts the error of ρ against the mesh's cMCF
  factors and says when no harmonic basis can reach them;
* a harmonic ρ of degree La (K not given): K and Lb of :func:`~shspec.fitting.numeig_plan.plan_fit` (2.5
  eigenvalues per coefficient, a basis on which the truth itself succeeds); a spectrum with fewer eigenvalues is
  refused before any fit (:class:`~shspec.errors.ShortSpectrumError`) with the degree those support
  (``lmax_factor="auto"`` fits it), unless ``allow_short_spectrum`` asks to fit the degree asked anyway;
* a mesh fit (per-vertex factors): 95 % of the vertices in eigenvalues up to 1500 vertices, else those the mesh
  resolves (``numeig="auto"``), and the study's penalty R = 0.05;
* a target with errors (noise, a spectrum file's error column, a mesh's discretization): the error those errors
  leave on ρ, before fitting.
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass, field

import numpy as np

from ..errors import BeyondBasisError, InvalidArgumentError, ShortSpectrumError
from ..galerkin.log_model import LogHarmonicModel
from ..galerkin.model import HarmonicModel
from ..inverse.identifiability import identifiability
from ..inverse.options import FitOptions
from ..inverse.prepared import PreparedFit
from ..inverse.schedule import (DEFAULT_STAGE_MAX_ITER, default_hop_degree, degree_ramp, numeig_ramp,
                                parity_ramp, parse_schedule)
from ..inverse.target import Target
from ..mesh.model import MeshModel
from ..mesh.progress import announce, mesh_progress
from ..mesh.refine import eigenvalue_errors, trusted_numeig
from ..mesh.triangle_mesh import TriangleMesh
from ..core.parallel import make_executor, stop_executor, usable_cores
from ..spectral.topology import check_genus_zero
from ..spectrum_file import read_spectrum, read_spectrum_file
from ..sphere.factor import ConformalFactor
from ..sphere.random import random_centred_coefficients
from .adaptive import adaptive_fit
from .expected import Measured, expectation
from .initial import initial_parameters, read_initial, read_truth
from .numeig_plan import SEARCH_NUMEIG_FACTOR, NumeigPlan, plan_fit, search_numeig, supported_degree
from .request import FitRequest
from .surface_plan import TRUTH_DEGREE, SurfacePlan, default_numeig, plan_surface_fit
from .targets import (MeshTarget, harmonic_target, mesh_target, parse_target, refined_target, subdivision_changes,
                      subdivision_spectra)

__all__ = ["FitPlan", "Choice", "prepare_fit", "DEFAULT_LMAX_FACTOR", "MESH_REG", "MESH_NUMEIG_FRACTION",
           "MESH_FRACTION_VERTICES"]

#: La of a fit that is not planned by a surface plan and gives none.
DEFAULT_LMAX_FACTOR = 15

#: Basis degree Lb of a fit whose K is given.
DEFAULT_LMAX = 30

#: Default K of a mesh fit: this share of the vertices (the study's "e0.95": 570 of 600, 1140 of 1200) on meshes of
#: at most MESH_FRACTION_VERTICES vertices, and ``numeig="auto"`` on larger ones.
MESH_NUMEIG_FRACTION = 0.95
MESH_FRACTION_VERTICES = 1500

#: Default R of a mesh fit: the study's regularized fit (Section 3.2.2, cotan-squared penalty).
MESH_REG = 0.05


@dataclass(frozen=True)
class Choice:
    """One planned setting: its name, value and why.

    Examples
    --------
    >>> from shspec.fitting import prepare_fit
    >>> plan = prepare_fit("blob", lmax_factor=6, lmax=12, numeig=40, progress=False)
    >>> plan.choice("numeig")
    Choice(name='numeig', value=40, reason='as asked')
    """

    name: str
    value: object
    reason: str

    def to_dict(self) -> dict:
        return {"value": self.value, "reason": self.reason}


@dataclass(frozen=True)
class FitPlan(PreparedFit):
    """A fit planned by :func:`prepare_fit`, ready for ``fit(plan)``.

    Attributes
    ----------
    target : Target
        What is fitted, with its errors, cut to the planned K.
    model : SpectralModel
    options : FitOptions
        With the planned penalty and schedule.
    init : (model.nparams,) array or None
    choices : tuple of Choice
        The model, La, K, Lb and R, each with its reason.
    notes : tuple of str
        What the planning found on the way (a target's refinement, warnings).
    expected_error : float or None
        The relative L2 error of ρ that the target's errors leave (None: the target is taken as exact).
    surface_plan : SurfacePlan or None
        A mesh's plan: La, K, Lb, the predicted error against its cMCF factors, or why the basis cannot reach
        them.
    numeig_plan : NumeigPlan or None
        The plan of K and Lb of a harmonic ρ.
    numeig_auto : dict or None
        The report of ``numeig="auto"``.
    adaptive : AdaptiveOptions or None
        An adaptive mesh fit's options (run by :func:`~shspec.fitting.adaptive_fit`).
    workers : int or None
        Processes of the starts' pool (1: serial).
    scheduler : str or None
        A Dask scheduler's address.

    Examples
    --------
    >>> from shspec.fitting import prepare_fit
    >>> from shspec.inverse import fit
    >>> plan = prepare_fit("blob", lmax_factor=6, lmax=12, numeig=40, workers=1, progress=False)
    >>> plan.model.describe(), plan.target.numeig
    ('harmonic Lb=12 La=6', 40)
    >>> print(plan.statement().splitlines()[0])
    fitting blob: 40 eigenvalues, harmonic Lb=12 La=6, 4 starts
    """

    choices: tuple = ()
    notes: tuple = ()
    expected_error: float | None = None
    surface_plan: SurfacePlan | None = field(default=None, repr=False)
    numeig_plan: NumeigPlan | None = field(default=None, repr=False)
    numeig_auto: dict | None = field(default=None, repr=False)
    adaptive: object = None
    workers: int | None = None
    scheduler: str | None = None
    expectation: tuple = field(default=(None, None), repr=False)

    def choice(self, name: str) -> Choice:
        """The choice of that name ("model", "lmax_factor", "numeig", "lmax", "reg")."""
        for c in self.choices:
            if c.name == name:
                return c
        raise InvalidArgumentError(f"no choice {name!r}; the plan has {[c.name for c in self.choices]}")

    def statement(self) -> str:
        """What the fit will do and why, a line each, for the console."""
        on = ("" if self.adaptive is not None or (self.workers, self.scheduler) == (1, None)
              else " on a Dask cluster" if self.scheduler else f" on {self.workers} processes")
        lines = [f"fitting {self.target.name}: {self.target.numeig} eigenvalues, {self.model.describe()}, "
                 f"{self.options.starts} starts{on}"]
        lines += [f"  {c.name} = {c.value}: {c.reason}" for c in self.choices]
        lines += [f"  {note}" for note in self.notes]
        if self.expected_error is not None:
            lines.append(f"  before fitting: the target's errors allow rho to about {self.expected_error:.2g} "
                         "(expected relative L2 error at a random start of the fit's law)")
        if self.expectation[1] is not None:
            lines.append(f"  {self.expectation[1]}")
        return "\n".join(lines)

    def record(self) -> dict:
        """What the plan adds to the fit's summary, JSON-ready."""
        out = {"plan": {c.name: c.to_dict() for c in self.choices}}
        if self.notes:
            out["plan"]["notes"] = list(self.notes)
        if self.numeig_plan is not None:
            out["numeig_plan"] = self.numeig_plan.to_dict()
        if self.surface_plan is not None:
            out["surface_plan"] = self.surface_plan.to_dict()
        if self.expected_error is not None:
            out["expected_error"] = self.expected_error
        if self.numeig_auto is not None:
            out["numeig_auto"] = self.numeig_auto
        measured, said = self.expectation
        if said is not None:
            out["expectation"] = {"measured": None if measured is None else dataclasses.asdict(measured), "said": said}
        return out

    def run(self, fit_target, *, resume: bool = False, executor=None):
        """Run the plan (``fit(plan)``): on ``executor`` if given, else on the plan's workers or scheduler; an
        adaptive plan refines its mesh stage by stage.  The result carries :meth:`record`."""
        if self.options.progress:
            print(self.statement(), file=sys.stderr)
        record = self.record()
        if self.adaptive is not None:
            if resume or executor is not None:
                raise InvalidArgumentError("an adaptive fit neither resumes nor runs on an executor")
            adaptive = adaptive_fit(self.target, dataclasses.replace(self.adaptive, fit=self.options),
                                    log=(lambda msg: print(msg, file=sys.stderr)) if self.options.progress else None)
            return dataclasses.replace(adaptive.result, plan={**record, "adaptive": adaptive.to_dict()})
        own = executor is None
        executor = make_executor(self.workers, self.scheduler) if own else executor
        try:
            result = fit_target(self.target, self.model, self.options, resume=resume, init=self.init,
                                executor=executor)
        finally:
            if own:
                stop_executor(executor)  # the starts a success made unneeded may still run: not waited for
        return dataclasses.replace(result, plan=record)


@dataclass
class _Planning:
    """The plan as it is made: the request, and what each step has settled."""

    request: FitRequest
    kind: str
    lmax_factor: int | None = None
    lmax: int | None = None
    numeig: int | None = None
    choices: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    surface_plan: SurfacePlan | None = None
    numeig_plan: NumeigPlan | None = None
    numeig_auto: dict | None = None
    target: Target | None = None

    def choose(self, name: str, value, reason: str):
        self.choices.append(Choice(name, value, reason))
        return value

    def say(self, text: str) -> None:
        self.notes.append(text)


def prepare_fit(target, **fields) -> FitPlan:
    """Plan a fit of ``target`` (module notes): the target with its errors, the model, the options, and the
    reasons for each choice.

    Parameters
    ----------
    target : FitRequest, or what :attr:`FitRequest.target` takes
        A request, or its target (a string such as ``"mesh:spot_600"``, a mesh, a ρ, a Target, eigenvalues).
    **fields
        The other fields of :class:`~shspec.fitting.request.FitRequest` (not with a request).

    Returns
    -------
    FitPlan
        Run it with ``shspec.inverse.fit(plan)``.

    Raises
    ------
    InvalidArgumentError
        For a request that cannot be planned (it names the field).
    BeyondBasisError
        Where the harmonic basis cannot reach a mesh's factors: the diagnosis says why and what would.

    Examples
    --------
    Hear a shipped mesh, as ``shspec fit --target mesh:spot_600`` does (a minute on two cores):

    >>> from shspec.fitting import prepare_fit
    >>> from shspec.inverse import fit
    >>> plan = prepare_fit("mesh:spot_600")      # doctest: +SKIP
    >>> result = fit(plan)                        # doctest: +SKIP

    A harmonic ρ's spectrum, K and Lb planned:

    >>> plan = prepare_fit("blob", lmax_factor=6, progress=False)
    >>> plan.choice("numeig").value, plan.choice("lmax").value
    (122, 29)
    """
    if isinstance(target, FitRequest):
        if fields:
            raise InvalidArgumentError(f"give a FitRequest or its fields, not both ({', '.join(fields)})")
        request = target
    else:
        request = FitRequest(target, **fields)
    _check_noise(request)
    kind = request.model or ("log" if request.is_mesh else "harmonic")
    p = _Planning(request, kind)
    p.choose("model", kind, "as asked" if request.model else
             "a mesh's factors may span decades; rho = exp(u) stays positive" if kind == "log" else "the default")
    with mesh_progress(request.progress):
        if _surface_planned(request, kind):
            _plan_surface(p)
        else:
            _plan_degrees(p)
            p.target = _build_target(p)
            p.target = _with_errors(p)
        _check_numeig(p)
    target = _with_truth(p.target, request.truth)
    _check_genus(request, target)
    model = _model(p)
    where = _where(request)
    return FitPlan(target, model, _options(p), init=_init(request, model), choices=tuple(p.choices),
                   notes=tuple(p.notes), expected_error=_expected_error(p, model, target),
                   surface_plan=p.surface_plan, numeig_plan=p.numeig_plan, numeig_auto=p.numeig_auto,
                   adaptive=request.adaptive, expectation=_expectation(p, target, where), **where)


def _check_noise(r: FitRequest) -> None:
    """Refuse a noise given beside errors of the target's own before any planning (a plan of K takes a minute)."""
    if r.noise is None:
        return
    what = r.target
    if isinstance(what, str) and what.startswith("spectrum:"):
        own = read_spectrum_file(what.partition(":")[2]).errors is not None
    else:
        own = r.errors is not None or (isinstance(what, Target) and what.errors is not None)
    if own:
        raise InvalidArgumentError("the target gives each eigenvalue's error (a spectrum file's error column, or "
                                   "errors given); noise (--noise) would replace them: give one")


def _surface_planned(request: FitRequest, kind: str) -> bool:
    """Whether La, K and Lb come from a surface plan: a log fit of a mesh's cotan spectrum, La and K not given."""
    return (kind == "log" and request.is_mesh and request.source in ("pl", "cmcf") and request.lmax_factor is None
            and request.numeig is None)


def _plan_surface(p: _Planning) -> None:
    """The mesh target refined (or with the request's noise) and cut to the K of its surface plan."""
    r = p.request
    target = _target_of(r, DEFAULT_LMAX, default_numeig(r.mesh_size()), TRUTH_DEGREE)
    target = target.with_noise(r.noise) if r.noise is not None else _refined(p, target, subdivision_spectra(target))
    if r.progress:
        announce("planning La and K by the floor of the basis and the target's errors, then polishing the best "
                 "expansion of the cMCF factors against the spectrum (a minute or two)")
    plan = plan_surface_fit(target)
    if plan.beyond_basis:
        raise BeyondBasisError(plan.diagnosis())
    if not plan.feasible:
        p.say(f"warning: {plan.diagnosis()}")
    why = f"the surface plan: predicted error of rho against the cMCF factors {plan.predicted:.2g}"
    bias = plan.bias if plan.bias is not None else plan.floor
    p.lmax_factor = p.choose("lmax_factor", plan.lmax_factor, f"{why} (floor {plan.floor:.2g}, bias {bias:.2g}, "
                             f"the target's errors alone {plan.noise:.2g}; the fewest coefficients within 10 % of "
                             f"the best prediction, {plan.best_predicted:.2g})")
    p.numeig = p.choose("numeig", plan.numeig, f"the fewest with {SEARCH_NUMEIG_FACTOR:g} eigenvalues per coefficient "
                        "(all there are, if fewer)")
    p.lmax = p.choose("lmax", plan.lmax, "each eigenvalue converged to a tenth of its error")
    rel = plan.fit_errors[1:] / target.eigenvalues[1:plan.numeig]
    p.say(f"the fit is held to the target's errors and the misfit of the best degree-{plan.lmax_factor} expansion "
          f"of its cMCF factors polished against the spectrum: {rel.min():.1g} to {rel.max():.1g} (relative)")
    p.surface_plan, p.target = plan, plan.fitted_target(target)


def _plan_degrees(p: _Planning) -> None:
    """La, Lb and K of a fit that no surface plan makes (module notes)."""
    r = p.request
    la = r.lmax_factor if r.lmax_factor not in (None, "auto") else DEFAULT_LMAX_FACTOR
    if r.lmax_factor == "auto":
        have = _given_eigenvalues(r)
        la = max(2, supported_degree(have))
        p.lmax_factor = p.choose("lmax_factor", la, f"the degree {have} eigenvalues support at "
                                 f"{SEARCH_NUMEIG_FACTOR:g} per coefficient of rho")
    elif r.lmax_factor is not None:
        p.lmax_factor = p.choose("lmax_factor", la, "as asked")
    elif isinstance(r.target, ConformalFactor):
        p.lmax_factor = p.choose("lmax_factor", r.target.lmax, "the degree of the rho given")
        la = r.target.lmax
    else:
        p.lmax_factor = p.choose("lmax_factor", la, "the default degree")
    if r.numeig is not None or p.kind == "mesh":
        _given_numeig(p)
        return
    have, floor = _spectrum_size(r), search_numeig(la)
    if have is not None and have < floor and not r.allow_short_spectrum:  # short whatever K the plan finds
        _short_spectrum(p, have, floor)
    # the log model takes the plan of a harmonic rho of the same degree: the same number of unknowns
    plan = plan_fit(la, random_centred_coefficients(r.options.seed, la, 0.2))
    if plan.numeig is None:
        raise InvalidArgumentError(plan.statement() + "; give numeig (--numeig)")
    p.numeig_plan = plan
    p.numeig = p.choose("numeig", plan.numeig, plan.statement())
    p.lmax = p.choose("lmax", plan.lmax if r.lmax is None else r.lmax,
                      "as asked" if r.lmax is not None else "the planned K converged at it")


def _spectrum_size(r: FitRequest) -> int | None:
    """How many eigenvalues a spectrum's target brings; None for a target computed to the K asked (a mesh, a ρ)."""
    what = r.target
    if isinstance(what, str) and what.startswith("spectrum:"):
        return read_spectrum_file(what.partition(":")[2]).eigenvalues.size
    if isinstance(what, Target):
        return what.numeig
    if isinstance(what, (np.ndarray, list, tuple)):
        return int(np.size(what))
    return None


def _given_eigenvalues(r: FitRequest) -> int:
    """How many eigenvalues a spectrum's target brings to the fit (lmax_factor="auto" needs a spectrum)."""
    have = _spectrum_size(r)
    if have is None:
        raise InvalidArgumentError("lmax_factor='auto' (--lmax-factor auto) picks the degree a given spectrum "
                                   "supports: give a spectrum (spectrum:FILE, eigenvalues or a Target)")
    return min(have, r.numeig) if isinstance(r.numeig, int) else have


def _short_spectrum(p: _Planning, have: int, planned: int) -> None:
    """Refuse a target of fewer eigenvalues than the plan asks for at its degree, naming the degree they support
    and what the benchmark measured with so few; with ``allow_short_spectrum``, say so and go on (the plan's
    statement says what the fit can expect)."""
    la = p.lmax_factor
    supported = supported_degree(have)
    given = (f"the target has {have} eigenvalues; the plan of degree {la} asks for {planned} "
             f"({SEARCH_NUMEIG_FACTOR:g} per coefficient of rho): {have} support degree {supported}")
    if p.request.allow_short_spectrum:
        p.say(f"warning: {given}; fitted at degree {la} as asked (allow_short_spectrum)")
        return
    fix = ("Fit that degree with lmax_factor='auto' (--lmax-factor auto)" if supported >= 2 else
           f"Give at least {search_numeig(2)} eigenvalues (degree 2)")
    raise ShortSpectrumError(f"{given}. {fix}, or fit degree {la} with the {have} given: allow_short_spectrum=True "
                             f"(--allow-short-spectrum); {expectation(la, have)[1]}", supported)


def _given_numeig(p: _Planning) -> None:
    """K as asked, or a mesh fit's share of its vertices; Lb as asked or :data:`DEFAULT_LMAX`."""
    r = p.request
    numeig = r.numeig
    if numeig is None:  # a mesh fit: the study's share of the eigenvalues where a dense solve is cheap
        n = r.mesh_size() if r.is_mesh else 0
        numeig = max(2, round(MESH_NUMEIG_FRACTION * n)) if 0 < n <= MESH_FRACTION_VERTICES else "auto"
        p.choose("numeig", numeig, f"{MESH_NUMEIG_FRACTION:g} of the mesh's vertices" if numeig != "auto" else
                 f"those the mesh resolves (a mesh of more than {MESH_FRACTION_VERTICES} vertices)")
    else:
        p.choose("numeig", numeig, "as asked")
    if numeig == "auto":
        p.numeig_auto = {}  # filled in when the target is known
        numeig = default_numeig(r.mesh_size())
    elif numeig == "all":
        numeig = r.mesh_size() - 1
    p.numeig = numeig
    p.lmax = p.choose("lmax", DEFAULT_LMAX if r.lmax is None else r.lmax,
                      "as asked" if r.lmax is not None else "the default basis")


def _target_of(r: FitRequest, lmax: int, numeig: int, lmax_factor: int) -> Target:
    """The request's target with ``numeig`` eigenvalues (a spectrum's: at most as many as it has)."""
    what = r.target
    if isinstance(what, str):
        return parse_target(what, lmax=lmax, numeig=numeig, lmax_factor=lmax_factor, source=r.source,
                            subdivisions=r.subdivisions)
    if isinstance(what, TriangleMesh):
        return mesh_target(what, lmax, numeig, lmax_factor, source=r.source)
    if isinstance(what, ConformalFactor):
        return harmonic_target(what, lmax, numeig)
    target = what if isinstance(what, Target) else Target("spectrum", np.asarray(what, dtype=float),
                                                           errors=r.errors)
    return target.first(min(numeig, target.numeig))


def _build_target(p: _Planning) -> Target:
    return _target_of(p.request, p.lmax, p.numeig, p.lmax_factor)


def _refined(p: _Planning, target: MeshTarget, fine) -> MeshTarget:
    """:func:`refined_target` of the subdivisions' spectra ``fine`` (levels, k), with a note."""
    refined = refined_target(target, fine)
    rel = refined.errors[1:] / refined.eigenvalues[1:]
    how = ("those of its 4-to-1 subdivision" if len(fine) == 1 else
           f"extrapolated from {len(fine)} 4-to-1 subdivisions (Richardson)")
    p.say(f"the mesh target's eigenvalues are {how}, with an estimated discretization error of {rel.min():.1g} to "
          f"{rel.max():.1g} (relative): the fit weighs and stops by it")
    return refined


def _with_errors(p: _Planning) -> Target:
    """The target with its errors: its own, the request's noise, or a mesh's discretization errors for
    a harmonic model (which hears them; a mesh model shares the mesh's discretization)."""
    target, r = p.target, p.request
    if target.errors is not None:  # its own (noise beside them was refused before planning)
        return target
    if r.noise is not None:
        return target.with_noise(r.noise)
    if isinstance(target, MeshTarget) and target.source in ("pl", "cmcf") and p.kind != "mesh":
        fine = subdivision_spectra(target)
        if p.numeig_auto is not None:
            p.numeig_auto = {"changes": subdivision_changes(target, fine[0])}
        return _refined(p, target, fine)
    return target


def _check_numeig(p: _Planning) -> None:
    """Cut the target to the K its mesh resolves (``numeig="auto"``), or say when it has fewer than planned."""
    if p.numeig_auto is not None:
        _auto_numeig(p)
        return
    planned, have = p.numeig, p.target.numeig
    if planned is not None and have < planned and p.numeig_plan is not None:
        _short_spectrum(p, have, planned)


def _auto_numeig(p: _Planning) -> None:
    """The target cut to the eigenvalues its mesh resolves to ``numeig_tol``, and the report."""
    target, tol = p.target, p.request.numeig_tol
    if not isinstance(target, MeshTarget):
        raise InvalidArgumentError("numeig='auto' needs a mesh target (star:... or mesh:...)")
    cmcf = target.source == "cmcf"
    where = "its cMCF sphere carrying the cMCF factors" if cmcf else "the target mesh"
    err = p.numeig_auto.get("changes")
    if err is None:
        err = subdivision_changes(target) if cmcf else eigenvalue_errors(target.mesh, target.numeig)[1]
    k = trusted_numeig(err, tol)
    p.numeig_auto = {"chosen": k, "of": target.numeig, "tolerance": tol, "estimated_on": where,
                     "estimate": "|lambda_i - lambda_i(4-to-1 subdivision)| / lambda_i",
                     "largest_kept_error": float(err[1:k].max()),
                     "first_dropped_error": float(err[k]) if k < err.size else None}
    p.say(f"numeig auto: {k} of the first {target.numeig} eigenvalues of {where} ({target.sphere.nvertices} "
          f"vertices) have an estimated discretization error <= {tol:g} (largest kept "
          f"{p.numeig_auto['largest_kept_error']:.2g}" + (f", next {err[k]:.2g})" if k < err.size else ")"))
    p.target = target.first(k)


def _with_truth(target: Target, truth) -> Target:
    """The target with the request's truth (a ConformalFactor, coefficients or a file of them)."""
    if truth is None:
        return target
    if not isinstance(truth, ConformalFactor):
        truth = (ConformalFactor(np.asarray(truth, dtype=float), name="truth")
                 if isinstance(truth, (np.ndarray, list, tuple)) else read_truth(truth))
        truth.check_positive()
    return dataclasses.replace(target, truth=truth)


def _check_genus(r: FitRequest, target: Target) -> None:
    """Refuse a spectrum or mesh whose heat trace says confidently that its genus is not 0 (the blob, a star and a
    harmonic rho are spheres by construction)."""
    if r.allow_any_genus or isinstance(r.target, ConformalFactor):
        return
    if isinstance(r.target, str):
        scheme, _, where = r.target.partition(":")
        if scheme not in ("spectrum", "mesh"):
            return
        # the whole file, not only the K fitted: the heat trace needs many eigenvalues to be confident
        eigenvalues = read_spectrum(where) if scheme == "spectrum" else target.eigenvalues
    elif isinstance(r.target, Target):
        eigenvalues = r.target.eigenvalues
    else:
        eigenvalues = target.eigenvalues if isinstance(r.target, TriangleMesh) else np.asarray(r.target, float)
    check_genus_zero(eigenvalues, area=target.area)


def _model(p: _Planning):
    r = p.request
    if p.kind == "harmonic":
        return HarmonicModel(p.lmax, p.lmax_factor)
    if p.kind == "log":
        return LogHarmonicModel(p.lmax, p.lmax_factor)
    if not isinstance(p.target, MeshTarget):
        raise InvalidArgumentError("model='mesh' (--model mesh) needs a mesh target (star:..., mesh:... or a "
                                   "TriangleMesh): it fits per-vertex factors on the target's cMCF sphere")
    return MeshModel(p.target.sphere, lmax_factor=p.lmax_factor, transform="exp" if r.log_factors else "identity",
                     reg_kind=r.reg_kind)


def _options(p: _Planning) -> FitOptions:
    """The request's options with the planned penalty and schedule, and its progress."""
    r, base = p.request, p.request.options
    default_reg = FitOptions().reg
    if r.reg is not None and base.reg not in (default_reg, r.reg):
        raise InvalidArgumentError(f"reg={r.reg:g} and options.reg={base.reg:g} disagree: give one")
    reg = r.reg if r.reg is not None else (base.reg if base.reg != default_reg else
                                           MESH_REG if p.kind == "mesh" else default_reg)
    p.choose("reg", reg, "as asked" if r.reg is not None or base.reg != default_reg else
             "the study's regularized mesh fit" if p.kind == "mesh" else "no penalty")
    return dataclasses.replace(base, reg=reg, schedule=_schedule(p, base.schedule), progress=r.progress)


def _schedule(p: _Planning, given):
    r = p.request
    text, hop = r.schedule, r.hop_degree
    if not isinstance(text, str):
        return tuple(text)
    if hop is not None and (text not in ("auto", "degree-ramp") or p.kind == "mesh"):
        raise InvalidArgumentError(f"hop_degree (--hop-degree) shapes the degree ramp of a harmonic fit (schedule "
                                   f"auto or degree-ramp); with schedule {text!r} mark the stage to hop as 'L:Kh'")
    if text == "auto" and hop is None:
        return given
    if text in ("auto", "degree-ramp"):
        la = p.lmax_factor
        return degree_ramp(p.target.numeig, la, stage_max_iter=DEFAULT_STAGE_MAX_ITER,
                           hop_degree=default_hop_degree(la) if hop is None else hop or None)
    if text == "none":
        return ()
    if text == "ramp":
        return numeig_ramp(p.target.numeig)
    if text == "parity-ramp":
        if p.kind == "mesh":  # said while planning, before fit() would refuse the even stages
            raise InvalidArgumentError("the parity ramp holds odd degrees at 0: a mesh model has no degrees")
        return parity_ramp(p.target.numeig, p.lmax_factor)
    return parse_schedule(text)


def _init(r: FitRequest, model):
    """The first start's parameters from the request's init (a file, or the model's own parameters)."""
    if r.init is None:
        return None
    if isinstance(r.init, (np.ndarray, list, tuple)):
        return initial_parameters(np.asarray(r.init, dtype=float), "own", model, name="init")
    return read_initial(r.init, model)


def _expected_error(p: _Planning, model, target: Target) -> float | None:
    """Before fitting: the relative error of ρ that the target's errors leave at a random start of the fit's law
    (:func:`~shspec.inverse.identifiability.identifiability` with them as noise); a surface plan's prediction."""
    if p.surface_plan is not None:
        return p.surface_plan.predicted
    if target.errors is None or p.kind == "mesh":
        return None
    opt = p.request.options
    ref = model.random_start(np.random.default_rng([opt.seed, 0]), opt.start_amplitude, target.area_estimate())
    noise = np.r_[1.0, target.errors[1:] / target.eigenvalues[1:]]
    return identifiability(model, ref, target.numeig, noise=noise).noise_error


def _expectation(p: _Planning, target: Target, where: dict) -> tuple[Measured | None, str]:
    """The many-law benchmark's record for this fit (:func:`~shspec.fitting.expected.expectation`), or why it
    does not apply: the benchmark fits exact spectra with a harmonic model, the default options and schedule, its
    starts on two processes."""
    r, defaults = p.request, FitOptions()
    # the seed draws other starts of the same law; checkpoints and progress do not change a start's path
    changed = [f.name for f in dataclasses.fields(FitOptions)
               if f.name not in ("progress", "seed", "checkpoint_every", "checkpoint_path")
               and getattr(r.options, f.name) != getattr(defaults, f.name)] + ["reg"] * (r.reg is not None)
    serial = where["scheduler"] is None and (where["workers"] or 1) < 2
    unlike = next((why for differs, why in (
        (p.kind != "harmonic", f"a {p.kind} fit; the many-law benchmark measures harmonic fits of spectra"),
        (target.errors is not None, "the target has errors; the benchmark's spectra are exact"),
        (bool(changed), f"options other than the defaults: {', '.join(changed)}"),
        (r.schedule != "auto" or r.hop_degree is not None, "a schedule other than the default"),
        (r.init is not None, "a given start"),
        (serial, "the starts run one after another; the benchmark ran them on two processes")) if differs), None)
    return expectation(p.lmax_factor, target.numeig, unlike)


def _where(r: FitRequest) -> dict:
    """The starts' workers and scheduler: as asked; "auto": one process per start and usable core, serial for one
    start, one core, or with checkpoints inside the starts (a pool checkpoints finished starts only); None: here."""
    if r.scheduler is not None:
        return {"workers": None if r.workers == "auto" else r.workers, "scheduler": r.scheduler}
    if r.workers != "auto":
        return {"workers": r.workers or 1, "scheduler": None}
    opt = r.options
    return {"workers": 1 if opt.checkpoint_every else max(1, min(opt.starts, usable_cores())), "scheduler": None}
