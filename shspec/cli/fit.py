"""``shspec fit``: recover a conformal factor from a spectrum.

The command parses its arguments into a :class:`~shspec.fitting.FitRequest`, plans it with
:func:`~shspec.fitting.prepare_fit`, runs ``shspec.inverse.fit(plan)`` and writes the result: the calls a Python
user makes, with the same bits.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import OutputError
from ..fitting import FitRequest, prepare_fit
from ..fitting.adaptive import AdaptiveOptions
from ..fitting.plan import MESH_REG
from ..fitting.request import MODEL_KINDS
from ..fitting.targets import TARGET_SOURCES
from ..inverse.multistart import fit
from ..inverse.options import AREA_MODES, OPTIMIZERS, WEIGHTINGS, FitOptions
from ..inverse.output import (alignment_record, claim_output, rho_error, success_definition, surface_record,
                              write_result)
from ..mesh.model import REGULARIZER_KINDS
from ._common import whole_number
from .help_format import HelpFormatter


def _numeig(text: str):
    return text if text in ("auto", "all") else whole_number(2, "K counts lambda_0 = 0 too")(text)


def _degree(text: str):
    return text if text == "auto" else whole_number(1, "the degree La of rho; at 0 rho is constant, a round sphere")(text)


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


def _directory(text: str) -> Path:
    if not text.strip():  # Path("") is the current folder
        raise argparse.ArgumentTypeError("the output directory is empty; name one")
    return Path(text)


def register(subparsers) -> None:
    """Add ``fit`` to the shspec command line."""
    d = FitOptions()
    p = subparsers.add_parser(
        "fit", help="fit a conformal factor rho to a target spectrum (the inverse problem)",
        formatter_class=HelpFormatter, usage="shspec fit --target TARGET --out DIR [options]",
        description="Fit rho to a target spectrum from several random starts and write result.h5, summary.json "
        "and figures to DIR. The common case needs only --target and --out: the fit is planned, and says why.")
    p.add_argument("--target", required=True,
                   help="blob | star:l,m,p | mesh:PATH or a shipped mesh (mesh:spot_600) | spectrum:FILE")
    p.add_argument("--out", type=_directory, required=True, metavar="DIR", help="output directory (created)")
    p.add_argument("--model", choices=MODEL_KINDS, default=None, metavar="MODEL",
                   help="harmonic: rho's coefficients; log: log rho's; mesh: per-vertex factors (default: log for "
                   "mesh targets, else harmonic)")
    p.add_argument("--lmax-factor", type=_degree, default=None, metavar="La",
                   help="degree La of rho, or 'auto': the most K given supports (default: planned for meshes, else 15)")
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
    _add_run_options(p.add_argument_group("runs"), d)
    _add_mesh_options(p.add_argument_group("mesh targets and mesh fits"))
    _add_search_options(p.add_argument_group("advanced search (FitOptions)"), d)
    p.set_defaults(func=_fit)


def _add_run_options(runs, d: FitOptions) -> None:
    runs.add_argument("--workers", type=int, default=None, metavar="N",
                      help="processes for the starts; 1: serial (default: one per start and core, 1 with "
                      "--checkpoint-every)")
    runs.add_argument("--scheduler", default=None, metavar="ADDRESS", help="run the starts on a Dask cluster (shspec[dask])")
    runs.add_argument("--all-starts", action="store_true", help="run every start (default: stop at a success)")
    runs.add_argument("--checkpoint-every", type=int, default=d.checkpoint_every, metavar="N",
                      help="write DIR/checkpoint.h5 every N iterations (0: never)")
    runs.add_argument("--resume", action="store_true", help="continue from DIR/checkpoint.h5 (which must exist)")
    runs.add_argument("--overwrite", action="store_true", help="discard the checkpoint of an earlier fit in DIR")
    runs.add_argument("--init", type=Path, default=None, metavar="FILE",
                      help="start from a result.h5, summary.json, .npy or text column")
    runs.add_argument("--quiet", action="store_true", help="no progress display")
    runs.add_argument("--allow-any-genus", action="store_true", help="fit a target whose heat trace says genus != 0")
    runs.add_argument("--allow-short-spectrum", action="store_true", help="fit La with fewer eigenvalues than planned")


def _add_mesh_options(mesh) -> None:
    mesh.add_argument("--source", choices=TARGET_SOURCES, default="pl", metavar="SRC",
                      help="a mesh target's spectrum: cotan (pl), of its cMCF sphere (cmcf), or harmonic")
    mesh.add_argument("--subdivisions", type=int, default=3, metavar="N", help="icosphere subdivisions of star targets")
    mesh.add_argument("--numeig-tol", type=float, default=0.01, metavar="TOL", help="relative eigenvalue error for --numeig auto")
    mesh.add_argument("--reg-kind", choices=REGULARIZER_KINDS, default="cotan-squared", metavar="KIND",
                      help="penalty of mesh fits: " + ", ".join(REGULARIZER_KINDS))
    mesh.add_argument("--log-factors", action=argparse.BooleanOptionalAction, default=True,
                      help="fit s = log c rather than c")
    mesh.add_argument("--adaptive", action="store_true", help="fit from an icosphere refined as the fit goes")
    mesh.add_argument("--adaptive-start", type=int, default=2, metavar="N", help="icosphere subdivisions of the first stage")
    mesh.add_argument("--adaptive-growth", type=float, default=AdaptiveOptions.growth, metavar="X",
                      help="vertex count ratio between adaptive stages")


def _add_search_options(adv, d: FitOptions) -> None:
    adv.add_argument("--schedule", default="auto", metavar="S", help="auto, degree-ramp, parity-ramp, ramp, none, "
                     "or stages '2,4,8' / '6:16,6:64h,8:80e,8' (L:K, h: hops, e: odd degrees 0)")
    adv.add_argument("--start-budget", type=int, default=None, metavar="N",
                     help="end a failed start after N search iterations' work (0: never; default: 1500 at La 8, 9)")
    adv.add_argument("--hop-degree", type=int, default=None, metavar="D",
                     help="degree ramp hops at degree D (0: none; 6 from La 10)")
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
    adv.add_argument("--weights", choices=WEIGHTINGS, default=d.weights, metavar="W", help="weights: " + ", ".join(WEIGHTINGS))
    adv.add_argument("--area", choices=AREA_MODES, default=d.area, metavar="MODE", help="the area a_00: " + ", ".join(AREA_MODES))
    adv.add_argument("--max-iter", type=int, default=d.max_iter, metavar="N", help="iterations per stage")
    adv.add_argument("--amplitude", type=float, default=d.start_amplitude, metavar="A",
                     help="starts' RMS size relative to mean rho")


def _request(args) -> FitRequest:
    """The fit the arguments ask for."""
    checkpoint = args.out / "checkpoint.h5" if args.checkpoint_every or args.resume else None
    options = FitOptions(optimizer=args.optimizer, weights=args.weights, area=args.area, starts=args.starts,
                         start_budget=args.start_budget, stop_at_success=not args.all_starts, seed=args.seed,
                         start_amplitude=args.amplitude, max_iter=args.max_iter, basin_hops=args.basin_hops,
                         hop_grid=args.hop_grid, hop_tries=args.hop_tries, hop_extend=args.hop_extend,
                         stage_basis_tol=args.stage_basis_tol, search_basis_tol=args.search_basis_tol,
                         checkpoint_every=args.checkpoint_every,
                         checkpoint_path=None if checkpoint is None else str(checkpoint))
    adaptive = (AdaptiveOptions(subdivisions=args.adaptive_start, growth=args.adaptive_growth, reg_kind=args.reg_kind)
                if args.adaptive else None)
    return FitRequest(args.target, model=args.model, lmax_factor=args.lmax_factor, lmax=args.lmax, numeig=args.numeig,
                      noise=args.noise, truth=args.truth, reg=args.reg, source=args.source, init=args.init,
                      subdivisions=args.subdivisions, numeig_tol=args.numeig_tol, reg_kind=args.reg_kind,
                      log_factors=args.log_factors, adaptive=adaptive, schedule=args.schedule, options=options,
                      hop_degree=args.hop_degree, allow_any_genus=args.allow_any_genus, scheduler=args.scheduler,
                      allow_short_spectrum=args.allow_short_spectrum, progress=not args.quiet,
                      workers="auto" if args.workers is None else args.workers)


def _fit(args) -> int:
    out: Path = args.out
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out} is a file; give a directory")
    request = _request(args)  # a mistyped target or option is named before the folder is touched
    # held from before the plan to the last file: a second fit into the folder is refused at once
    with claim_output(out, resume=args.resume, overwrite=args.overwrite):
        plan = prepare_fit(request)
        if plan.workers not in (None, 1) and plan.options.checkpoint_every and not args.quiet:
            print(f"note: on {plan.workers} workers the checkpoint holds the finished starts only (--checkpoint-every "
                  "checkpoints inside a start with --workers 1)", file=sys.stderr)
        result = fit(plan, resume=args.resume)
        write_result(result, out)
    _report(result, out)
    return 130 if result.interrupted else 0


def _report(result, out: Path) -> None:
    """The fit's outcome on the console: what the spectrum determines, the best start, the error against a truth."""
    ident = result.identifiability()
    print(("warning: " if ident.underdetermined else "") + ident.statement(), file=sys.stderr)
    best, starts = result.best, result.options.starts
    # the progress lines count every start that ran; the result keeps those up to the race's winner
    stopped = "" if len(result.starts) == starts or result.interrupted else (
        f" (of {starts} asked, those kept up to the first success; --all-starts runs and keeps all)")
    print(f"best start {best.index}: energy {best.energy:.3e}, max relative residual {best.relative_residual:.3e}; "
          f"{result.success_count}/{len(result.starts)} starts succeeded ({success_definition(result)}){stopped}; "
          f"{result.seconds:.1f} s; wrote {out}")
    error = rho_error(ident, surface_record(result))
    value = "unknown" if error["value"] is None else f"about {error['value']:.2g}"
    print(f"rho: relative error {value} ({error['meaning'].removeprefix('unknown: ')})")
    aligned = alignment_record(result)  # computed once, by the summary already
    if aligned and "relative_error" in aligned:  # the truth is known (--truth, or a target that carries it)
        print(f"against the truth, after Moebius centering and the best element of O(3): relative L2 error of rho "
              f"{aligned['relative_error']:.2g}, of its per-degree power {aligned['power_error']:.2g}")
