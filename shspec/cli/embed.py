"""Re-embedding subcommands: ``shspec embed`` and ``shspec validate``."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..core.atomic import atomic_output_files, check_writable
from ..core.parallel import usable_cores
from ..embed.embed import EmbedOptions, embed
from ..errors import InvalidArgumentError, OutputError
from ..pipeline.validation import ValidationOptions, validate_target, write_report
from ..mesh.mesh_files import load_mesh, mesh_format, save_mesh
from ._common import load_numbers


def register(subparsers) -> None:
    """Add ``embed`` and ``validate`` to the shspec command line."""
    p = subparsers.add_parser("embed", help="re-embed per-vertex conformal factors of a sphere mesh in R^3",
                              description="Find vertex positions whose edge lengths are l_ij (c_i c_j)^(1/4) on a "
                              "unit-sphere mesh (e.g. sphere.obj and factors.txt written by 'shspec cmcf'); write "
                              "the mesh and a JSON summary (edge-length error, folds, self-intersections).")
    p.add_argument("sphere", type=Path, help="unit-sphere mesh file")
    p.add_argument("factors", type=Path, help="text file with one conformal factor per vertex")
    p.add_argument("--out", type=Path, required=True, help="output mesh file (.obj, .ply, .off, .stl)")
    p.add_argument("--steps", type=int, default=None, help="continuation steps (default: from the factor range)")
    p.add_argument("--pressure", type=float, default=EmbedOptions.pressure,
                   help=f"pressure prior (bumps outwards) (default {EmbedOptions.pressure:g})")
    p.add_argument("--smoothing", type=float, default=EmbedOptions.smoothing,
                   help=f"bi-Laplacian factor filter (default {EmbedOptions.smoothing:g})")
    p.add_argument("--summary", type=Path, default=None, metavar="FILE.json",
                   help="also write the JSON summary, with the inputs and options, to this file")
    p.set_defaults(func=_embed)

    q = subparsers.add_parser("validate", help="end-to-end validation of a target mesh (spectra, factors, "
                              "re-embedding) with a Markdown report",
                              description="cMCF of the target, spectra of target / cMCF factors (PL, harmonic) / "
                              "fitted factors / re-embedded meshes, factor errors, Hausdorff and Chamfer distances; "
                              "writes summary.json, report.md and PNG figures to DIR.")
    q.add_argument("--target", required=True, metavar="mesh:PATH", help="target, as mesh:PATH")
    q.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory (created)")
    q.add_argument("--numeig", type=int, default=None,
                   help="eigenvalues compared and fitted (default: planned from the target's errors)")
    q.add_argument("--lmax", type=int, default=None, help="harmonic basis degree Lb (default: planned)")
    q.add_argument("--lmax-factor", type=int, default=None, help="degree La of log rho (default: planned)")
    q.add_argument("--accuracy", type=float, default=ValidationOptions.accuracy,
                   help="relative error of rho the plan aims for (default %(default)g)")
    q.add_argument("--no-fit", action="store_true", help="skip the inverse fit")
    q.add_argument("--starts", type=int, default=None, metavar="N",
                   help="random starts of the fit, stopped at the first success (default: one per usable core)")
    q.add_argument("--workers", type=int, default=None, metavar="N",
                   help="processes the starts run on (default: one per start and usable core; 1: serial)")
    q.add_argument("--up", choices=("x", "y", "z"), default="z", help="vertical axis of the renderings (default z)")
    q.add_argument("--merge-vertices", action="store_true",
                   help="weld vertices at identical positions (a vertex soup; always done for STL)")
    q.set_defaults(func=_validate)


def _embed(args) -> int:
    # checked before the embedding, whose result would otherwise be lost
    mesh_format(args.out)
    if args.summary is not None and args.summary.resolve() == args.out.resolve():
        raise InvalidArgumentError(f"--summary and --out are the same file {args.out}")
    for path in (args.out, args.summary):
        if path is not None:
            check_writable(path)
    sphere = load_mesh(args.sphere, validate=False)
    factors = load_numbers(args.factors, "conformal factors of the vertices")
    res = embed(sphere, factors, EmbedOptions(steps=args.steps, pressure=args.pressure, smoothing=args.smoothing))
    summary = {"sphere": str(args.sphere), "factors": str(args.factors), "out": str(args.out),
               "steps_option": args.steps, "pressure": args.pressure, "smoothing": args.smoothing,
               "edge_length_error": res.edge_error_rms,
               "edge_length_error_max": res.edge_error_max, "folded_faces": res.folded_faces,
               "self_intersections": res.self_intersections, "steps": res.steps,
               "iterations": res.iterations, "factorizations": res.factorizations, "success": res.success,
               "seconds": res.seconds, "cpu_seconds": res.cpu_seconds}
    # one unit: a failed write leaves the mesh and the summary of an earlier run as they were
    with atomic_output_files([args.out] + ([args.summary] if args.summary is not None else [])) as files:
        save_mesh(res.mesh, files[0], file_type=args.out.suffix)
        if args.summary is not None:
            files[1].write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary))
    if not res.success:  # the exit code alone would leave the reader to decode the JSON
        why = [f"{what}" for what, bad in (
            (f"the Gauss-Newton iterations did not reach EmbedOptions.tol (edge-length error {res.edge_error_rms:.3g}"
             f" rms, {res.edge_error_max:.3g} max)", not res.converged),
            (f"{res.folded_faces} faces are folded", res.folded_faces > 0),
            (f"{res.self_intersections} pairs of faces intersect", res.self_intersections > 0)) if bad]
        print(f"shspec embed: the embedding failed: {'; '.join(why)}; {args.out} is written for inspection",
              file=sys.stderr)
    return 0 if res.success else 1


def _validate(args) -> int:
    scheme, _, path = args.target.partition(":")
    if scheme != "mesh" or not path:
        raise InvalidArgumentError(f"--target must be mesh:PATH, got {args.target!r}")
    if args.out.exists() and not args.out.is_dir():
        raise OutputError(f"--out {args.out} is a file; give a directory")
    mesh = load_mesh(Path(path), merge_vertices=args.merge_vertices or None)
    starts = args.starts if args.starts is not None else usable_cores()
    opt = ValidationOptions(numeig=args.numeig, lmax=args.lmax, lmax_factor=args.lmax_factor, accuracy=args.accuracy,
                            fit=not args.no_fit, fit_starts=starts,
                            fit_workers=args.workers if args.workers is not None else min(starts, usable_cores()))
    result = validate_target(mesh, opt, name=Path(path).stem, log=print)
    report = write_report(result, args.out, up=args.up)
    s = result.summary
    print(f"hausdorff_relative {s['hausdorff_relative']:.4g}  edge_length_error {s['edge_length_error']:.4g}  "
          f"report {report}")
    failed = {step: why for step, why in s["status"].items() if why.startswith("failed")}
    for step, why in s["status"].items():
        if why.startswith(("failed", "skipped", "not attempted")) and why != "skipped: disabled":
            print(f"shspec validate: step {step} {why}", file=sys.stderr)
    return 1 if failed else 0
