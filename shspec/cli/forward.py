"""``shspec forward`` and ``shspec convergence``: spectra of a conformal factor in the harmonic basis."""

from __future__ import annotations

import contextlib
import json
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np

from .._version import __version__
from ..core.atomic import atomic_output, atomic_outputs, save_figure, write_hdf5, write_text
from ._common import CACHE_DIR_HELP
from .help_format import HelpFormatter
from ..errors import BandLimitError, InvalidArgumentError, TruncationWarning
from ..galerkin.convergence import convergence, convergence_in_factor
from ..mesh.factor_spectrum import pl_spectrum_of_factor
from ..galerkin.solver import MAX_BASIS_DEGREE, spectrum
from ..gaunt.cache import list_tables
from ..core.outputs import ensure_directory, write_csv
from ..sphere.harmonics import check_degree
from ._rho import RHO_HELP, parse_rho


def register(sub) -> None:
    p = sub.add_parser(
        "forward", help="Laplace-Beltrami spectrum of a conformal factor rho (harmonic Galerkin)",
        description="Compute the first K eigenvalues of the Laplace-Beltrami operator of g = rho*g0 in the real "
        "spherical-harmonic basis of degree <= --lmax. Without arguments: a Moebius-boosted sphere, whose exact "
        "spectrum l(l+1) is printed beside for comparison. The Gaunt table is taken from the cache or built.",
        formatter_class=HelpFormatter)
    p.add_argument("--rho", default="boost:2:1,1,1", help=RHO_HELP)
    p.add_argument("--lmax", type=int, default=30, help="basis band limit Lb")
    p.add_argument("--lmax-factor", type=int, default=None,
                   help="band limit La of rho (default: Lb for built-ins, the file's own for files)")
    p.add_argument("--numeig", type=int, default=36, help="number of eigenvalues K (lambda_0 = 0 included)")
    p.add_argument("--out", help="save the spectrum with its parameters to this .json or .h5 file")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--cache-dir", help=CACHE_DIR_HELP)
    p.set_defaults(func=run_forward)

    c = sub.add_parser(
        "convergence", help="convergence of the harmonic spectrum in Lb (or in La), with CSV/JSON and plots",
        description="Spectra of rho for each basis band limit in --lmax-values (the largest is the reference), the "
        "relative change of every eigenvalue and the fitted exponential rate per round-sphere multiplet; with "
        "--factor-values, the same for truncations of rho at fixed Lb. Writes convergence.csv, convergence.json "
        "and PNG plots into --out. --pl-subdivisions adds the piecewise-linear spectrum of an icosphere carrying "
        "rho (it converges from below).",
        formatter_class=HelpFormatter)
    c.add_argument("--rho", default="boost:2:1,1,1", help=RHO_HELP)
    c.add_argument("--lmax-values", default="6,8,10,12,14,16,18,20,24",
                   help="comma-separated basis band limits")
    c.add_argument("--factor-values", default=None,
                   help="comma-separated band limits of rho to truncate to (at Lb = the largest --lmax-values)")
    c.add_argument("--lmax-factor", type=int, default=20, help="band limit of built-in rho")
    c.add_argument("--numeig", type=int, default=36, help="eigenvalues per spectrum")
    c.add_argument("--pl-subdivisions", type=int, default=None, help="icosphere subdivisions for the PL spectrum")
    c.add_argument("--out", default="convergence", help="output folder")
    c.add_argument("--cache-dir", help=CACHE_DIR_HELP)
    c.set_defaults(func=run_convergence)


