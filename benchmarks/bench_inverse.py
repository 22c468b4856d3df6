"""Benchmark of the inverse solver → benchmarks/results/bench_inverse.json (and figures in docs/figures/).

Sections (each written to the JSON as soon as it is done, so a partial run still reports):

* ``blob``: the built-in harmonic blob, Lb = 20, La = 6, 120 eigenvalues, 8 starts, Levenberg–Marquardt, one
  stage and the numeig ramp (16, 36, 64, 100, 120): success rate, median time per start, error after alignment.
* ``optimizers``: LM, L-BFGS, BFGS and gradient descent from the same start on a small problem that LM solves.
* ``study``: the study's harmonic setting Lb = 30, La = 15 (256 coefficients), 256 eigenvalues, R = 0 and 1e-6.
* ``mesh_log``: log-factor PL fits with the study's Dirichlet R of bunny_600 on its own cMCF sphere (targets (a) pl
  and (b) cmcf; LM, L-BFGS, linear factors), the adaptive fit from an icosphere, bunny_1200 and the 8000-vertex bunny.
* ``mesh_all``: the same with every eigenvalue of the mesh (K = n − 1), LM against L-BFGS at 600 and 1200 vertices.
* ``bunny``: the PL fit of bunny_600 / bunny_1200 started from its own cMCF sphere (study Figures 2 and 1,
  R = 0.1 and 0.05), against the baseline of the round start.

Run ``python benchmarks/bench_inverse.py [--quick]``.  BLAS is limited to one thread: the machine is shared, and
oversubscribed BLAS threads made one eigensolve ten times slower here.  Times are wall times on a loaded machine.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

from shspec import HarmonicModel, __version__  # noqa: E402
from shspec.core.parallel import make_executor, stop_executor  # noqa: E402
from shspec.inverse import FitOptions, align, degree_ramp, fit, numeig_ramp  # noqa: E402
from shspec.fitting import blob_factor, harmonic_target, mesh_target  # noqa: E402
from shspec.sphere.random import random_centred_coefficients  # noqa: E402
from shspec.inverse import plots  # noqa: E402
from shspec.mesh.figures import plot_spectra_validation, plot_vertex_factors  # noqa: E402
from shspec.experiments.common import load_mesh_area_4pi  # noqa: E402
from shspec.experiments.fitting import vertex_factor_errors  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import git_commit, machine_info  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "bench_inverse.json"
FIGURES = ROOT / "docs" / "figures"
MESHES = ROOT.parent / "shared" / "data" / "meshes"


def _starts(result):
    return [{"index": s.index, "relative_residual": s.relative_residual, "energy": s.energy,
             "iterations": s.iterations, "time_s": s.seconds, "status": s.status, "success": s.success}
            for s in result.starts]


def _summary(result, truth=None):
    out = {"success": result.success_count, "starts": len(result.starts),
           "median_time_per_start_s": float(np.median([s.seconds for s in result.starts])),
           "total_time_s": result.seconds, "best_relative_residual": result.best.relative_residual,
           "distinct_solutions": len(result.solutions), "per_start": _starts(result)}
    if truth is not None:
        al = align(result.factor(), truth)
        out.update(relative_error=al.relative_error, power_error=al.power_error, mirrored=al.mirrored)
    return out


_SECTIONS = ("blob", "blob_hops", "optimizers", "study", "goal_degree10", "goal_blob", "success_by_degree", "bunny",
             "mesh_log", "mesh_all")


def _save(report):
    """Merge this run's sections into the JSON file (runs of different sections may overlap in time)."""
    OUT.parent.mkdir(parents=True, exist_ok=True)
    merged = json.loads(OUT.read_text()) if OUT.exists() else {}
    merged.update({k: v for k, v in report.items() if k not in _SECTIONS or k in report["ran"]})
    merged.pop("ran", None)
    OUT.write_text(json.dumps(merged, indent=2) + "\n")


def bench_blob(report, starts):
    target = harmonic_target(blob_factor(), 20, 120)
    model = HarmonicModel(20, 6)
    section = {}
    for name, schedule in (("direct", ()), ("ramp", numeig_ramp(120))):
        result = fit(target, model, FitOptions(starts=starts, schedule=schedule, max_iter=150, basin_hops=0))
        section[name] = _summary(result, target.truth)
        report["blob"] = section
        _save(report)
        if name == "ramp" or result.success_count:
            fig = plots.plot_factors(result)
            fig.savefig(FIGURES / f"blob_fit_{name}.png", dpi=100)
            plt.close(fig)
            fig = plots.plot_history(result)
            fig.savefig(FIGURES / f"blob_history_{name}.png", dpi=100)
            plt.close(fig)


