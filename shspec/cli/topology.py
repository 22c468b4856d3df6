"""``shspec topology``: Euler characteristic, genus and area of a surface from its spectrum, before any fit."""

from __future__ import annotations

import json

import numpy as np

from ..errors import InvalidArgumentError
from ..mesh.eigen import mesh_spectrum
from ..mesh.mesh_files import load_mesh
from ..spectrum_file import read_spectrum_file
from ..spectral.topology import MIN_EIGENVALUES, estimate_topology

#: Default K of mesh targets: enough for a ~10k-vertex mesh (measured: docs, benchmarks page), at most n/5 so that
#: coarse meshes stay in the range where their cotan eigenvalues are accurate.
DEFAULT_MESH_NUMEIG = 500


def register(subparsers) -> None:
    """Add ``topology`` to the shspec command line."""
    p = subparsers.add_parser(
        "topology", help="Euler characteristic, genus and area from a spectrum (heat-trace asymptotics)",
        description="Fit the heat trace Z(t) = sum exp(-lambda t) ~ A/(4 pi t) + chi/6 + a1 t + ... of a spectrum "
        "over windows of t tied to its largest eigenvalue and print the Euler characteristic chi with its "
        "uncertainty, the genus with a confidence statement, and the area (known or fitted).")
    p.add_argument("--target", required=True, help="spectrum:FILE (text or CSV: one eigenvalue per line, index and "
                   "eigenvalue, index, eigenvalue and error, or columns named in a header; .npy; .json; see "
                   "shspec.spectrum_file) or mesh:PATH (its cotan spectrum, any genus)")
    p.add_argument("--area", type=float, help="the surface area, if known (mesh targets: the mesh's area)")
    p.add_argument("--numeig", type=int, metavar="K", help="eigenvalues used, lambda_0 = 0 included (spectrum: all "
                   f"by default; mesh: min({DEFAULT_MESH_NUMEIG}, vertices/5))")
    p.add_argument("--noise", type=float, default=None, metavar="EPS",
                   help="relative noise of each eigenvalue, propagated into the uncertainty (default: the largest "
                   "relative error of a spectrum file's error column, else 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--quiet", action="store_true", help="no size estimate or progress bar for large meshes")
    p.set_defaults(func=_topology)


def _topology(args) -> int:
    kind, _, arg = args.target.partition(":")
    area, noise = args.area, args.noise
    if kind == "spectrum" and arg:
        spectrum = read_spectrum_file(arg)
        lam, numeig = spectrum.eigenvalues, args.numeig
        if noise is None and spectrum.errors is not None:
            noise = float(np.max(spectrum.errors[1:] / lam[1:]))
    elif kind == "mesh" and arg:
        mesh = load_mesh(arg, require_genus0=False)
        numeig = args.numeig or min(DEFAULT_MESH_NUMEIG, max(MIN_EIGENVALUES, mesh.nvertices // 5))
        lam = mesh_spectrum(mesh, numeig).eigenvalues[:numeig]
        area = mesh.area() if area is None else area
    else:
        raise InvalidArgumentError(f"unknown target {args.target!r}: use spectrum:FILE or mesh:PATH")
    est = estimate_topology(lam, area, numeig=numeig, relative_noise=0.0 if noise is None else noise)
    if args.json:
        print(json.dumps({"target": args.target, **est.to_dict()}))
        return 0
    how = "known" if est.area_known else f"fitted, ± {est.area_error:.3g}"
    print(f"target: {args.target}")
    print(f"eigenvalues used: {est.numeig}; window t in [{est.window[0]:.4g}, {est.window[1]:.4g}]")
    weyl = est.weyl_area / est.area - 1
    print(f"area: {est.area:.6g} ({how}); Weyl's law alone (N(lambda) ~ A lambda / 4 pi) would say "
          f"{est.weyl_area:.6g}, {weyl:+.0%}: the heat trace's estimate is the one to use")
    print(f"Euler characteristic: {est.euler_characteristic:.3f} ± {est.euler_characteristic_error:.3f}")
    print(est.statement)
    return 0
