"""``validate_target``: everything the study's Section 2.4 asks to compare, for one target mesh.

Steps (each reported with a status, never faked):

1. cMCF of the target (:func:`~shspec.mesh.cmcf.cmcf`): the sphere mesh and the per-vertex factors c.
2. The target's cotan spectrum refined by subdivision (Richardson-extrapolated from two subdivisions up to 12,500
   vertices), with its discretization error (:func:`~shspec.fitting.targets.refined_target`)
   and, unless La and K are given, the plan of a log-ρ fit (:func:`~shspec.fitting.surface_plan.plan_surface_fit`):
   La, K and Lb from the floor of the basis and the target's errors, and the error they predict.
3. Spectra, first K eigenvalues: the target's PL spectrum; the sphere carrying c, PL (:class:`MeshModel`) and
   harmonic (log c expanded to degree La, :class:`LogHarmonicModel`: positive by construction, whatever the range
   of c); the fitted ρ (step 5); the re-embedded meshes.
4. Re-embedding of c (:func:`~shspec.embed.embed`), its edge-length error, folds, self-intersections, bump/dip
   ambiguity, Hausdorff/Chamfer distance to the target after rigid alignment, and the factor error of the
   re-embedded mesh: its own cMCF factors against the target's, as rotation-invariant per-degree power and after
   Möbius + O(3) alignment (:func:`shspec.inverse.align`).
5. The inverse fit (:func:`shspec.inverse.fit`, log-ρ model) of the target's PL spectrum with its errors; the fitted
   ρ against c at the cMCF vertices after alignment (:func:`~shspec.inverse.output.surface_record`: factor error,
   log correlation, the floor beside them), the error bar and the predicted error; and the re-embedding of the
   fitted factors.  The step is "ok" only when the fit reaches its target within the target's errors; where the plan
   shows that the basis cannot represent c (factors spanning decades), it is not attempted and the status says,
   in one line, what it would take.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..core.atomic import atomic_outputs, save_figure, write_text
from ..core.checks import check_float, check_int, check_options
from ..core.parallel import make_executor, stop_executor
from ..embed.ambiguity import AmbiguityReport, detect_ambiguity
from ..embed.render import render_mesh
from ..embed.distances import SurfaceDistance, surface_distance
from ..embed.embed import EmbedOptions, EmbedResult, embed
from ..errors import InvalidArgumentError, NotPositiveError, ShspecError
from ..galerkin.log_model import LogHarmonicModel
from ..galerkin.truncation import basis_degree_for
from ..inverse import FitOptions, align, fit
from ..inverse.output import success_definition, surface_record
from ..fitting.surface_plan import DEFAULT_ACCURACY, TRUTH_DEGREE, default_numeig, log_floor, plan_surface_fit
from ..core.outputs import ensure_directory
from ..mesh.bridge import fit_harmonic, mesh_band_limit
from ..mesh.cmcf import CMCFResult, cmcf
from ..mesh.eigen import mesh_spectrum
from ..mesh.model import MeshModel
from ..mesh.plot import plot_hammer
from ..mesh.mesh_files import save_mesh
from ..mesh.triangle_mesh import TriangleMesh
from ..report import validation_markdown
from ..sphere.evaluate import sample_harmonic
from ..sphere.rotate import power_spectrum
from ..sphere.harmonics import vector_to_cilm
from ..fitting.targets import mesh_target, refined_target

__all__ = ["ValidationOptions", "ValidationResult", "validate_target", "write_report", "SPECTRUM_LABELS"]

#: What each spectrum of a validation is, as figure legends say it.
SPECTRUM_LABELS = {"target_pl": "target mesh, refined by subdivision (cotan)",
                   "cmcf_pl": "cMCF sphere with its factors (cotan)",
                   "cmcf_harmonic": "cMCF factors, log expanded (Galerkin)", "embedded_pl": "re-embedded cMCF factors",
                   "fit_harmonic": "fitted log rho (Galerkin)", "fit_embedded_pl": "re-embedded fitted factors"}


@dataclass(frozen=True)
class ValidationOptions:
    """Options of :func:`validate_target`.

    Attributes
    ----------
    numeig : int or None
        Eigenvalues K compared and fitted (λ₀ = 0 included); None: planned (from
        :func:`~shspec.fitting.surface_plan.default_numeig`).
    lmax, lmax_factor : int or None
        Harmonic basis degree Lb and log-ρ degree La; None: planned.
    accuracy : float
        Relative L2 error of ρ the plan aims for.
    fit : bool
        Run the inverse fit.
    fit_starts : int
        Random starts of the fit, stopped at the first success.
    fit_workers : int
        Processes the starts run on at once (1: here, one after the other; the command line's default is one per
        start and usable core).  A process pool re-imports the calling script: guard it with
        ``if __name__ == "__main__":``.
    ambiguity : bool
        Run the bump/dip test on the re-embedding.
    embed : EmbedOptions
        Options of every re-embedding.
    """

    numeig: int | None = None
    lmax: int | None = None
    lmax_factor: int | None = None
    accuracy: float = DEFAULT_ACCURACY
    fit: bool = True
    fit_starts: int = 1
    fit_workers: int = 1
    ambiguity: bool = True
    embed: EmbedOptions = field(default_factory=EmbedOptions)

    def __post_init__(self):
        for name in ("numeig", "lmax", "lmax_factor"):
            if getattr(self, name) is not None:
                check_int(getattr(self, name), f"ValidationOptions.{name}", minimum=2 if name == "numeig" else 1)
        check_int(self.fit_starts, "ValidationOptions.fit_starts", minimum=1)
        check_int(self.fit_workers, "ValidationOptions.fit_workers", minimum=1)
        check_float(self.accuracy, "ValidationOptions.accuracy", positive=True)
        if not isinstance(self.embed, EmbedOptions):
            raise InvalidArgumentError("ValidationOptions.embed must be EmbedOptions")


@dataclass(frozen=True)
class ValidationResult:
    """Result of :func:`validate_target`.

    Attributes
    ----------
    name : str
    target : TriangleMesh
    flow : CMCFResult
    spectra : dict of str to (k,) array
        Eigenvalues per source (only the sources that ran).
    status : dict of str to str
        "ok", or "skipped: reason", per step.
    embedding : EmbedResult
        Re-embedding of the cMCF factors.
    distance : SurfaceDistance
    ambiguity : AmbiguityReport or None
    fit_embedding : EmbedResult or None
        Re-embedding of the fitted factors.
    fit_distance : SurfaceDistance or None
    summary : dict
        JSON-ready numbers (see :func:`write_report`).
    """

    name: str
    target: TriangleMesh = field(repr=False)
    flow: CMCFResult = field(repr=False)
    spectra: dict = field(repr=False)
    status: dict
    embedding: EmbedResult = field(repr=False)
    distance: SurfaceDistance
    ambiguity: AmbiguityReport | None = field(repr=False)
    fit_embedding: EmbedResult | None = field(repr=False)
    fit_distance: SurfaceDistance | None
    summary: dict = field(repr=False)


def _factor_comparison(sphere_a, c_a, sphere_b, c_b, la):
    """Relative per-degree power error and aligned L2 error of two per-vertex factor fields."""
    a = fit_harmonic(sphere_a, c_a, la).coefficients
    b = fit_harmonic(sphere_b, c_b, la).coefficients
    pa, pb = power_spectrum(a), power_spectrum(b)
    out = {"power_error": float(np.linalg.norm(pa - pb) / np.linalg.norm(pb))}
    try:
        out["aligned_l2_error"] = float(align(a, b).relative_error)
    except ShspecError as exc:
        # Möbius centering needs ρ > 0; a band-limited expansion of extreme factors (the bunny's) is not.
        out["aligned_l2_error"] = None
        out["aligned_l2_error_skipped"] = str(exc)
    return out


def validate_target(mesh: TriangleMesh, options: ValidationOptions | None = None, *, name: str = "target",
                    log=None) -> ValidationResult:
    """Run the validation pipeline on a target mesh (see the module notes).

    Parameters
    ----------
    mesh : TriangleMesh
        Closed genus-0 target, n vertices.
    options : ValidationOptions, optional
    name : str
        Name used in the report.
    log : callable, optional
        Called with one progress string per step (e.g. ``print``).

    Returns
    -------
    ValidationResult

    Raises
    ------
    MeshError
        If the target is not a closed manifold genus-0 mesh.
    """
    opt = check_options(options, ValidationOptions)
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    run = _Run(mesh, opt, name, log if log is not None else (lambda _msg: None))
    flow = run.timed("cmcf", cmcf, mesh)
    run.status["cmcf"] = "ok" if flow.success else "ok (not converged)"
    run.say(f"cMCF: {flow.iterations} steps, roundness {flow.roundness:.2e}, {run.times['cmcf']:.1f} s")
    target, plan, la, lb = run.timed("plan", _planned_target, run, flow)
    floor = _reference_spectra(run, flow, target, la, lb)
    emb, dist, amb = _embedding(run, flow)
    re_flow = run.timed("factor_errors", cmcf, emb.mesh)
    factor_errors = {"embedded_vs_cmcf": _factor_comparison(re_flow.sphere, re_flow.factors, flow.sphere,
                                                            flow.factors, la)}
    fit_info, fit_emb, fit_dist = _fitted(run, flow, target, plan, la, lb)
    summary = _summary(run, flow, target, plan, (la, lb, floor), (emb, dist, amb), (fit_info, fit_emb, fit_dist),
                       factor_errors)
    return ValidationResult(name=name, target=mesh, flow=flow, spectra=run.spectra, status=run.status,
                            embedding=emb, distance=dist, ambiguity=amb, fit_embedding=fit_emb,
                            fit_distance=fit_dist, summary=summary)


@dataclass
class _Run:
    """A validation as it runs: its mesh, options and name, what it says, and what each step has found."""

    mesh: TriangleMesh
    opt: ValidationOptions
    name: str
    say: object
    status: dict = field(default_factory=dict)
    spectra: dict = field(default_factory=dict)
    times: dict = field(default_factory=dict)
    start: float = field(default_factory=time.perf_counter)

    def timed(self, step: str, function, *args):
        t = time.perf_counter()
        out = function(*args)
        self.times[step] = time.perf_counter() - t
        return out


def _planned_target(run: _Run, flow: CMCFResult):
    """The refined PL target cut to its K, with its plan (None when La and K are given), La and Lb."""
    opt, mesh = run.opt, run.mesh
    k0 = min(opt.numeig or default_numeig(mesh.nvertices), mesh.nvertices - 1)
    target = refined_target(mesh_target(mesh, 30, k0, TRUTH_DEGREE, source="pl", name=run.name, flow=flow))
    if opt.lmax_factor is not None or opt.numeig is not None:
        la = mesh_band_limit(mesh.nvertices, opt.lmax_factor or 8)
        return target.first(k0), None, la, opt.lmax or max(basis_degree_for(k0, la), 16)
    plan = plan_surface_fit(target, accuracy=opt.accuracy)
    run.say(plan.statement())
    return plan.fitted_target(target), plan, plan.lmax_factor, plan.lmax


def _reference_spectra(run: _Run, flow: CMCFResult, target, la: int, lb: int) -> float:
    """The target's spectrum and those of its cMCF factors (PL, and log-harmonic of degree La); the floor of La."""
    k = target.numeig
    run.spectra["target_pl"] = target.eigenvalues
    run.spectra["cmcf_pl"] = MeshModel(flow.sphere).spectrum(flow.factors, k).eigenvalues
    log_c, floor = log_floor(flow.sphere, flow.factors, la)
    run.spectra["cmcf_harmonic"] = LogHarmonicModel(lb, la).eigenvalues(log_c, k)
    run.status["cmcf_harmonic"] = "ok"
    run.say(f"spectra: target, cMCF PL, cMCF log-harmonic (La = {la}: floor {floor:.2g})")
    return floor


