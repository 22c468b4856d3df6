"""``adaptive_fit``: a per-vertex fit that starts from a generic icosphere and refines it where the fit needs it (the
study's A.5, its open problem: its PL inverse only worked from the target's own cMCF sphere).

Each stage fits log factors s = log c (:class:`~shspec.mesh.model.MeshModel`, ``transform="exp"``) on the current
sphere mesh; between stages :func:`~shspec.mesh.refine.refine_sphere` splits the edges that are long in the fitted
metric (so that each vertex carries a comparable share of the fitted area), keeps the mesh Delaunay on the sphere
and carries s to the new vertices by linear interpolation, and the next stage starts from it (``init``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..core.checks import check_int, check_options
from ..errors import InvalidArgumentError
from ..inverse.multistart import fit
from ..inverse.options import FitOptions
from ..inverse.results import FitResult
from ..mesh.model import REGULARIZER_KINDS, MeshModel
from ..mesh.refine import mesh_quality, refine_sphere
from ..mesh.shapes import icosphere
from ..inverse.target import Target

__all__ = ["AdaptiveOptions", "AdaptiveStage", "AdaptiveResult", "adaptive_fit", "stage_sizes"]


def stage_sizes(start: int, final: int, growth: float = 2.0) -> tuple[int, ...]:
    """Vertex counts of the stages: ``start``, then ×``growth`` per stage, ending exactly at ``final``."""
    start, final = check_int(start, "start", minimum=12), check_int(final, "final", minimum=12)
    if not growth > 1:
        raise InvalidArgumentError(f"growth must be > 1, got {growth}")
    sizes = [start]
    while sizes[-1] < final:
        sizes.append(min(final, int(round(sizes[-1] * growth))))
    return tuple(sizes)


@dataclass(frozen=True)
class AdaptiveOptions:
    """Options of :func:`adaptive_fit`.

    Attributes
    ----------
    subdivisions : int
        The starting icosphere (2: 162 vertices, 3: 642).
    nvertices : int or None
        Vertices of the last stage; None: as many as the target's own mesh has (or the start's, without one).
    growth : float
        Vertex count ratio between stages.  Small steps let the refinement follow the fit: the metric grows only
        as fast as the mesh resolves it (bunny_600, R = 0.05, three seeds: log RMS 0.33, 0.35, 0.43 after Möbius
        + O(3) alignment with 1.3 and numeig_fraction 0.5, against 0.47, 0.45, 0.47 with 2.0 and 0.25).
    reg_kind : str
        The regularizer of every stage (:data:`~shspec.mesh.model.REGULARIZER_KINDS`).
    numeig_fraction : float
        Stages before the last match at most this fraction of their mesh's vertex count in eigenvalues: the top of
        a coarse mesh's spectrum is its own discretization, not the surface's (the last stage matches all of the
        target's, at most n − 1).
    fit : FitOptions
        The options of every stage's fit (the first stage's schedule and starts; later stages start from the
        refined previous result in one stage).

    Examples
    --------
    >>> from shspec.fitting import AdaptiveOptions
    >>> AdaptiveOptions(subdivisions=1, nvertices=162).growth
    1.3
    """

    subdivisions: int = 2
    nvertices: int | None = None
    growth: float = 1.3
    reg_kind: str = "dirichlet"
    numeig_fraction: float = 0.5
    fit: FitOptions = field(default_factory=FitOptions)

    def __post_init__(self):
        check_int(self.subdivisions, "AdaptiveOptions.subdivisions", minimum=0, maximum=5)
        check_int(self.nvertices, "AdaptiveOptions.nvertices", allow_none=True, minimum=12)
        if self.reg_kind not in REGULARIZER_KINDS:
            raise InvalidArgumentError(f"reg_kind must be one of {REGULARIZER_KINDS}, got {self.reg_kind!r}")
        if not 0 < self.numeig_fraction <= 1:
            raise InvalidArgumentError(f"numeig_fraction must be in (0, 1], got {self.numeig_fraction}")
        if not isinstance(self.fit, FitOptions):
            raise InvalidArgumentError("AdaptiveOptions.fit must be FitOptions")


@dataclass(frozen=True)
class AdaptiveStage:
    """One stage: the mesh size, the fit's residual and time, and the mesh's shape.

    Examples
    --------
    >>> from shspec.fitting import AdaptiveOptions, adaptive_fit, mesh_target
    >>> from shspec.inverse import FitOptions
    >>> from shspec.mesh.shapes import star_surface
    >>> target = mesh_target(star_surface(2, 1, 0.3, 1), lmax=10, numeig=10, lmax_factor=4)
    >>> quick = FitOptions(starts=1, max_iter=5, basin_hops=0, progress=False)
    >>> stages = adaptive_fit(target, AdaptiveOptions(subdivisions=1, fit=quick)).stages
    >>> stages[0].nvertices, stages[-1].nvertices     # from the icosphere to the target's own size
    (42, 42)
    """

    nvertices: int
    relative_residual: float
    energy: float
    status: str
    seconds: float
    min_angle: float
    fitted_range: tuple

    def to_dict(self) -> dict:
        return {"nvertices": self.nvertices, "relative_residual": self.relative_residual, "energy": self.energy,
                "status": self.status, "seconds": self.seconds, "min_angle_deg": self.min_angle,
                "fitted_range": list(self.fitted_range)}


@dataclass(frozen=True)
class AdaptiveResult:
    """Result of :func:`adaptive_fit`: the stages, and the last stage's fit (its model holds the refined mesh).

    Examples
    --------
    >>> from shspec.fitting import AdaptiveOptions, adaptive_fit, mesh_target
    >>> from shspec.inverse import FitOptions
    >>> from shspec.mesh.shapes import star_surface
    >>> target = mesh_target(star_surface(2, 1, 0.3, 1), lmax=10, numeig=10, lmax_factor=4)
    >>> quick = FitOptions(starts=1, max_iter=5, basin_hops=0, progress=False)
    >>> result = adaptive_fit(target, AdaptiveOptions(subdivisions=1, nvertices=162, fit=quick))
    >>> [stage.nvertices for stage in result.stages]
    [42, 55, 72, 94, 122, 159, 162]
    >>> result.result.model.nparams
    162
    """

    stages: tuple
    result: FitResult

    def to_dict(self) -> dict:
        return {"stages": [s.to_dict() for s in self.stages], "sizes": [s.nvertices for s in self.stages],
                "seconds": float(sum(s.seconds for s in self.stages))}


def adaptive_fit(target: Target, options: AdaptiveOptions | None = None, *, log=None) -> AdaptiveResult:
    """Fit per-vertex log factors to ``target`` from a generic icosphere, refining between stages (module notes).

    Parameters
    ----------
    target : Target
        The spectrum (and, for the comparison in the summary, the truth on its own cMCF sphere).
    options : AdaptiveOptions, optional
    log : callable, optional
        Called with one line per stage.

    Returns
    -------
    AdaptiveResult

    Examples
    --------
    >>> from shspec.fitting import AdaptiveOptions, adaptive_fit, mesh_target
    >>> from shspec.inverse import FitOptions
    >>> from shspec.mesh.shapes import star_surface
    >>> target = mesh_target(star_surface(2, 1, 0.3, 1), lmax=10, numeig=10, lmax_factor=4)
    >>> quick = FitOptions(starts=1, max_iter=5, basin_hops=0, progress=False)
    >>> result = adaptive_fit(target, AdaptiveOptions(subdivisions=1, nvertices=162, fit=quick))
    >>> len(result.stages), result.result.model.nparams
    (7, 162)
    """
    opt = check_options(options, AdaptiveOptions)
    if not isinstance(target, Target):
        raise InvalidArgumentError(f"target must be a Target, got {type(target).__name__}")
    say = log if log is not None else (lambda _msg: None)
    sphere = icosphere(opt.subdivisions)
    own = getattr(target, "sphere", None)  # a mesh target's cMCF sphere sets the final size
    final = opt.nvertices or (own.nvertices if own is not None else sphere.nvertices)
    sizes = stage_sizes(sphere.nvertices, max(final, sphere.nvertices), opt.growth)
    stages, init, result = [], None, None
    for i, n in enumerate(sizes):
        if i:
            sphere, s = refine_sphere(sphere, np.log(result.best.params), n)
            init = np.exp(s)
        model = MeshModel(sphere, transform="exp", reg_kind=opt.reg_kind)
        k = min(target.numeig, sphere.nvertices - 1)
        if i < len(sizes) - 1:
            k = min(k, max(2, int(opt.numeig_fraction * sphere.nvertices)))
        stage_target = target.first(k)
        t0 = time.perf_counter()
        result = fit(stage_target, model, opt.fit, init=init)
        best = result.best
        stages.append(AdaptiveStage(nvertices=sphere.nvertices, relative_residual=float(best.relative_residual),
                                    energy=float(best.energy), status=str(best.status),
                                    seconds=time.perf_counter() - t0, min_angle=mesh_quality(sphere).min_angle,
                                    fitted_range=(float(best.params.min()), float(best.params.max()))))
        say(f"adaptive stage {i + 1}/{len(sizes)}: {sphere.nvertices} vertices, {k} eigenvalues, residual "
            f"{best.relative_residual:.3g} ({best.status}), factors {best.params.min():.3g}..{best.params.max():.3g}")
    return AdaptiveResult(stages=tuple(stages), result=result)
