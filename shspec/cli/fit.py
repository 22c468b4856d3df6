"""``shspec fit``: recover a conformal factor from a spectrum (a thin layer over :func:`shspec.inverse.fit`).

The defaults are those of :class:`~shspec.inverse.FitOptions`, so the command line and the library give the same
fit; the discretizations it can fit are listed in ``MODELS``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import h5py
import numpy as np

from ..atomic import write_text
from ..checks import real_array
from ._common import whole_number
from ..errors import BeyondBasisError, InvalidArgumentError, OutputError
from ..galerkin import HarmonicModel, LogHarmonicModel
from .help_format import HelpFormatter
from ..inverse.identifiability import identifiability
from ..inverse.planning import plan_fit
from ..inverse.surface_plan import TRUTH_DEGREE, default_numeig, plan_surface_fit
from ..inverse.checkpoint import claim_checkpoint
from ..inverse.multistart import fit
from ..inverse.options import AREA_MODES, OPTIMIZERS, WEIGHTINGS, FitOptions
from ..inverse.output import alignment_record, success_definition, write_result
from ..inverse.schedule import (DEFAULT_STAGE_MAX_ITER, default_hop_degree, degree_ramp, numeig_ramp,
                               parse_schedule)
from ..targets import (TARGET_SOURCES, Target, check_target_text, parse_target, read_spectrum, refined_target,
                       subdivision_changes, subdivision_spectra)
from ..mesh.model import REGULARIZER_KINDS, MeshModel
from ..mesh.mesh_files import load_mesh
from ..mesh.progress import mesh_progress
from ..mesh.refine import eigenvalue_errors, trusted_numeig
from ..pipeline.adaptive import AdaptiveOptions, adaptive_fit
from ..parallel import make_executor, stop_executor, usable_cores
from ..spectral.topology import check_genus_zero
from ..sphere.factor import ConformalFactor
from ..sphere.harmonics import as_coefficients
from ..sphere.random import random_centred_coefficients


def _harmonic(args, target: Target) -> HarmonicModel:
    return HarmonicModel(args.lmax, args.lmax_factor)


def _log_harmonic(args, target: Target) -> LogHarmonicModel:
    return LogHarmonicModel(args.lmax, args.lmax_factor)


def _mesh(args, target: Target) -> MeshModel:
    if target.sphere is None:
        raise InvalidArgumentError("--model mesh needs a mesh target (star:... or mesh:...): it fits per-vertex "
                                   "factors on the target's cMCF sphere")
    return MeshModel(target.sphere, lmax_factor=args.lmax_factor, transform="exp" if args.log_factors else "identity",
                     reg_kind=args.reg_kind)


def _read_values(path: Path, what: str) -> np.ndarray:
    """The array of a parameter file: a fit's ``result.h5`` (its solution) or ``summary.json`` (its cilm), a
    ``.npy`` array, or text with one value per line."""
    try:
        if path.suffix == ".h5":
            with h5py.File(path, "r") as f:
                value = f["solution"][()]
        elif path.suffix == ".json":
            value = np.array(json.loads(path.read_text())["cilm"], dtype=float)
        elif path.suffix == ".npy":
            value = np.load(path, allow_pickle=False)
        else:
            value = np.loadtxt(path, ndmin=1)
    except (OSError, KeyError, ValueError, TypeError, EOFError) as exc:
        raise InvalidArgumentError(f"cannot read {what} from {path}: {exc or type(exc).__name__}") from None
    return value


def read_initial(path: Path, model) -> np.ndarray:
    """A starting point for ``model`` from a file (:func:`_read_values`' formats).  Harmonic coefficients (flat or
    cilm) are zero-padded to the model's La; coefficients above it must be 0.

    Raises
    ------
    InvalidArgumentError
        If the file cannot be read or does not fit the model.
    """
    value = _read_values(path, "a starting point")
    if isinstance(model, (HarmonicModel, LogHarmonicModel)):  # the log model's parameters are log rho's coefficients
        a = as_coefficients(value)
        if a.size > model.nparams and np.any(a[model.nparams:] != 0):
            raise InvalidArgumentError(f"the starting rho in {path} has degree > La = {model.lmax_factor}")
        out = np.zeros(model.nparams)
        out[:min(a.size, out.size)] = a[:out.size]
        return out
    value = real_array(value, f"the starting point in {path}").ravel()
    if value.shape != (model.nparams,):
        raise InvalidArgumentError(f"{path} holds {value.size} values; the mesh model has {model.nparams} vertices")
    return value


def read_truth(path: Path) -> ConformalFactor:
    """The true rho of a target, from harmonic coefficients (flat or cilm) in any of :func:`_read_values`' formats.

    Raises
    ------
    InvalidArgumentError, NotPositiveError
        If the file cannot be read, holds no harmonic coefficients, or its rho is not positive.
    """
    rho = ConformalFactor(as_coefficients(_read_values(path, "the true rho")), name=f"truth ({path.name})")
    rho.check_positive()
    return rho


#: The discretizations ``--model`` chooses from: name -> builder(args, target).
MODELS = {"harmonic": _harmonic, "log": _log_harmonic, "mesh": _mesh}


def register(subparsers) -> None:
    """Add ``fit`` to the shspec command line."""
    d = FitOptions()
    p = subparsers.add_parser(
        "fit", help="fit a conformal factor rho to a target spectrum (the inverse problem)",
        formatter_class=HelpFormatter, usage="shspec fit --target TARGET --out DIR [options]",
        description="Fit rho to a target spectrum from several random starts and write result.h5, summary.json "
        "and figures to DIR. The common case needs only --target and --out; the user guide explains the search.")
    p.add_argument("--target", required=True,
                   help="blob | star:l,m,p | mesh:PATH or a shipped mesh (mesh:spot_600) | spectrum:FILE")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory (created)")
    p.add_argument("--model", choices=tuple(MODELS), default=None, metavar="MODEL",
                   help="harmonic: rho's coefficients; log: log rho's; mesh: per-vertex factors (default: log for "
                   "mesh targets, else harmonic)")
    p.add_argument("--lmax-factor", type=whole_number(1, "the degree La of rho; at 0 rho is constant, a round sphere"),
                   default=None, metavar="La", help="degree La of rho (default: planned for mesh targets, else 15)")
    p.add_argument("--lmax", type=int, default=None, metavar="Lb", help="basis degree Lb (default: planned; 30 with --numeig)")
    p.add_argument("--numeig", type=_numeig, default=None, metavar="K",
                   help="eigenvalues matched, with lambda_0: a number, or 'auto'/'all' for meshes (default: planned)")
    p.add_argument("--reg", type=float, default=None, metavar="R",
                   help=f"penalty weight R (default: {MESH_REG:g} mesh fits, else {d.reg:g})")
    p.add_argument("--starts", type=int, default=d.starts, metavar="N", help="random starts")
    p.add_argument("--seed", type=int, default=d.seed, metavar="S", help="random seed")
    p.add_argument("--truth", type=Path, default=None, metavar="FILE",
                   help="the true rho's coefficients: report the error")
    p.add_argument("--noise", type=float, default=None, metavar="REL",
                   help="relative error of each eigenvalue (default: a file's error column, else exact)")

    runs = p.add_argument_group("runs")
    runs.add_argument("--workers", type=int, default=None, metavar="N",
                      help="processes for the starts; 1: serial (default: one per start and core, 1 with "
                      "--checkpoint-every)")
    runs.add_argument("--scheduler", default=None, metavar="ADDRESS",
                      help="run the starts on a Dask cluster (shspec[dask])")
    runs.add_argument("--all-starts", action="store_true",
                      help="run every start (default: stop at a success)")
    runs.add_argument("--checkpoint-every", type=int, default=d.checkpoint_every, metavar="N",
                      help="write DIR/checkpoint.h5 every N iterations (0: never)")
    runs.add_argument("--resume", action="store_true", help="continue from DIR/checkpoint.h5 (which must exist)")
    runs.add_argument("--overwrite", action="store_true", help="discard the checkpoint of an earlier fit in DIR")
    runs.add_argument("--init", type=Path, default=None, metavar="FILE",
                      help="start from a result.h5, summary.json, .npy or text column")
    runs.add_argument("--quiet", action="store_true", help="no progress display")
    runs.add_argument("--allow-any-genus", action="store_true", help="fit a target whose heat trace says genus != 0")

    mesh = p.add_argument_group("mesh targets and mesh fits")
    mesh.add_argument("--source", choices=TARGET_SOURCES, default="pl", metavar="SRC",
                      help="a mesh target's spectrum: cotan (pl), of its cMCF sphere (cmcf), or harmonic")
    mesh.add_argument("--subdivisions", type=int, default=3, metavar="N", help="icosphere subdivisions of star targets")
    mesh.add_argument("--numeig-tol", type=float, default=0.01, metavar="TOL", help="relative eigenvalue error for --numeig auto")
    mesh.add_argument("--reg-kind", choices=REGULARIZER_KINDS, default="cotan-squared", metavar="KIND",
                      help="penalty of mesh fits: " + ", ".join(REGULARIZER_KINDS))
    mesh.add_argument("--log-factors", action=argparse.BooleanOptionalAction, default=True,
                      help="fit s = log c rather than c")
    mesh.add_argument("--adaptive", action="store_true", help="start from an icosphere and refine it as the fit goes")
    mesh.add_argument("--adaptive-start", type=int, default=2, metavar="N", help="icosphere subdivisions of the first stage")
    mesh.add_argument("--adaptive-growth", type=float, default=AdaptiveOptions.growth, metavar="X",
                      help="vertex count ratio between adaptive stages")

    adv = p.add_argument_group("advanced search (FitOptions)")
    adv.add_argument("--schedule", default="auto", metavar="S",
                     help="'auto', 'degree-ramp', 'ramp', 'none', or stages '2,4,8,15' / '6:16,6:64h' (L:K, h = hop)")
    adv.add_argument("--hop-degree", type=int, default=None, metavar="D",
                     help="degree whose stage hops in the degree ramp (0: none; default: 6 in fits of degree 10 "
                          "and more)")
    adv.add_argument("--basin-hops", type=int, default=d.basin_hops, metavar="N", help="accepted escape moves at most")
    adv.add_argument("--hop-grid", action=argparse.BooleanOptionalAction, default=d.hop_grid,
                     help="also try every degree block turned through the octahedral group")
    adv.add_argument("--hop-tries", type=int, default=d.hop_tries, metavar="N", help="moves refitted per hop at most")
    adv.add_argument("--hop-extend", type=int, default=d.hop_extend, metavar="N", help="iterations of a falling screen")
    adv.add_argument("--stage-basis-tol", type=_optional_tol, default=d.stage_basis_tol, metavar="TOL",
                     help="tolerance of early stages' bases ('none': on --lmax)")
    adv.add_argument("--search-basis-tol", type=_optional_tol, default=d.search_basis_tol, metavar="TOL",
                     help="the same for the last stage's search, polished on --lmax ('none': all on --lmax)")
    adv.add_argument("--optimizer", choices=OPTIMIZERS, default=None, metavar="NAME",
                     help=f"{', '.join(OPTIMIZERS)} (default: the model's, lm or lbfgs)")
    adv.add_argument("--weights", choices=WEIGHTINGS, default=d.weights, metavar="W",
                     help="weights: " + ", ".join(WEIGHTINGS))
    adv.add_argument("--area", choices=AREA_MODES, default=d.area, metavar="MODE",
                     help="the area a_00: " + ", ".join(AREA_MODES))
    adv.add_argument("--max-iter", type=int, default=d.max_iter, metavar="N", help="iterations per stage")
    adv.add_argument("--amplitude", type=float, default=d.start_amplitude, metavar="A",
                     help="size of the random starts, relative to the mean of rho")
    p.set_defaults(func=_fit)


def _schedule(text: str, numeig: int, lmax_factor: int, hop_degree: int | None, harmonic: bool):
    if hop_degree is not None and (text not in ("auto", "degree-ramp") or not harmonic):
        raise InvalidArgumentError(f"--hop-degree shapes the degree ramp of a harmonic fit (--schedule auto or "
                                   f"degree-ramp); with --schedule {text!r} mark the stage to hop as 'L:Kh'")
    if text == "auto" and hop_degree is None:
        return None
    if text in ("auto", "degree-ramp"):
        return degree_ramp(numeig, lmax_factor, stage_max_iter=DEFAULT_STAGE_MAX_ITER,
                           hop_degree=default_hop_degree(lmax_factor) if hop_degree is None else hop_degree or None)
    if text == "none":
        return ()
    if text == "ramp":
        return numeig_ramp(numeig)
    return parse_schedule(text)


def _numeig(text: str):
    if text in ("auto", "all"):
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--numeig is an integer, 'auto' or 'all', got {text!r}") from None


def _optional_tol(text: str):
    if text.lower() == "none":
        return None
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a positive tolerance or 'none', got {text!r}")
    return value


def _auto_numeig(args, target: Target, changes=None) -> tuple[Target, dict]:
    """The target cut to the eigenvalues its mesh resolves to ``--numeig-tol`` (see ``--numeig``), and a report;
    ``changes``: the eigenvalues' changes under one subdivision when already computed (:func:`subdivision_changes`)."""
    if target.mesh is None:
        raise InvalidArgumentError("--numeig auto needs a mesh target (star:... or mesh:...)")
    n = target.mesh.nvertices
    where = "its cMCF sphere carrying the cMCF factors" if target.source == "cmcf" else "the target mesh"
    if changes is not None:
        err = changes
    elif target.source == "cmcf":
        err = subdivision_changes(target)
    else:  # a harmonic-source target too: the K its mesh resolves
        _, err = eigenvalue_errors(target.mesh, target.numeig)
    k = trusted_numeig(err, args.numeig_tol)
    report = {"chosen": k, "of": target.numeig, "tolerance": args.numeig_tol, "estimated_on": where,
              "estimate": "|lambda_i - lambda_i(4-to-1 subdivision)| / lambda_i",
              "largest_kept_error": float(err[1:k].max()),
              "first_dropped_error": float(err[k]) if k < err.size else None}
    print(f"--numeig auto: {k} of the first {target.numeig} eigenvalues of {where} ({n} vertices) have an estimated "
          f"discretization error <= {args.numeig_tol:g} (largest kept {report['largest_kept_error']:.2g}"
          + (f", next {err[k]:.2g})" if k < err.size else ")"), file=sys.stderr)
    cut = target.first(k)
    return cut, report