def _int_list(text: str, name: str) -> list[int]:
    try:
        return [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise InvalidArgumentError(f"{name} must be comma-separated whole numbers, got {text!r}") from None


def _exact_sphere(k: int) -> np.ndarray:
    l = np.repeat(np.arange(int(np.sqrt(k)) + 2), 2 * np.arange(int(np.sqrt(k)) + 2) + 1)[:k]
    return (l * (l + 1)).astype(float)


def _check_limits(args) -> None:
    """The band limits of the command line, checked with the library's own rules and named as options."""

    args.lmax = check_degree(args.lmax, "--lmax", minimum=1, maximum=MAX_BASIS_DEGREE)
    if args.lmax_factor is not None:
        args.lmax_factor = check_degree(args.lmax_factor, "--lmax-factor", minimum=0)
        if args.lmax_factor > 2 * args.lmax:
            raise BandLimitError(f"--lmax-factor = {args.lmax_factor} > 2*--lmax = {2 * args.lmax}: degrees of rho "
                                 "above 2*Lb do not couple two basis functions, so they would be ignored")
    args.numeig = check_degree(args.numeig, "--numeig", minimum=1)  # the library says how far to raise --lmax


@contextlib.contextmanager
def _status(message: str, after: float = 1.0):
    """Print ``message`` on stderr if the block is still running after ``after`` seconds (a silent first run)."""
    timer = threading.Timer(after, lambda: print(message, file=sys.stderr, flush=True))
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()


def _working_message(args, rho) -> str:
    """What a slow forward run is doing: building a table only when none covering its band limits is cached (the
    notice used to promise a one-time wait on every slow run)."""
    la = rho.lmax if args.lmax_factor is None else args.lmax_factor
    covered = any(info.problem is None and info.lmax >= args.lmax and info.lmax_factor >= min(la, 2 * args.lmax)
                  for info in list_tables(args.cache_dir))
    if covered:
        return "shspec forward: working..."
    return ("shspec forward: working... (building the Gaunt table for these band limits, once per cache; a first "
            "run also compiles shspec's numba kernels)")


def _number(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def run_forward(args) -> int:

    _check_limits(args)
    if args.out and Path(args.out).suffix.lower() not in (".json", ".h5", ".hdf5"):
        raise InvalidArgumentError(f"--out must end in .json or .h5, got {Path(args.out).name}")
    rho = parse_rho(args.rho, args.lmax_factor if args.lmax_factor is not None else args.lmax)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught, _status(_working_message(args, rho)):
        warnings.simplefilter("always", TruncationWarning)
        res = spectrum(rho, lmax=args.lmax, k=args.numeig, lmax_factor=args.lmax_factor, cache_dir=args.cache_dir)
    for w in caught:
        if issubclass(w.category, TruncationWarning):
            print(f"shspec forward: warning: {w.message}", file=sys.stderr)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    seconds = time.perf_counter() - start
    isometric = args.rho.startswith("boost") or args.rho.startswith("sphere")
    exact = _exact_sphere(args.numeig) * (4 * np.pi / rho.area) if isometric else None
    record = {"rho": args.rho, "rho_name": rho.name, "lmax": res.lmax, "lmax_factor": res.lmax_factor, "numeig": args.numeig,
              "area": rho.area, "eigenvalues": res.eigenvalues.tolist(),
              # JSON has no inf: a truncation error that cannot be bounded is null
              "truncation_error_factor": _number(res.truncation.factor),
              "truncation_error_basis": _number(res.truncation.basis),
              "truncation_error_unresolved": _number(res.truncation.unresolved),
              "seconds": seconds, "shspec_version": __version__}
    if exact is not None:
        rel = np.abs(res.eigenvalues[1:] - exact[1:]) / exact[1:]
        record["max_relative_error_vs_exact"] = float(rel.max()) if rel.size else 0.0
    if args.out:
        # the input itself, not only its name or path, so that the file reproduces the run
        _save(Path(args.out), dict(record, rho_coefficients=rho.coefficients.tolist()), res.eigenvectors)
    if args.json:
        print(json.dumps(record))
        return 0
    print(f"rho = {rho.name}, area {rho.area:.6g}; basis Lb = {res.lmax}, factor La = {res.lmax_factor}; "
          f"{args.numeig} eigenvalues in {seconds:.2f} s")
    print(f"{'i':>4s} {'lambda_i':>22s}" + (f" {'exact':>10s} {'rel. error':>10s}" if exact is not None else ""))
    for i, lam in enumerate(res.eigenvalues):
        line = f"{i:4d} {lam:22.15f}"
        if exact is not None:
            err = abs(lam - exact[i]) / exact[i] if exact[i] else abs(lam)
            line += f" {exact[i]:10.4f} {err:10.2e}"
        print(line)
    if exact is not None:
        print(f"max relative error against the exact spectrum: {record['max_relative_error_vs_exact']:.2e}")
    t = res.truncation
    if not np.isnan(t.basis):  # inf (a tail that cannot be bounded) prints as inf
        print(f"estimated truncation error (relative): rho cut at La {t.factor:.1e}, basis (degrees above Lb) "
              f"{t.basis:.1e}; degrees above rho's own, extrapolated {t.unresolved:.1e}")
    else:  # relative to lambda_0 = 0 alone (K = 1) there is nothing to estimate
        print("estimated truncation error: not estimated (it is relative to the nonzero eigenvalues; ask for "
              "--numeig 2 or more)")
    if args.out:
        print(f"saved to {args.out}")
    return 0


def _save(path: Path, record: dict, vectors: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".json":
        with atomic_output(path) as tmp:
            tmp.write_text(json.dumps(record, indent=1))
    elif path.suffix.lower() in (".h5", ".hdf5"):
        def fill(f):
            f["eigenvalues"] = np.asarray(record["eigenvalues"])
            f["eigenvectors"] = vectors
            f["rho_coefficients"] = np.asarray(record["rho_coefficients"])
            for key, value in record.items():
                if key not in ("eigenvalues", "rho_coefficients"):
                    f.attrs[key] = np.nan if value is None else value  # HDF5 has no null; JSON no inf

        write_hdf5(path, fill)
    else:
        raise InvalidArgumentError(f"--out must end in .json or .h5, got {path.name}")


def run_convergence(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    lmax_values = _int_list(args.lmax_values, "--lmax-values")
    rho = parse_rho(args.rho, args.lmax_factor)
    out = ensure_directory(args.out)
    studies = [convergence(rho, lmax_values, args.numeig, cache_dir=args.cache_dir)]
    if args.factor_values:
        studies.append(convergence_in_factor(rho, _int_list(args.factor_values, "--factor-values"), max(lmax_values),
                                             args.numeig, cache_dir=args.cache_dir))
    if args.pl_subdivisions is not None:
        pl = pl_spectrum_of_factor(rho, args.numeig, args.pl_subdivisions)
        studies[0].pl_eigenvalues[f"PL icosphere({args.pl_subdivisions})"] = pl
    # one unit: a failed write leaves the folder's previous study whole (shspec.core.atomic.atomic_outputs)
    with atomic_outputs(out) as files:
        summary = {"rho": args.rho, "numeig": args.numeig,
                   "studies": [_write_study(study, rho, files) for study in studies]}
        write_text(files.path("convergence.json"), json.dumps(summary, indent=1))
    print(f"wrote {out}/convergence.json, CSV and PNG files")
    return 0


def _write_study(study, rho, files) -> dict:
    """Write one convergence study's table and figure into ``files`` and print its line; returns its entry of
    convergence.json."""
    import matplotlib.pyplot as plt

    rows = study.table()
    write_csv(files.path(f"convergence_{study.parameter}.csv"), rows)
    rates = study.rates()
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.5))
    study.plot(axes[0])
    study.plot_spectra(axes[1])
    axes[0].set_title(f"{rho.name}: convergence in {study.parameter}")
    fig.tight_layout()
    try:
        save_figure(fig, files.path(f"convergence_{study.parameter}.png"), dpi=120)
    finally:
        plt.close(fig)
    finite = rates[~np.isnan(rates)]
    print(f"{study.parameter}: values {study.values.tolist()}; largest change at the coarsest "
          f"{rows[0]['max_relative_change']:.2e}, next-to-finest {rows[-2]['max_relative_change']:.2e}; "
          f"median exponential rate {np.median(finite) if finite.size else float('nan'):.3f} per degree")
    return {"parameter": study.parameter, "values": study.values.tolist(), "fixed": study.fixed,
            "eigenvalues": study.eigenvalues.tolist(), "rows": rows,
            "rates_per_group": {f"l{l}": (None if np.isnan(r) else float(r)) for (l, _), r in zip(study.groups(),
                                                                                             rates)},
            "pl_eigenvalues": {k: v.tolist() for k, v in study.pl_eigenvalues.items()}}