def bench_blob_hops(report, starts):
    """The blob with the degree ramp and basin hops (4 power-preserving block moves), the escape from local minima."""
    target = harmonic_target(blob_factor(), 20, 120)
    result = fit(target, HarmonicModel(20, 6), FitOptions(starts=starts, schedule=degree_ramp(120, 6), max_iter=150,
                                                         basin_hops=4, hop_iter=15))
    report["blob_hops"] = {"degree_ramp_hops4": _summary(result, target.truth)}
    _save(report)



def bench_optimizers(report, budget):
    truth = random_centred_coefficients(1, 4, 0.15)
    target = harmonic_target(truth, 12, 49)
    model = HarmonicModel(12, 4)
    section = {"setting": "Lb=12, La=4, 49 eigenvalues, random centred rho (seed 1), start seed 1, one start"}
    for name in ("lm", "lbfgs", "bfgs", "gd"):
        iters = 100 if name == "lm" else budget
        result = fit(target, model, FitOptions(schedule=(), basin_hops=0, starts=1, seed=1, optimizer=name, max_iter=iters))
        s = result.best
        section[name] = {"iterations": s.iterations, "time_s": s.seconds, "relative_residual": s.relative_residual,
                         "status": s.status}
        report["optimizers"] = section
        _save(report)


def _goal_summary(result, truth, options_text):
    """_summary plus, per start, its error after alignment and its linearized estimate (identifiability)."""
    out = _summary(result, truth)
    out["options"] = options_text
    for row, start in zip(out["per_start"], result.starts):
        al = align(result.model.to_factor(start.params), truth)
        row["rho_error_after_alignment"] = al.relative_error
    ident = result.identifiability()
    out["identifiability"] = {k: v for k, v in ident.to_dict().items() if k != "singular_values"}
    out["success_1e-8"] = sum(r["rho_error_after_alignment"] <= 1e-8 for r in out["per_start"])
    return out


def _fit_measured(target, model, options, workers):
    """``fit`` on ``workers`` processes, and the run's record: workers, wall time and load average around it."""
    load, t0 = list(os.getloadavg()), time.perf_counter()
    ex = make_executor(workers)
    try:
        result = fit(target, model, options, executor=ex)
    finally:
        stop_executor(ex)  # as shspec fit: the starts a first success made unneeded are not waited for
    return result, {"workers": workers, "wall_seconds": time.perf_counter() - t0,
                    "load_average_before_after": [load, list(os.getloadavg())]}


def bench_study(report, starts, workers):
    """The study's harmonic setting: Lb = 30, La = 15, K = 256, R = 0 and 1e-6, the default schedule."""
    truth = blob_factor(15)
    target = harmonic_target(truth, 30, 256)
    model = HarmonicModel(30, 15)
    section = {"setting": "Lb=30, La=15 (256 coefficients), 256 eigenvalues, target: the blob, default options"}
    for reg in (0.0, 1e-6):
        result, run = _fit_measured(target, model, FitOptions(starts=starts, reg=reg), workers)
        section[f"R={reg:g}"] = {**run, **_goal_summary(result, truth, f"FitOptions(starts={starts}, reg={reg:g})")}
        report["study"] = section
        _save(report)


def bench_goal_degree10(report, starts, workers):
    """Issue 14's first goal: a random centred rho of degree 10, 300 eigenvalues, Lb = 24, default options."""
    truth = random_centred_coefficients(1, 10, 0.2)
    target = harmonic_target(truth, 24, 300)
    result, run = _fit_measured(target, HarmonicModel(24, 10), FitOptions(starts=starts), workers)
    report["goal_degree10"] = {"setting": "random centred rho (seed 1, degree 10), Lb=24, 300 eigenvalues", **run,
                               **_goal_summary(result, truth, f"FitOptions(starts={starts})")}
    _save(report)