def _mesh_size(args) -> int:
    """Vertices of the mesh of a star:/mesh: target."""
    scheme, _, arg = args.target.partition(":")
    return load_mesh(arg).nvertices if scheme == "mesh" else 10 * 4 ** args.subdivisions + 2


def _plan(args) -> dict | None:
    """Fill in --numeig and --lmax where the user gave none (see --numeig); the plan's report, or None."""
    if args.numeig is not None:
        args.lmax = 30 if args.lmax is None else args.lmax
        return None
    if args.model == "mesh":
        # the study's share of the eigenvalues where a dense solve is cheap; beyond, those the mesh resolves
        n = _mesh_size(args) if _mesh_scheme(args) else 0
        args.numeig = max(2, round(MESH_NUMEIG_FRACTION * n)) if 0 < n <= MESH_FRACTION_VERTICES else "auto"
        args.lmax = 30 if args.lmax is None else args.lmax
        return None
    # the log model takes the plan of a harmonic rho of the same degree: the same number of unknowns
    plan = plan_fit(args.lmax_factor, random_centred_coefficients(args.seed, args.lmax_factor, 0.2))
    if plan.numeig is None:
        raise InvalidArgumentError(plan.statement() + "; give --numeig")
    args.numeig = plan.numeig
    args.lmax = plan.lmax if args.lmax is None else args.lmax
    if not args.quiet:
        print(f"--numeig not given: {plan.statement()}", file=sys.stderr)
    return {"numeig": plan.numeig, "lmax": args.lmax, **{k: v for k, v in plan.to_dict().items()
                                                         if k not in ("numeig", "lmax")}}


