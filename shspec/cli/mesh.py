"""Mesh subcommands: ``shspec mesh-spectrum`` (one mesh, or many with ``--out``) and ``shspec cmcf``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..core.atomic import atomic_output, atomic_outputs, save_figure, write_text
from ..errors import InvalidArgumentError
from ..core.outputs import ensure_directory
from ..mesh.cmcf import CMCFOptions, cmcf
from ..mesh.cotan import MASS_KINDS
from ..mesh.eigen import mesh_spectrum
from ..mesh.mesh_files import load_mesh, save_mesh
from ..mesh.plot import plot_hammer
from ..core.parallel import make_executor
from ..spectral.batch import run_batch
from ..spectrum_file import SPECTRUM_SUFFIXES, write_spectrum


def register(subparsers) -> None:
    """Add ``mesh-spectrum`` and ``cmcf`` to the shspec command line."""
    p = subparsers.add_parser("mesh-spectrum", help="first K cotan Laplace-Beltrami eigenvalues of meshes",
                              description="Validate closed manifold triangle meshes (any genus) and compute their "
                              "first K cotan eigenvalues (ascending, 1/area in the mesh's unit). A degenerate group "
                              "cut at K is completed, so more than K values may come out. One mesh without --out: "
                              "print them. With --out DIR: any number of meshes (files or folders), one "
                              "NAME.eigenvalues.txt per mesh (one value per line, readable by 'shspec fit --target "
                              "spectrum:FILE' and numpy.loadtxt) and a table spectra.csv, with progress.")
    p.add_argument("paths", type=Path, nargs="+", metavar="PATH", help="mesh files (.obj, .ply, .off, .stl) or "
                   "folders of them")
    p.add_argument("--numeig", type=int, default=20, metavar="K", help="number of eigenvalues (default 20)")
    p.add_argument("--mass", choices=MASS_KINDS, default="lumped", help="mass matrix (default lumped)")
    p.add_argument("--json", action="store_true", help="print one JSON object with key 'eigenvalues' (one mesh)")
    p.add_argument("--out", type=Path, metavar="DIR", help="write files per mesh and spectra.csv to DIR (created); "
                   "for a single mesh, a file path ending in .txt, .csv, .json or .npy writes its spectrum there")
    p.add_argument("--descriptors", action="store_true", help="with --out: also NAME.shapedna.txt (eigenvalue * "
                   "area), NAME.heat_trace.txt (t, Z(t)) and NAME.hks.txt (heat kernel signature per vertex)")
    p.add_argument("--topology", action="store_true", help="with --out: also NAME.topology.json (Euler "
                   "characteristic and genus from the heat trace) and its columns in the table")
    p.add_argument("--workers", type=int, metavar="N", help="with --out: N worker processes, one BLAS thread each")
    p.add_argument("--scheduler", metavar="ADDRESS", help="with --out: run on a Dask distributed cluster")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_mesh_spectrum)

    q = subparsers.add_parser("cmcf", help="conformalized mean-curvature flow of a mesh to the unit sphere",
                              description="Map a closed genus-0 mesh to the unit sphere by cMCF and write "
                              "sphere.obj, factors.txt (one conformal factor per vertex), summary.json and "
                              "factors.png (Hammer projection of the factors) to DIR.")
    q.add_argument("path", type=Path, help="mesh file (.obj, .ply, .off, .stl)")
    q.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory (created)")
    q.add_argument("--tol", type=float, default=CMCFOptions.tol,
                   help=f"roundness tolerance; the flow also stops where the roundness stalls above it "
                   f"(default {CMCFOptions.tol:g})")
    q.add_argument("--max-iter", type=int, default=CMCFOptions.max_iter,
                   help=f"most flow steps (default {CMCFOptions.max_iter})")
    q.add_argument("--no-center", action="store_true", help="skip Möbius centering")
    q.add_argument("--merge-vertices", action="store_true",
                   help="weld vertices at identical positions (a vertex soup; always done for STL)")
    q.set_defaults(func=_cmcf)


def _mesh_spectrum(args) -> int:
    if args.out is not None and args.out.suffix.lower() in SPECTRUM_SUFFIXES and not args.out.is_dir():
        # one mesh into one file (the round trip into 'fit --target spectrum:FILE'), not a folder named s.txt
        if len(args.paths) != 1 or args.descriptors or args.topology or args.workers or args.scheduler:
            raise InvalidArgumentError(f"--out {args.out} is a spectrum file, for a single mesh; several meshes, "
                                       "--descriptors, --topology, --workers and --scheduler need --out DIR")
        mesh = load_mesh(args.paths[0], require_genus0=False)
        spec = mesh_spectrum(mesh, args.numeig, args.mass)
        ensure_directory(args.out.parent)
        write_spectrum(args.out, spec.eigenvalues, f"first {spec.eigenvalues.size} cotan Laplace-Beltrami "
                       f"eigenvalues of {args.paths[0]} ({args.mass} mass), ascending, 1/area; area "
                       f"{mesh.area():.17g}")
        return 0
    if args.out is not None:
        with make_executor(args.workers, args.scheduler) as executor:
            run_batch(args.paths, args.out, args.numeig, mass=args.mass, descriptors=args.descriptors,
                      topology=args.topology, executor=executor, progress=not args.quiet)
        return 0
    if len(args.paths) != 1 or args.descriptors or args.topology or args.workers or args.scheduler:
        raise InvalidArgumentError("several meshes, --descriptors, --topology, --workers and --scheduler need "
                                   "--out DIR")
    path = args.paths[0]
    mesh = load_mesh(path, require_genus0=False)
    spec = mesh_spectrum(mesh, args.numeig, args.mass)
    if args.json:
        print(json.dumps({"path": str(path), "mass": args.mass, "nvertices": mesh.nvertices,
                          "eigenvalues": spec.eigenvalues.tolist()}))
    else:
        for i, lam in enumerate(spec.eigenvalues):
            print(f"{i:5d}  {lam:.15g}")
    return 0


#: What ``shspec cmcf`` writes into its folder.
CMCF_OUTPUTS = ("sphere.obj", "factors.txt", "summary.json", "factors.png")


def _cmcf(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mesh = load_mesh(args.path, merge_vertices=args.merge_vertices or None)
    result = cmcf(mesh, CMCFOptions(tol=args.tol, max_iter=args.max_iter, center=not args.no_center))
    summary = {
        "input": str(args.path), "tol": args.tol, "max_iter": args.max_iter, "center": not args.no_center,
        "nvertices": mesh.nvertices, "roundness": result.roundness,
        "iterations": result.iterations, "time": result.seconds, "flips": result.flips,
        "distortion_mean": result.distortion_mean, "distortion_max": result.distortion_max,
        "centering_residual": None if np.isnan(result.centering_residual) else result.centering_residual,
        "success": result.success, "stop_reason": result.stop_reason,
    }
    # one unit: a failed write leaves the folder's previous run whole (shspec.core.atomic.atomic_outputs)
    with atomic_outputs(ensure_directory(args.out), replaces=CMCF_OUTPUTS) as files:
        save_mesh(result.sphere, files.path("sphere.obj"))
        with atomic_output(files.path("factors.txt")) as tmp:
            np.savetxt(tmp, result.factors, fmt="%.17g",
                       header="conformal factor per vertex: input vertex area / sphere vertex area")
        write_text(files.path("summary.json"), json.dumps(summary, indent=2) + "\n")
        fig = plot_hammer(result.sphere, result.factors, log=True, title=f"{args.path.name}: conformal factors",
                          label="factor (log scale)")
        try:
            save_figure(fig, files.path("factors.png"), dpi=120, bbox_inches="tight")
        finally:
            plt.close(fig)
    print(json.dumps(summary))
    return 0 if result.success else 1