def _embedding(run: _Run, flow: CMCFResult):
    """The cMCF factors re-embedded, its distance to the target, its spectrum and the bump/dip ambiguity."""
    opt = run.opt
    emb = embed(flow.sphere, flow.factors, opt.embed)
    run.times["embed"] = emb.seconds
    run.status["embed"] = "ok" if emb.success else "ok (not successful: see flags)"
    run.say(f"re-embedding: rms edge error {emb.edge_error_rms:.3g}, {emb.seconds:.1f} s")
    dist = surface_distance(emb.mesh, run.mesh)
    k = run.spectra["target_pl"].size
    run.spectra["embedded_pl"] = mesh_spectrum(emb.mesh, k, whole_multiplets=False).eigenvalues
    amb = detect_ambiguity(flow.sphere, emb, embed_options=opt.embed) if opt.ambiguity else None
    run.status["ambiguity"] = "ok" if opt.ambiguity else "skipped: disabled"
    return emb, dist, amb


def _fitted(run: _Run, flow: CMCFResult, target, plan, la: int, lb: int):
    """The log-rho fit of the target and its re-embedding: (fit record, EmbedResult or None, distance or None)."""
    out = {}, None, None
    if not run.opt.fit:
        run.status["fit"] = "skipped: disabled"
    elif plan is not None and plan.beyond_basis:
        run.status["fit"] = f"not attempted: {plan.diagnosis()}"
    else:
        try:
            out = _fit_and_embed(run, flow, target, plan, la, lb)
        except ShspecError as exc:
            run.status["fit"] = f"failed: {exc}"
    run.say(f"fit: {run.status['fit']}")
    return out