#: Default K of ``--model mesh``: this share of the vertices (the study's "e0.95": 570 of 600, 1140 of 1200) on
#: meshes of at most MESH_FRACTION_VERTICES vertices, and ``--numeig auto`` on larger ones.
MESH_NUMEIG_FRACTION = 0.95
MESH_FRACTION_VERTICES = 1500

#: Default R of ``--model mesh``: the study's regularized fit (Section 3.2.2, cotan-squared penalty).
MESH_REG = 0.05

def _mesh_scheme(args) -> bool:
    return args.target.partition(":")[0] in ("star", "mesh")


def _resolve_defaults(args) -> bool:
    """Fill in --model and, where it is not planned, --lmax-factor; whether the mesh target's fit is planned by
    :func:`plan_surface_fit` (a log fit of a mesh's cotan spectrum, neither La nor K given)."""
    if args.model is None:
        args.model = "log" if _mesh_scheme(args) else "harmonic"
    planned = (args.model == "log" and _mesh_scheme(args) and args.source in ("pl", "cmcf")
               and args.lmax_factor is None and args.numeig is None)
    if args.lmax_factor is None and not planned:
        args.lmax_factor = 15
    if args.reg is None:
        args.reg = MESH_REG if args.model == "mesh" else FitOptions().reg
    return planned


