"""``recursive_fit``: the study's Section 3.2.3 — fit, re-embed, and fit again on the re-embedded mesh's own sphere.

The PL inverse problem (per-vertex factors of a fixed mesh, :class:`~shspec.mesh.model.MeshModel`) works when its
mesh is already adapted to the target (the target's own cMCF sphere, :doc:`/theory`), which a real problem does not
have.
The study's remedy: take the surface re-embedded from a first fit, compute its cMCF sphere — a sphere mesh refined
where the first result has its features — and fit again there.  Each pass:

1. fit per-vertex factors c to the target spectrum with :func:`shspec.inverse.fit` on the pass's reference mesh;
2. re-embed (:func:`~shspec.embed.embed`) the metric of the reference mesh times c, through a unit-sphere mesh;
3. cMCF of the embedded surface (:func:`~shspec.mesh.cmcf.cmcf`): its sphere and factors b define the next pass.

Warm start.  :func:`~shspec.inverse.fit` starts a mesh fit near constant factors of its model's mesh.  On the new
cMCF sphere that is the round sphere, far from the first result (and measured worse on a 162-vertex blob: the
second fit ends with a larger residual than the first).  So by default (``warm_start``) the model of pass k ≥ 2 is
the previous re-embedded surface itself — the new sphere's metric b·g₀ up to the discretization of cMCF — and its
near-constant start *is* the previous result; the factors then embed through the new sphere as b·c.  With
``warm_start=False`` the fit runs on the new sphere from the fit's own start, as the study describes.

Each pass records the fit's residual, the re-embedding's strain, the relative error of the re-embedded surface's own
PL spectrum against the target, and, when the target carries its mesh, the Hausdorff/Chamfer distance to it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..embed.distances import surface_distance
from ..embed.embed import EmbedOptions, EmbedResult, embed
from ..core.checks import check_int, check_options
from ..mesh.cotan import vertex_areas
from ..errors import InvalidArgumentError
from ..inverse import FitOptions, Target, fit
from ..inverse.energy import rms_relative_residual
from ..mesh.cmcf import cmcf
from ..mesh.eigen import mesh_spectrum
from ..mesh.model import MeshModel
from ..mesh.triangle_mesh import TriangleMesh

__all__ = ["RecursiveOptions", "RefinementPass", "RecursiveResult", "recursive_fit"]


def _default_fit_options():
    return FitOptions(optimizer="lm", schedule=(), basin_hops=0, starts=1, max_iter=40, reg=1e-5, start_amplitude=0.02)


@dataclass(frozen=True)
class RecursiveOptions:
    """Options of :func:`recursive_fit`.

    Attributes
    ----------
    passes : int
        Fit-and-embed passes (2: the study's "one more time").
    fit : FitOptions
        Options of every fit (default: one start, 40 Levenberg–Marquardt iterations, regularizer 1e-5, start
        amplitude 0.02).
    embed : EmbedOptions
        Options of every re-embedding (default: no self-intersection count).
    warm_start : bool or "init"
        Fit pass k ≥ 2 on the previous re-embedded surface (True, see the module notes); False: on its cMCF sphere
        from the fit's own start; "init": on its cMCF sphere, started (``fit(..., init=...)``) from the transferred
        factors, the cMCF factors of the re-embedded surface scaled to the target's area.
    log_factors : bool
        Fit s = log c (``MeshModel(transform="exp")``).
    reg_kind : str
        The mesh regularizer (:data:`~shspec.mesh.model.REGULARIZER_KINDS`).

    Examples
    --------
    >>> from shspec.fitting import RecursiveOptions
    >>> RecursiveOptions(passes=2).passes
    2
    """

    passes: int = 2
    fit: object = field(default_factory=_default_fit_options)
    embed: EmbedOptions = field(default_factory=lambda: EmbedOptions(check_intersections=False))
    warm_start: bool | str = True
    log_factors: bool = False
    reg_kind: str = "bilaplacian"

    def __post_init__(self):
        check_int(self.passes, "RecursiveOptions.passes", minimum=1)
        if self.warm_start not in (True, False, "init"):
            raise InvalidArgumentError(f"RecursiveOptions.warm_start must be True, False or 'init', got "
                                       f"{self.warm_start!r}")
        if not isinstance(self.fit, FitOptions):
            raise InvalidArgumentError("RecursiveOptions.fit must be FitOptions")
        if not isinstance(self.embed, EmbedOptions):
            raise InvalidArgumentError("RecursiveOptions.embed must be EmbedOptions")


@dataclass(frozen=True)
class RefinementPass:
    """One pass of :func:`recursive_fit`.

    Attributes
    ----------
    sphere : TriangleMesh
        The unit-sphere mesh the factors live on (n vertices).
    factors : (n,) array
        The fitted metric on ``sphere`` (per-vertex conformal factors).
    embedding : EmbedResult
        Its re-embedding.
    fit_residual : float
        max_i |λ_i/λ*_i − 1| (i ≥ 1) of the fitted model.
    spectral_rms_error : float
        RMS over i ≥ 1 of |λ_i/λ*_i − 1| for the re-embedded surface's own PL spectrum.
    hausdorff_relative, chamfer_relative : float or None
        Distances of the re-embedded surface to the target mesh over its bounding-box diagonal (None without one).
    fit_status : str
        Why the fit stopped.
    cpu_seconds : float
        CPU time of the pass.

    Examples
    --------
    >>> from shspec.fitting import RecursiveOptions, mesh_target, recursive_fit
    >>> from shspec.inverse import FitOptions
    >>> from shspec.mesh.shapes import star_surface
    >>> target = mesh_target(star_surface(2, 1, 0.3, 1), lmax=10, numeig=10, lmax_factor=4)
    >>> quick = FitOptions(starts=1, max_iter=5, basin_hops=0, progress=False)
    >>> first = recursive_fit(target, options=RecursiveOptions(passes=1, fit=quick)).passes[0]
    >>> first.sphere.nvertices, first.hausdorff_relative < 0.2
    (42, True)
    """

    sphere: TriangleMesh = field(repr=False)
    factors: np.ndarray = field(repr=False)
    embedding: EmbedResult = field(repr=False)
    fit_residual: float
    spectral_rms_error: float
    hausdorff_relative: float | None
    chamfer_relative: float | None
    fit_status: str
    cpu_seconds: float


@dataclass(frozen=True)
class RecursiveResult:
    """Result of :func:`recursive_fit`: the passes in order.

    Examples
    --------
    >>> from shspec.fitting import RecursiveOptions, mesh_target, recursive_fit
    >>> from shspec.inverse import FitOptions
    >>> from shspec.mesh.shapes import star_surface
    >>> target = mesh_target(star_surface(2, 1, 0.3, 1), lmax=10, numeig=10, lmax_factor=4)
    >>> quick = FitOptions(starts=1, max_iter=5, basin_hops=0, progress=False)
    >>> result = recursive_fit(target, options=RecursiveOptions(passes=2, fit=quick))
    >>> len(result.passes), result.final is result.passes[-1]
    (2, True)
    """

    passes: tuple

    @property
    def final(self) -> RefinementPass:
        return self.passes[-1]


def recursive_fit(target, sphere: TriangleMesh | None = None, options: RecursiveOptions | None = None, *,
                  log=None) -> RecursiveResult:
    """Fit per-vertex factors to a target spectrum, re-embed, and fit again on the result's cMCF sphere.

    Parameters
    ----------
    target : shspec.inverse.Target
        The spectrum (k eigenvalues), e.g. from :func:`shspec.fitting.mesh_target`.
    sphere : TriangleMesh, optional
        Unit-sphere mesh of the first pass; default the target's own cMCF sphere (``target.sphere``).
    options : RecursiveOptions, optional
    log : callable, optional
        Called with one line per pass.

    Returns
    -------
    RecursiveResult

    Raises
    ------
    InvalidArgumentError
        No sphere given and the target has none; wrong types.

    Examples
    --------
    >>> from shspec.fitting import RecursiveOptions, mesh_target, recursive_fit
    >>> from shspec.inverse import FitOptions
    >>> from shspec.mesh.shapes import star_surface
    >>> target = mesh_target(star_surface(2, 1, 0.3, 1), lmax=10, numeig=10, lmax_factor=4)
    >>> quick = FitOptions(starts=1, max_iter=5, basin_hops=0, progress=False)
    >>> result = recursive_fit(target, options=RecursiveOptions(passes=2, fit=quick))
    >>> [p.sphere.nvertices for p in result.passes]   # each pass fits on the last surface's cMCF sphere
    [42, 42]
    """
    opt = check_options(options, RecursiveOptions)
    if not isinstance(target, Target):
        raise InvalidArgumentError(f"target must be a Target, got {type(target).__name__}")
    sphere = sphere if sphere is not None else getattr(target, "sphere", None)
    if not isinstance(sphere, TriangleMesh):
        raise InvalidArgumentError("a sphere mesh is needed: pass one, or a target built from a mesh")
    say = log if log is not None else (lambda _msg: None)
    lam_star = target.eigenvalues
    k = lam_star.size
    reference, base = sphere, np.ones(sphere.nvertices)
    init = None
    passes = []
    for p in range(opt.passes):
        cpu = time.process_time()
        model = MeshModel(reference, transform="exp" if opt.log_factors else "identity", reg_kind=opt.reg_kind)
        result = fit(target, model, opt.fit, init=init)
        best = result.best
        c = base * np.asarray(best.params, dtype=float)
        emb = embed(sphere, c, opt.embed)
        lam = mesh_spectrum(emb.mesh, k, whole_multiplets=False).eigenvalues
        spec = rms_relative_residual(lam, lam_star)
        haus = cham = None
        if isinstance(getattr(target, "mesh", None), TriangleMesh):
            d = surface_distance(emb.mesh, target.mesh)
            haus, cham = d.hausdorff_relative, d.chamfer_relative
        passes.append(RefinementPass(sphere=sphere, factors=c, embedding=emb, fit_residual=float(best.relative_residual),
                                     spectral_rms_error=spec, hausdorff_relative=haus, chamfer_relative=cham,
                                     fit_status=str(best.status), cpu_seconds=time.process_time() - cpu))
        say(f"pass {p + 1}: fit residual {best.relative_residual:.3g} ({best.status}), strain "
            f"{emb.edge_error_rms:.3g}, spectral error {spec:.3g}, Hausdorff {haus}")
        if p + 1 < opt.passes:
            flow = cmcf(emb.mesh)
            sphere = flow.sphere
            if opt.warm_start == "init":
                reference, base = flow.sphere, np.ones(sphere.nvertices)
                init = flow.factors * (target.area_estimate() / float(flow.factors @ vertex_areas(flow.sphere)))
            elif opt.warm_start:
                reference, base = emb.mesh, flow.factors
            else:
                reference, base = flow.sphere, np.ones(sphere.nvertices)
    return RecursiveResult(passes=tuple(passes))