def _fit_and_embed(run: _Run, flow: CMCFResult, target, plan, la: int, lb: int):
    workers = min(run.opt.fit_workers, run.opt.fit_starts)
    executor = make_executor(workers) if workers > 1 else None
    try:
        result = run.timed("fit", lambda: fit(target, LogHarmonicModel(lb, la),
                                              FitOptions(starts=run.opt.fit_starts, progress=False),
                                              executor=executor))
    finally:
        if executor is not None:
            stop_executor(executor)  # starts a success made unneeded are not waited for
    best, k = result.best, target.numeig
    run.spectra["fit_harmonic"] = result.model.eigenvalues(best.params, k)
    info = {"seconds": run.times["fit"], "residual_chi2_reached": best.success,
            "error_bar": result.identifiability().noise_error, **(surface_record(result) or {})}
    if plan is not None:
        info["predicted_error"] = plan.predicted
    verdict = ("ok" if best.success else "failed: the fitted spectrum does not reach the target within its "
               f"errors ({success_definition(result)} does not hold)")
    try:
        aligned = result.alignment().aligned
    except NotPositiveError as exc:  # the fit stands; what cannot be made is its comparison with the factors
        which = _not_positive(target.truth, f"the cMCF factors' expansion of degree {target.truth.lmax}",
                              result.factor(), "the fitted rho's harmonic expansion")
        run.status["fit"] = (f"{verdict}; its alignment with the cMCF factors and its re-embedding skipped: {which} "
                             f"is not positive, so it cannot be Moebius-centred ({exc})")
        return info, None, None
    info["rho_cilm"] = vector_to_cilm(aligned).tolist()  # the fitted rho, aligned with the cMCF factors
    c_fit = sample_harmonic(aligned, flow.sphere.vertices)
    if np.any(c_fit <= 0):
        run.status["fit"] = f"{verdict}; embedding skipped: the fitted factor is not positive at every vertex"
        return info, None, None
    fit_emb = embed(flow.sphere, c_fit, run.opt.embed)
    fit_dist = surface_distance(fit_emb.mesh, run.mesh)
    run.spectra["fit_embedded_pl"] = mesh_spectrum(fit_emb.mesh, k, whole_multiplets=False).eigenvalues
    run.status["fit"] = verdict
    return info, fit_emb, fit_dist