def bench_success_by_degree(report, starts, workers, degrees=(6, 8, 12)):
    """Success rates of the default fit on random centred rho (seed 1) of several degrees, each at the K and Lb that
    ``shspec fit`` plans without --numeig (degree 10 and the blob at 15 are the goal sections): every start run (a
    rate needs them all, where the default stops at the first success).  Degrees not run keep their earlier
    records."""
    from shspec.fitting.numeig_plan import plan_fit

    section = json.loads(OUT.read_text()).get("success_by_degree", {}) if OUT.exists() else {}
    for la in degrees:
        truth = random_centred_coefficients(1, la, 0.2)
        plan = plan_fit(la, random_centred_coefficients(0, la, 0.2))
        target = harmonic_target(truth, plan.lmax, plan.numeig)
        options = FitOptions(starts=starts, stop_at_success=False)
        result, run = _fit_measured(target, HarmonicModel(plan.lmax, la), options, workers)
        setting = f"random centred rho (seed 1, degree {la}), planned K={plan.numeig}, Lb={plan.lmax}"
        section[f"degree {la}"] = {"setting": setting, "commit": git_commit(), **run,
                                   **_goal_summary(result, truth, f"FitOptions(starts={starts}, "
                                                                  "stop_at_success=False)")}
        report["success_by_degree"] = section
        _save(report)


def bench_goal_blob(report, starts, workers):
    """Issue 14's second goal: the blob at La = 15 with the K that ``shspec identifiability`` recommends."""
    from shspec.fitting.numeig_plan import plan_numeig

    la = 15
    truth = blob_factor(la)
    plan = plan_numeig(la, truth, noise=FitOptions().residual_tol, accuracy=1e-8)
    k, lb = (plan.numeig, plan.lmax) if plan.numeig is not None else (600, 30)
    target = harmonic_target(truth, lb, k)
    # progress: each stage and hop is logged on stderr as it ends
    result, run = _fit_measured(target, HarmonicModel(lb, la), FitOptions(starts=starts, progress=True), workers)
    report["goal_blob"] = {"setting": f"the blob at La=15, K={k}, Lb={lb}", "plan": plan.to_dict(), **run,
                           **_goal_summary(result, truth, f"FitOptions(starts={starts})")}
    _save(report)


def bench_bunny(report, max_iter, numeig):
    from shspec.mesh.mesh_files import load_mesh
    from shspec.mesh.model import MeshModel

    section = {"setting": f"PL fit from the target's own cMCF sphere, {numeig} PL eigenvalues, start: round "
                          "(constant factors, 1e-3 random)", "baseline": "the round start itself"}
    for name, reg in (("bunny_600", 0.1), ("bunny_1200", 0.05)):
        path = MESHES / f"{name}.obj"
        if not path.exists():
            section[name] = {"skipped": f"{path} not found"}
            continue
        t0 = time.perf_counter()
        target = mesh_target(load_mesh(path), lmax=20, numeig=numeig, lmax_factor=10, name=name)
        t_target = time.perf_counter() - t0
        model = MeshModel(target.sphere)
        result = fit(target, model, FitOptions(optimizer="lm", schedule=(), starts=1, reg=reg, max_iter=max_iter,
                                                start_amplitude=1e-3))
        w = model.vertex_areas
        c_true = target.factors

        def err(c):
            # RMS of log(c / c_true), area weighted: cMCF factors span several decades on the bunny (ears), so a
            # plain relative L2 error is the error at a few vertices.
            d = np.log(c / c_true)
            return float(np.sqrt(w @ d ** 2 / w.sum()))

        round_c = np.full(c_true.size, target.area / w.sum())
        fig, spectra = plot_spectra_validation(model, result.best.params, target.mesh, target.factors,
                                               result.best.eigenvalues.size)
        fig.savefig(FIGURES / f"{name}_validation.png", dpi=100)
        plt.close(fig)
        fig = plot_vertex_factors(model.mesh, result.best.params, target.factors)
        fig.savefig(FIGURES / f"{name}_factors.png", dpi=100)
        plt.close(fig)
        rel = {k: float(np.max(np.abs(v[1:] / spectra["target"][1:] - 1))) for k, v in spectra.items()}
        section[name] = {"R": reg, "nvertices": int(c_true.size), "target_setup_s": t_target,
                         "fit_time_s": result.seconds, "iterations": result.best.iterations,
                         "status": result.best.status, "relative_residual": result.best.relative_residual,
                         "log_factor_rms_error_fit": err(result.best.params),
                         "log_factor_rms_error_round_baseline": err(round_c),
                         "cmcf_factor_range": [float(c_true.min()), float(c_true.max())],
                         "validation_max_rel_spectrum_error": {"cmcf_factors": rel["cmcf"], "fit": rel["fit"]}}
        report["bunny"] = section
        _save(report)