def _refined(target: Target, fine, quiet: bool) -> Target:
    """:func:`refined_target` of the subdivisions' spectra ``fine`` (levels, k), said on the console."""
    refined = refined_target(target, fine)
    if not quiet:
        rel = refined.errors[1:] / refined.eigenvalues[1:]
        how = ("those of its 4-to-1 subdivision" if len(fine) == 1 else
               f"extrapolated from {len(fine)} 4-to-1 subdivisions (Richardson)")
        print(f"the mesh target's eigenvalues are {how}, with an estimated discretization error of {rel.min():.1g} "
              f"to {rel.max():.1g} (relative): the fit weighs and stops by it", file=sys.stderr)
    return refined


def _subdivision_spectra(target: Target, quiet: bool) -> np.ndarray:
    """:func:`subdivision_spectra` (levels, k), with the mesh's progress on the console."""
    with mesh_progress(not quiet):
        return subdivision_spectra(target)


def _surface_target(args) -> tuple[Target, dict]:
    """The mesh target with its errors, cut to the K of :func:`plan_surface_fit`, whose La and Lb go into ``args``;
    and the plan's report.  Raises BeyondBasisError where the basis cannot represent the target's factors."""
    with mesh_progress(not args.quiet):
        target = parse_target(args.target, lmax=30, numeig=default_numeig(_mesh_size(args)), lmax_factor=TRUTH_DEGREE,
                              source=args.source, subdivisions=args.subdivisions)
    target = (target.with_noise(args.noise) if args.noise is not None
              else _refined(target, _subdivision_spectra(target, args.quiet), args.quiet))
    plan = plan_surface_fit(target)
    if not args.quiet:
        print(plan.statement(), file=sys.stderr)
    if plan.beyond_basis:
        raise BeyondBasisError(plan.diagnosis())
    if not plan.feasible:
        print(f"warning: {plan.diagnosis()}", file=sys.stderr)
    args.lmax_factor, args.lmax, args.numeig = plan.lmax_factor, plan.lmax, plan.numeig
    if not args.quiet:
        rel = plan.fit_errors[1:] / target.eigenvalues[1:plan.numeig]
        print(f"the fit is held to the target's errors and the misfit of the best degree-{plan.lmax_factor} expansion "
              f"of its cMCF factors: {rel.min():.1g} to {rel.max():.1g} (relative)", file=sys.stderr)
    return plan.fitted_target(target), {"surface_plan": plan.to_dict(), "expected_error": plan.predicted}