def _not_positive(first, first_name: str, second, second_name: str) -> str:
    """The name of the first of two harmonic ρ that is not positive on the sphere."""
    try:
        first.check_positive()
    except NotPositiveError:
        return first_name
    return second_name


def _summary(run: _Run, flow, target, plan, degrees, embedding, fitted, factor_errors) -> dict:
    """The JSON-ready numbers of a validation (:func:`write_report`)."""
    (la, lb, floor), (emb, dist, amb), (fit_info, fit_emb, fit_dist) = degrees, embedding, fitted
    lam0, mesh = run.spectra["target_pl"], run.mesh
    return {
        "name": run.name, "nvertices": mesh.nvertices, "nfaces": mesh.nfaces, "numeig": target.numeig, "lmax": lb,
        "lmax_factor": la, "plan": None if plan is None else plan.to_dict(),
        "target_errors": [float(x) for x in target.errors],
        "hausdorff_relative": dist.hausdorff_relative, "chamfer_relative": dist.chamfer_relative,
        "edge_length_error": emb.edge_error_rms, "edge_length_error_max": emb.edge_error_max,
        "folded_faces": emb.folded_faces, "self_intersections": emb.self_intersections,
        "embed_success": emb.success, "embed_steps": emb.steps, "embed_iterations": emb.iterations,
        "embed_seconds": emb.seconds, "reflected": dist.reflected,
        "cmcf": {"iterations": flow.iterations, "roundness": flow.roundness, "success": flow.success,
                 "factor_min": float(flow.factors.min()), "factor_max": float(flow.factors.max()),
                 "log_floor": floor},
        "spectral_error": {key: float(np.max(np.abs(v[1:] / lam0[1:] - 1))) for key, v in run.spectra.items()
                           if key != "target_pl"},
        "spectra": {key: v.tolist() for key, v in run.spectra.items()},
        "factor_errors": factor_errors, "fit": fit_info, "status": run.status,
        "ambiguity": None if amb is None else {
            "candidates": amb.candidates, "ambiguous": amb.ambiguous,
            "caps": [{"kind": c.kind, "area_fraction": c.area_fraction, "rms_original": c.rms_original,
                      "rms_mirrored": c.rms_mirrored, "ambiguous": c.ambiguous} for c in amb.caps]},
        "fit_embedding": None if fit_emb is None else {
            "edge_length_error": fit_emb.edge_error_rms, "hausdorff_relative": fit_dist.hausdorff_relative,
            "chamfer_relative": fit_dist.chamfer_relative, "success": fit_emb.success},
        "embed_options": asdict(run.opt.embed), "seconds": {**run.times, "total": time.perf_counter() - run.start},
    }