def _mesh_case(target, model, options, init=None):
    """One mesh fit: time, residual, the summary's factor errors and, for exactly representable targets, the RMS log
    error over the directions the eigenvalues determine (shspec.inverse.identifiability.determined_directions)."""
    from shspec.inverse.identifiability import determined_directions

    result = fit(target, model, options, init=init)
    best = result.best
    out = {"model": model.describe(), "optimizer": options.optimizer or model.default_optimizer, "R": options.reg, "numeig": target.numeig,
           "time_s": result.seconds, "iterations": best.iterations, "status": best.status,
           "relative_residual": best.relative_residual, "energy": best.energy,
           "load_average": list(os.getloadavg())}
    cmp = model.compare(best.params, target)
    out.update({k: cmp[k] for k in ("log_rms", "log_correlation", "fitted_range", "truth_range", "aligned") if k in cmp})
    if model._on(target.sphere):
        out["log_correlation_area_weighted"] = vertex_factor_errors(model.vertex_areas, best.params,
                                                                    target.factors)["log_correlation"]
    if target.source == "cmcf" and model._on(target.sphere):
        B = determined_directions(model, target.factors, target.numeig)
        e = np.log(best.params) - np.log(target.factors)
        out["determined_directions"] = int(B.shape[1])
        out["log_rms_determined"] = float(np.linalg.norm(B.T @ e) / np.sqrt(e.size))
    return out, result


def bench_mesh_log(report, quick):
    """Log-factor PL fits (Dirichlet R, the study's): bunny_600 on its own cMCF sphere, targets (a) pl and (b) cmcf;
    LM against L-BFGS and linear factors; the adaptive fit from an icosphere; 1200 and 8000 vertices."""
    from shspec.mesh.model import MeshModel
    from shspec.mesh.cmcf import cmcf
    from shspec.fitting.adaptive import AdaptiveOptions, adaptive_fit

    k = 40 if quick else 100
    section = {"setting": f"area 4pi, {k} eigenvalues, relative weights, Dirichlet R s'Ls/2, one start from the "
                          "constant factors (amplitude 1e-3), no schedule unless said; times are wall times on a "
                          "2-core machine shared with other engineers (approximate)"}
    report["mesh_log"] = section
    mesh = load_mesh_area_4pi(MESHES, "bunny_600")
    flow = cmcf(mesh)
    tgt = {src: mesh_target(mesh, 12, k, 6, name="bunny_600", source=src, flow=flow) for src in ("pl", "cmcf")}
    R = 0.05
    base = FitOptions(optimizer="lm", schedule=(), starts=1, basin_hops=0, start_amplitude=1e-3,
                      max_iter=30 if quick else 150)
    cases = [("a_lm_log", "pl", "exp", "lm", R), ("a_lm_linear", "pl", "identity", "lm", R),
             ("a_lbfgs_log", "pl", "exp", "lbfgs", R), ("b_lm_log_R0", "cmcf", "exp", "lm", 0.0),
             ("b_lm_log", "cmcf", "exp", "lm", R)]
    for label, src, transform, optimizer, reg in cases:
        model = MeshModel(tgt[src].sphere, transform=transform, reg_kind="dirichlet")
        opts = FitOptions(**{**base.__dict__, "optimizer": optimizer, "reg": reg,
                             "max_iter": base.max_iter * (3 if optimizer == "lbfgs" else 1)})
        section[label], _ = _mesh_case(tgt[src], model, opts)
        _save(report)
    t0 = time.perf_counter()
    ad = adaptive_fit(tgt["pl"], AdaptiveOptions(subdivisions=2, reg_kind="dirichlet",
                                                 fit=FitOptions(**{**base.__dict__, "reg": R})))
    cmp = ad.result.model.compare(ad.result.best.params, ad.result.target)
    section["a_adaptive_icosphere"] = {**ad.to_dict(), "time_s": time.perf_counter() - t0,
                                       **{k2: cmp[k2] for k2 in ("log_rms", "log_correlation", "fitted_range",
                                                                 "aligned")}}
    own = section["a_lm_log"]["log_rms"]
    section["a_adaptive_icosphere"]["log_rms_ratio_to_own_sphere"] = cmp["log_rms"] / own
    _save(report)
    for name, optimizer, iters in (("bunny_1200", "lm", 60), ("bunny_1200", "lbfgs", 150), ("bunny", "lbfgs", 20)):
        if quick and name == "bunny":
            continue
        t = mesh_target(load_mesh_area_4pi(MESHES, name), 12, k, 6, name=name)
        model = MeshModel(t.sphere, transform="exp", reg_kind="dirichlet")
        opts = FitOptions(**{**base.__dict__, "optimizer": optimizer, "reg": R, "max_iter": iters})
        section[f"{name}_{optimizer}"], _ = _mesh_case(t, model, opts)
        section[f"{name}_{optimizer}"]["nvertices"] = t.sphere.nvertices
        _save(report)