def _expected_error(args, model, target: Target) -> float:
    """Before fitting: the relative error of rho that the target's errors leave at a random start of the fit's law
    (:func:`~shspec.inverse.identifiability.identifiability` with them as noise), said and returned."""
    ref = model.random_start(np.random.default_rng([args.seed, 0]), args.amplitude, target.area_estimate())
    noise = np.r_[1.0, target.errors[1:] / target.eigenvalues[1:]]
    value = identifiability(model, ref, target.numeig, noise=noise).noise_error
    if not args.quiet:
        print(f"before fitting: the target's errors allow rho to about {value:.2g} (expected relative L2 error at a "
              "random start of the fit's law; more eigenvalues or smaller errors lower it)", file=sys.stderr)
    return value


def _where(args, options: FitOptions) -> tuple[int | None, str | None]:
    """(workers, scheduler) of :func:`~shspec.parallel.make_executor` for the starts: --scheduler; else --workers;
    else a local pool of one process per start and usable core, serial for one start, one core, or with
    --checkpoint-every (a pool checkpoints finished starts only)."""
    if args.scheduler is not None:
        return args.workers, args.scheduler
    if args.workers is not None:
        if args.workers > 1 and options.checkpoint_every and not args.quiet:
            print(f"note: on {args.workers} workers the checkpoint holds the finished starts only (--checkpoint-every "
                  "checkpoints inside a start with --workers 1)", file=sys.stderr)
        return args.workers, None
    return (1 if options.checkpoint_every else max(1, min(options.starts, usable_cores()))), None