#: Colours of ambiguity.png, by category: not tested, decided, ambiguous (the legend and the table's words).
AMBIGUITY_COLOURS = ("#d9d9d9", "tab:blue", "tab:red")


def _ambiguity_figure(result, amb, up: str):
    """The re-embedded mesh with each tested cap coloured by the verdict of the table (summary.json "ambiguity"):
    one fixed colour per category, so that the legend cannot disagree with the table whatever the caps are."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    label = np.zeros(result.target.nvertices)
    for cap in amb.caps:  # where caps overlap, "ambiguous" wins, as it does for the surface
        label[cap.vertices] = np.maximum(label[cap.vertices], 2.0 if cap.ambiguous else 1.0)
    n_amb = sum(cap.ambiguous for cap in amb.caps)
    # one category per face (the highest of its vertices): a mean would paint a cap's rim in another category
    face_label = label[result.embedding.mesh.faces].max(axis=1)
    fig = render_mesh(result.embedding.mesh, values=face_label, cmap=ListedColormap(AMBIGUITY_COLOURS), vmin=0.0,
                      vmax=2.0, up=up, title=f"{len(amb.caps)} tested caps: {n_amb} ambiguous, "
                      f"{len(amb.caps) - n_amb} decided")
    fig.legend(handles=[Patch(color=c, label=t) for c, t in
                        zip(AMBIGUITY_COLOURS, ("not tested", "decided", "ambiguous"))],
               loc="lower center", ncol=3, fontsize="small", frameon=False)
    return fig


def _spectra_figure(result: ValidationResult):
    """Every spectrum of the validation, and its relative difference from the target's, side by side."""
    import matplotlib.pyplot as plt

    lam0 = result.spectra["target_pl"]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.6))
    for n, (key, lam) in enumerate(result.spectra.items()):
        # one colour and one readable name per source, the same in both panels; the spectra nearly coincide on the
        # left, so the target is drawn as dots and the others as thin lines over it
        target = key == "target_pl"
        style = dict(color=f"C{n}", label=SPECTRUM_LABELS.get(key, key))
        a1.plot(lam, "o" if target else "-", ms=3, lw=0.8, zorder=1 if target else 2, **style)
        if not target:
            a2.semilogy(np.arange(1, lam.size), np.maximum(np.abs(lam[1:] / lam0[1:] - 1), 1e-300), ".-", ms=3,
                        lw=0.8, **style)
    a1.set(xlabel="index i", ylabel="λ_i (1/area)", title="the spectra")
    a2.set(xlabel="index i", ylabel="|λ_i / λ_i(target) − 1|", title="their difference from the target's")
    # one legend for both panels, below them: inside, it covered the data
    fig.legend(*a1.get_legend_handles_labels(), loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    return fig


#: What :func:`write_report` writes into its folder.
REPORT_OUTPUTS = ("summary.json", "report.md", "meshes.png", "embedded.obj", "fit_embedded.obj", "ambiguity.png",
                  "factors.png", "spectra.png")


def write_report(result: ValidationResult, out_dir, *, up: str = "z", dpi: int = 90) -> Path:
    """Write ``summary.json`` (with the fitted ρ's cilm, ``fit.rho_cilm``), ``report.md``, the PNG figures and the
    re-embedded meshes (``embedded.obj`` of the cMCF factors, ``fit_embedded.obj`` of the fitted ones, in the
    re-embedding's frame) of a validation to ``out_dir``.

    Parameters
    ----------
    result : ValidationResult
    out_dir : path
        Created if needed.
    up : {"x", "y", "z"}
        Vertical axis of the mesh renderings.
    dpi : int
        Resolution of the PNGs.

    Returns
    -------
    Path
        The path of ``report.md``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not isinstance(result, ValidationResult):
        raise InvalidArgumentError(f"expected a ValidationResult, got {type(result).__name__}")
    out = ensure_directory(out_dir)
    # one unit: a failed write leaves the folder's previous report whole (shspec.core.atomic.atomic_outputs)
    with atomic_outputs(out, replaces=REPORT_OUTPUTS) as files:
        s = result.summary
        write_text(files.path("summary.json"), json.dumps(s, indent=1))

        aligned = result.target.with_vertices(result.embedding.mesh.vertices @ result.distance.transform[:3, :3].T
                                              + result.distance.transform[:3, 3])
        meshes = [(result.target, "target"), (aligned, "re-embedded cMCF factors")]
        if result.fit_embedding is not None:
            T = result.fit_distance.transform
            meshes.append((result.target.with_vertices(result.fit_embedding.mesh.vertices @ T[:3, :3].T + T[:3, 3]),
                           "re-embedded fitted factors"))
        fig = plt.figure(figsize=(4.5 * len(meshes), 4.5))
        for i, (m, title) in enumerate(meshes):
            render_mesh(m, ax=fig.add_subplot(1, len(meshes), i + 1, projection="3d"), title=title, up=up)
        save_figure(fig, files.path("meshes.png"), dpi=dpi, bbox_inches="tight")
        plt.close(fig)
        save_mesh(result.embedding.mesh, files.path("embedded.obj"))
        if result.fit_embedding is not None:
            save_mesh(result.fit_embedding.mesh, files.path("fit_embedded.obj"))

        amb = result.ambiguity
        if amb is not None and amb.caps:
            fig = _ambiguity_figure(result, amb, up)
            save_figure(fig, files.path("ambiguity.png"), dpi=dpi, bbox_inches="tight")
            plt.close(fig)

        # the factors themselves on a log scale: the bar reads in c, and says how far the clipped extremes go
        fig = plot_hammer(result.flow.sphere, result.flow.factors, log=True, title="cMCF factors c",
                          label="conformal factor c (log scale)")
        save_figure(fig, files.path("factors.png"), dpi=dpi, bbox_inches="tight")
        plt.close(fig)

        fig = _spectra_figure(result)
        save_figure(fig, files.path("spectra.png"), dpi=dpi, bbox_inches="tight")
        plt.close(fig)

        write_text(files.path("report.md"), validation_markdown(s))
    return out / "report.md"
