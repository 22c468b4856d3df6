"""``shspec fit``: recover a conformal factor from a spectrum (a thin layer over :func:`shspec.inverse.fit`)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from ..errors import CheckpointError, InvalidArgumentError


def register(subparsers) -> None:
    """Add ``fit`` to the shspec command line."""
    from ..inverse.options import AREA_MODES, OPTIMIZERS, WEIGHTINGS

    p = subparsers.add_parser(
        "fit", help="fit a conformal factor rho to a target spectrum (the inverse problem)",
        description="Fit rho (harmonic coefficients, or per-vertex factors with --model mesh) to a target spectrum "
        "from several random symmetry-broken starts through a schedule of stages, and write result.h5, "
        "summary.json and PNG figures to DIR.")
    p.add_argument("--target", required=True,
                   help="blob | star:l,m,p | mesh:PATH | spectrum:FILE (text, one eigenvalue per line, .npy, .json)")
    p.add_argument("--lmax", type=int, default=30, help="basis band limit Lb (default 30)")
    p.add_argument("--lmax-factor", type=int, default=15, help="factor band limit La (default 15)")
    p.add_argument("--numeig", type=int, default=256, help="eigenvalues matched, lambda_0 = 0 included (default 256)")
    p.add_argument("--schedule", default="degree-ramp",
                   help="stages: degrees '2,4,8,15', degree:numeig pairs '6:16,6:64,6:120', 'degree-ramp' (degree "
                   "and numeig raised together; the default: with --basin-hops 4 it made 7 of 8 blob starts "
                   "succeed, see benchmarks/results/bench_inverse.json), 'ramp' (numeig 16, 36, 64, ... at full "
                   "degree: 2 of 8) or 'none' (one stage: 0 of 8)")
    p.add_argument("--basin-hops", type=int, default=4,
                   help="after the last stage, up to N accepted power-preserving moves of single degree blocks "
                   "(half-turns, sign flips) to leave local minima (default 4; 0 turns them off)")
    p.add_argument("--reg", type=float, default=0.0, help="bi-Laplacian regularization weight R (default 0)")
    p.add_argument("--starts", type=int, default=4, help="random starts (default 4)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--optimizer", choices=OPTIMIZERS, default="lm", help="optimizer (default lm)")
    p.add_argument("--weights", choices=WEIGHTINGS, default="relative", help="eigenvalue weights (default relative)")
    p.add_argument("--area", choices=AREA_MODES, default="auto", help="area treatment (default auto)")
    p.add_argument("--max-iter", type=int, default=200, help="iterations per stage (default 200)")
    p.add_argument("--amplitude", type=float, default=0.2, help="size of the random starts (default 0.2)")
    p.add_argument("--model", choices=("harmonic", "mesh"), default="harmonic",
                   help="fit harmonic coefficients, or per-vertex factors on the target's cMCF sphere (mesh targets)")
    p.add_argument("--source", choices=("pl", "harmonic"), default="pl",
                   help="spectrum of a mesh target: its cotan spectrum or the harmonic one of its factors")
    p.add_argument("--subdivisions", type=int, default=3, help="icosphere subdivisions of star targets (default 3)")
    p.add_argument("--checkpoint-every", type=int, default=0, metavar="N",
                   help="write DIR/checkpoint.h5 every N iterations (default never)")
    p.add_argument("--resume", action="store_true", help="continue from DIR/checkpoint.h5")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory (created)")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.add_argument("--allow-any-genus", action="store_true",
                   help="fit spectrum:/mesh: targets even when their heat trace says confidently genus != 0")
    p.set_defaults(func=_fit)


def _schedule(text, numeig: int, lmax_factor: int):
    from ..inverse.options import parse_schedule
    from ..inverse.schedule import degree_ramp, numeig_ramp

    if text == "none":
        return ()
    if text == "ramp":
        return numeig_ramp(numeig)
    if text == "degree-ramp":
        return degree_ramp(numeig, lmax_factor)
    return parse_schedule(text)


def _fit(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..galerkin.solver import HarmonicModel
    from ..inverse import plots
    from ..inverse.align import align
    from ..inverse.checkpoint import save_result
    from ..inverse.multistart import fit
    from ..inverse.options import FitOptions
    from ..inverse.targets import parse_target

    out = args.out
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CheckpointError(f"cannot create output directory {out}: {exc}") from exc
    target = parse_target(args.target, lmax=args.lmax, numeig=args.numeig, lmax_factor=args.lmax_factor,
                          source=args.source, subdivisions=args.subdivisions)
    if not args.allow_any_genus and args.target.partition(":")[0] in ("spectrum", "mesh"):
        from ..spectral.topology import check_genus_zero

        check_genus_zero(target.eigenvalues, area=target.area)
    options = FitOptions(optimizer=args.optimizer, weights=args.weights, reg=args.reg, area=args.area,
                         schedule=_schedule(args.schedule, target.numeig, args.lmax_factor), starts=args.starts, seed=args.seed,
                         start_amplitude=args.amplitude, max_iter=args.max_iter, basin_hops=args.basin_hops,
                         checkpoint_every=args.checkpoint_every,
                         checkpoint_path=str(out / "checkpoint.h5") if args.checkpoint_every or args.resume else None,
                         progress=not args.quiet)
    if args.model == "mesh":
        from ..mesh.model import MeshModel

        if target.sphere is None:
            raise InvalidArgumentError("--model mesh needs a mesh target (star:... or mesh:...)")
        model = MeshModel(target.sphere)
    else:
        model = HarmonicModel(args.lmax, args.lmax_factor)
    if not args.quiet:
        print(f"fitting {target.name}: {target.numeig} eigenvalues, {model!r}, {options.starts} starts",
              file=sys.stderr)
    result = fit(target, model, options, resume=args.resume)
    save_result(out / "result.h5", result)

    best = result.best
    if result.kind == "harmonic":
        cilm = result.factor().to_cilm()
    else:
        from ..mesh.bridge import fit_harmonic

        la = min(args.lmax_factor, int(np.sqrt(model.nparams / 2)) - 1)
        cilm = fit_harmonic(target.sphere, best.params, la).coefficients
        from ..sphere.harmonics import vector_to_cilm

        cilm = vector_to_cilm(cilm)
    summary = {
        "target": target.name, "source": target.source, "kind": result.kind, "lmax": args.lmax,
        "lmax_factor": args.lmax_factor, "numeig": target.numeig, "optimizer": options.optimizer, "reg": options.reg,
        "energy": best.energy, "relative_residual": best.relative_residual, "time_s": result.seconds,
        "interrupted": result.interrupted, "successes": result.success_count,
        "solutions": [{"start": i, "energy": result.starts[i].energy} for i in result.solutions],
        "starts": [{"index": r.index, "energy": r.energy, "relative_residual": r.relative_residual,
                    "iterations": r.iterations, "time_s": r.seconds, "status": r.status, "success": r.success}
                   for r in result.starts],
        "cilm": cilm.tolist(),
    }
    aligned = None
    if target.truth is not None:
        from ..sphere.factor import ConformalFactor

        aligned = align(ConformalFactor(cilm), target.truth)
        summary["alignment"] = {"relative_error": aligned.relative_error, "power_error": aligned.power_error,
                                "mirrored": aligned.mirrored}
    if result.kind == "mesh":
        w = target.sphere and model.vertex_areas
        diff = best.params - target.factors
        summary["factor_error"] = float(np.sqrt(w @ diff ** 2 / (w @ target.factors ** 2)))
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")

    figures = {"history.png": plots.plot_history(result), "residuals.png": plots.plot_residuals(result)}
    if result.kind == "mesh":
        figures["factors.png"] = plots.plot_factors(result)
        figures["validation.png"] = plots.plot_validation(result)[0]
    else:
        figures["factors.png"] = plots.plot_factors(result, aligned)
    for name, fig in figures.items():
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
    print(f"best start {best.index}: energy {best.energy:.3e}, max relative residual {best.relative_residual:.3e}, "
          f"{result.success_count}/{len(result.starts)} starts succeeded, {result.seconds:.1f} s; wrote {out}")
    return 130 if result.interrupted else 0