def _fit(args) -> int:
    out: Path = args.out
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out} is a file; give a directory")
    claim_checkpoint(out / "checkpoint.h5", resume=args.resume, overwrite=args.overwrite)
    if args.numeig in ("auto", "all") and not _mesh_scheme(args):
        raise InvalidArgumentError(f"--numeig {args.numeig} needs a mesh target (star:... or mesh:...)")
    check_target_text(args.target)  # a typo is named now, not after a minute of planning
    extra = {}
    if _resolve_defaults(args):
        target, extra = _surface_target(args)
        planned = None
    else:
        target, planned = None, _plan(args)
    if planned is not None:
        extra["numeig_plan"] = planned
    auto = args.numeig == "auto"
    numeig = args.numeig
    if auto:
        numeig = default_numeig(_mesh_size(args))  # what --numeig auto considers
    elif numeig == "all":
        numeig = _mesh_size(args) - 1
    if target is None:
        with mesh_progress(not args.quiet):  # a large mesh target: its size, and progress through cMCF and eigenpairs
            target = parse_target(args.target, lmax=args.lmax, numeig=numeig, lmax_factor=args.lmax_factor,
                                  source=args.source, subdivisions=args.subdivisions)
    if args.truth is not None:
        target = dataclasses.replace(target, truth=read_truth(args.truth))
    changes = None
    if target.errors is not None:
        pass  # planned with its errors already
    elif args.noise is not None:
        target = target.with_noise(args.noise)
    elif target.source in ("pl", "cmcf") and args.model != "mesh":
        # a harmonic model hears the mesh's own discretization error too: fit to it, not below it
        fine = _subdivision_spectra(target, args.quiet)
        changes = subdivision_changes(target, fine[0])
        target = _refined(target, fine, args.quiet)
    if planned is not None and target.numeig < planned["numeig"]:
        print(f"warning: the target has only {target.numeig} eigenvalues; the plan asked for {planned['numeig']}",
              file=sys.stderr)
    if auto:
        with mesh_progress(not args.quiet):  # the 4-to-1 subdivision's eigenpairs
            target, extra["numeig_auto"] = _auto_numeig(args, target, changes)
    scheme, _, where = args.target.partition(":")
    if not args.allow_any_genus and scheme in ("spectrum", "mesh"):
        # the whole file, not only the K fitted: the heat trace needs many eigenvalues to be confident
        check_genus_zero(read_spectrum(where) if scheme == "spectrum" else target.eigenvalues, area=target.area)
    model = MODELS[args.model](args, target)
    if target.errors is not None and args.model != "mesh" and "expected_error" not in extra:
        extra["expected_error"] = _expected_error(args, model, target)
    if not args.log_factors and args.adaptive:
        raise InvalidArgumentError("--adaptive fits log factors (refinement follows log c); drop --no-log-factors")
    options = FitOptions(optimizer=args.optimizer, weights=args.weights, reg=args.reg, area=args.area,
                         schedule=_schedule(args.schedule, target.numeig, args.lmax_factor, args.hop_degree,
                                            args.model != "mesh"),
                         starts=args.starts, stop_at_success=not args.all_starts,
                         seed=args.seed, start_amplitude=args.amplitude, max_iter=args.max_iter,
                         basin_hops=args.basin_hops, hop_grid=args.hop_grid, hop_tries=args.hop_tries,
                         hop_extend=args.hop_extend,
                         stage_basis_tol=args.stage_basis_tol, search_basis_tol=args.search_basis_tol,
                         checkpoint_every=args.checkpoint_every,
                         checkpoint_path=str(out / "checkpoint.h5") if args.checkpoint_every or args.resume else None,
                         progress=not args.quiet)
    where = None if args.adaptive else _where(args, options)
    if not args.quiet:
        on = ("" if where is None or where == (1, None) else " on a Dask cluster" if where[1]
              else f" on {where[0]} processes")
        print(f"fitting {target.name}: {target.numeig} eigenvalues, {model.describe()}, {options.starts} starts{on}",
              file=sys.stderr)
    init = None if args.init is None else read_initial(args.init, model)
    if args.adaptive:
        if args.model != "mesh" or init is not None or args.workers or args.scheduler or args.resume:
            raise InvalidArgumentError("--adaptive is a mesh fit (--model mesh) without --init, --workers, "
                                       "--scheduler or --resume")
        adaptive = adaptive_fit(target, AdaptiveOptions(subdivisions=args.adaptive_start, growth=args.adaptive_growth,
                                                        reg_kind=args.reg_kind, fit=options),
                                log=None if args.quiet else (lambda msg: print(msg, file=sys.stderr)))
        result, extra["adaptive"] = adaptive.result, adaptive.to_dict()
    else:
        executor = make_executor(*where)
        try:
            result = fit(target, model, options, resume=args.resume, init=init, executor=executor)
        finally:
            stop_executor(executor)  # the starts a success made unneeded may still run: not waited for
    write_result(result, out)
    if extra:
        path = out / "summary.json"
        write_text(path, json.dumps({**json.loads(path.read_text()), **extra}, indent=2) + "\n")
    ident = result.identifiability()
    print(("warning: " if ident.underdetermined else "") + ident.statement(), file=sys.stderr)
    best = result.best
    stopped = "" if len(result.starts) == options.starts or result.interrupted else (
        f" (the fit stops at a success; --all-starts runs all {options.starts})")
    print(f"best start {best.index}: energy {best.energy:.3e}, max relative residual {best.relative_residual:.3e}; "
          f"{result.success_count}/{len(result.starts)} starts succeeded ({success_definition(result)}){stopped}; "
          f"{result.seconds:.1f} s; wrote {out}")
    aligned = alignment_record(result)  # computed once, by the summary already
    if aligned and "relative_error" in aligned:  # the truth is known (--truth, or a target that carries it)
        print(f"against the truth, after Moebius centering and the best element of O(3): relative L2 error of rho "
              f"{aligned['relative_error']:.2g}, of its per-degree power {aligned['power_error']:.2g}")
    return 130 if result.interrupted else 0