def bench_mesh_all(report, quick):
    """Every eigenvalue of the mesh (K = n − 1), R = 0.05 (Dirichlet), log factors on the own cMCF sphere: LM
    against L-BFGS at 600 and 1200 vertices, target (a)."""
    from shspec.mesh.model import MeshModel

    section = {"setting": "K = n - 1 cotan eigenvalues of the mesh (target (a)), area 4pi, relative weights, "
                          "Dirichlet R = 0.05, one start from the constant factors, log factors; wall times on a "
                          "shared 2-core machine (approximate)"}
    report["mesh_all"] = section
    for name in ("bunny_600",) if quick else ("bunny_600", "bunny_1200"):
        mesh = load_mesh_area_4pi(MESHES, name)
        t = mesh_target(mesh, 12, mesh.nvertices - 1, 6, name=name)
        for optimizer, iters in (("lm", 60), ("lbfgs", 300)):
            model = MeshModel(t.sphere, transform="exp", reg_kind="dirichlet")
            opts = FitOptions(schedule=(), starts=1, basin_hops=0, start_amplitude=1e-3, reg=0.05,
                              optimizer=optimizer, max_iter=10 if quick else iters)
            section[f"{name}_{optimizer}"], _ = _mesh_case(t, model, opts)
            _save(report)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer starts and iterations")
    parser.add_argument("--sections", default="blob,optimizers,study,goal_degree10,goal_blob,bunny")
    parser.add_argument("--workers", type=int, default=1,
                        help="processes for the starts of the goal sections (one BLAS thread each)")
    parser.add_argument("--degrees", default="6,8,12", help="degrees of the success_by_degree section")
    parser.add_argument("--starts", type=int, default=None,
                        help="starts of the goal sections (default 4, 2 with --quick; each section records it)")
    args = parser.parse_args(argv)
    FIGURES.mkdir(parents=True, exist_ok=True)
    report = {"machine": {**machine_info(), "load_average_start": list(os.getloadavg()), "blas_threads": 1},
              "shspec": __version__, "quick": args.quick}
    sections = args.sections.split(",")
    report["ran"] = sections
    import warnings

    # The mesh eigensolver warns when k cuts a near-degenerate group; on the cMCF spheres it does so every step.
    warnings.filterwarnings("ignore", category=RuntimeWarning, module="shspec.mesh")
    with threadpool_limits(1):
        t0 = time.perf_counter()
        if "blob" in sections:
            bench_blob(report, 4 if args.quick else 8)
        if "blob_hops" in sections:
            bench_blob_hops(report, 4 if args.quick else 8)
        if "optimizers" in sections:
            bench_optimizers(report, 200 if args.quick else 1000)
        if "study" in sections:
            bench_study(report, 1 if args.quick else 2, args.workers)
        goal_starts = args.starts or (2 if args.quick else 4)
        if "goal_degree10" in sections:
            bench_goal_degree10(report, goal_starts, args.workers)
        if "goal_blob" in sections:
            bench_goal_blob(report, goal_starts, args.workers)
        if "success_by_degree" in sections:
            bench_success_by_degree(report, 2 if args.quick else 4, args.workers,
                                    tuple(int(d) for d in args.degrees.split(",")))
        if "bunny" in sections:
            bench_bunny(report, 15 if args.quick else 40, 60 if args.quick else 100)
        if "mesh_log" in sections:
            bench_mesh_log(report, args.quick)
        if "mesh_all" in sections:
            bench_mesh_all(report, args.quick)
    report["machine"]["load_average_end"] = list(os.getloadavg())
    report["total_time_s"] = time.perf_counter() - t0
    _save(report)
    report.pop("ran")
    print(json.dumps({k: v for k, v in report.items() if k != "machine"}, indent=1)[:3000])


if __name__ == "__main__":
    main()
