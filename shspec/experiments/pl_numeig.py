"""``pl-numeig``: the PL inverse on the star surface r = 1 + 0.5|Y_3^3| against the number of eigenvalues K
(Section 3.2.1.2).

One target (the cotan spectrum of the star surface, ``max(numeig_values) + heldout`` eigenvalues) and its cMCF
sphere; for each K a fit of the per-vertex factors (:class:`MeshModel`) matches the first K eigenvalues.  Reported:
the error of the factors against the cMCF factors (same sphere, vertex by vertex), the residual on the K fitted
eigenvalues, and the *prediction* residual on the eigenvalues K..K_max + heldout that the fit did not see.
"""

from __future__ import annotations

import numpy as np

from ..inverse import FitOptions, Stage, fit
from ..fitting import mesh_target
from ..mesh.figures import plot_vertex_factors
from ..mesh import MeshModel, star_surface
from .base import Experiment, Finding, register
from .common import figure, save_figure
from .fitting import (Progress, harmonic_errors, single_threaded, spearman, spectral_residuals,
                      vertex_factor_errors, write_h5)


def run(cfg: dict, out, progress: bool) -> Finding:
    state = _compute(cfg, progress)
    write_h5(out / "results.h5", state["h5"])
    files = _figures(cfg, state, out)
    summary, numbers = _summary(cfg, state)
    return Finding(summary, {"pl_numeig": state["rows"]}, files, numbers)


def _compute(cfg: dict, progress: bool) -> dict:
    """The target, one fit per K and its row; also the HDF5 groups and the cMCF factors' own residuals."""
    l, m, p = cfg["l"], cfg["m"], cfg["p"]
    ks = sorted(cfg["numeig_values"])
    ktot = ks[-1] + cfg["heldout"]
    rows, h5, results = [], {}, []
    bar = Progress(progress, len(ks), "pl-numeig")
    with single_threaded():
        mesh = star_surface(l, m, p, cfg["subdivisions"])
        target = mesh_target(mesh, 12, ktot, cfg["lmax_factor"], name=f"star({l},{m},{p:g})")
        model = MeshModel(target.sphere)
        cmcf_lam = model.spectrum(target.factors, ktot).eigenvalues
        h5["target"] = {"sphere_vertices": target.sphere.vertices, "faces": target.sphere.faces,
                        "surface_vertices": mesh.vertices, "cmcf_factors": target.factors,
                        "target_eigenvalues": target.eigenvalues}
        for k in ks:
            result, row, lam = _fit(cfg, target, model, k, ktot)
            rows.append(row)
            h5[f"K={k}"] = {"fitted_factors": result.best.params, "fitted_eigenvalues": lam}
            results.append(result)
            bar.step(f"K = {k}: error {row['error_l2']:.3f}, residual {result.best.relative_residual:.1e}, "
                     f"unseen {row['unseen_residual_mean']:.1e}")
    return {"rows": rows, "h5": h5, "results": results, "ks": ks, "ktot": ktot, "mesh": mesh, "target": target,
            "cmcf_mean": spectral_residuals(cmcf_lam, target.eigenvalues)[1],
            "deviation": vertex_factor_errors(model.vertex_areas, target.factors, target.factors)["baseline_l2"]}


def _fit(cfg: dict, target, model, k: int, ktot: int) -> tuple:
    """The fit of the first k eigenvalues, its row and its first ``ktot`` eigenvalues."""
    opts = FitOptions(optimizer="lm", starts=cfg["starts"], max_iter=cfg["max_iter"], reg=cfg["reg"], seed=cfg["seed"],
                      schedule=(Stage(numeig=k),))
    result = fit(target, model, opts)
    best = result.best
    err = vertex_factor_errors(model.vertex_areas, best.params, target.factors)
    harm = harmonic_errors(target.sphere, best.params, target.factors, cfg["lmax_factor"])
    lam = model.spectrum(best.params, ktot).eigenvalues
    rel = np.abs(lam[1:] - target.eigenvalues[1:]) / target.eigenvalues[1:]
    row = {"numeig": k, "vertices": target.sphere.nvertices, "fit_residual_max": best.relative_residual,
           "fit_residual_mean": spectral_residuals(best.eigenvalues, target.eigenvalues[:k])[1],
           "unseen_residual_max": float(rel[k - 1:].max()),
           "unseen_residual_mean": float(rel[k - 1:].mean()),
           "error_l2": err["relative_l2"], "error_log_rms": err["log_rms"],
           "error_power": harm["power_error"], "iterations": best.iterations, "status": best.status,
           "seconds": result.seconds}
    return result, row, lam


def _figures(cfg: dict, state: dict, out) -> list:
    """The errors and residuals against K, and the factors of the largest K; returns the file names."""
    rows, ks, results = state["rows"], state["ks"], state["results"]
    kk = np.array(ks)
    fig, axes = figure(1, 2, width=13)
    axes[0].plot(kk, [r["error_l2"] for r in rows], "o-", label="factors, relative L2")
    axes[0].plot(kk, [r["error_power"] for r in rows], "s--", label="harmonic power (O(3) invariant)")
    axes[0].axhline(state["deviation"], color="k", ls=":", label="constant factor")
    axes[0].set_xlabel("number of fitted eigenvalues K")
    axes[0].set_ylabel("relative error against the cMCF factors")
    axes[0].legend(fontsize=8)
    axes[0].grid(True, alpha=0.3)
    for key, style in (("fit_residual_mean", "o-"), ("unseen_residual_mean", "s-"), ("unseen_residual_max", "^:")):
        axes[1].semilogy(kk, [max(r[key], 1e-17) for r in rows], style, label=key)
    axes[1].axhline(state["cmcf_mean"], color="k", ls=":", label="cMCF factors (mean)")
    axes[1].set_xlabel("number of fitted eigenvalues K")
    axes[1].set_ylabel(f"relative eigenvalue residual (unseen: K..{state['ktot'] - 1})")
    axes[1].legend(fontsize=8)
    axes[1].grid(True, which="both", alpha=0.3)
    save_figure(fig, out / "error_vs_numeig.png")
    fig = plot_vertex_factors(results[-1].model.mesh, results[-1].best.params, results[-1].target.factors)
    fig.suptitle(f"K = {ks[-1]}: cMCF factors, fitted factors, difference")
    save_figure(fig, out / "factors_largest_k.png")
    return ["error_vs_numeig.png", "factors_largest_k.png"]


def _summary(cfg: dict, state: dict) -> tuple[str, dict]:
    """The Finding's text and its key numbers."""
    l, m, p = cfg["l"], cfg["m"], cfg["p"]
    rows, ks, mesh, target = state["rows"], state["ks"], state["mesh"], state["target"]
    deviation, cmcf_mean = state["deviation"], state["cmcf_mean"]
    err = np.array([r["error_l2"] for r in rows])
    rho = spearman(np.array(ks), err)
    best_i = int(np.argmin(err))
    numbers = {"numeig": ks, "error_l2": err.tolist(), "unseen_residual_mean": [r["unseen_residual_mean"] for r in rows],
               "spearman_error_vs_numeig": rho, "cmcf_residual_mean": cmcf_mean}
    summary = (
        f"On the star surface r = 1 + {p:g}|Y_{l}^{m}| ({mesh.nvertices} vertices; {target.factors.min():.2f} ≤ cMCF "
        f"factor ≤ {target.factors.max():.2f}, relative L2 deviation {deviation:.3f} from the constant) the PL fit "
        f"of the first K eigenvalues (K = {', '.join(map(str, ks))}; {cfg['starts']} start(s), at most "
        f"{cfg['max_iter']} iterations) reaches largest fitted residuals of "
        + ", ".join(f"{r['fit_residual_max']:.0e}" for r in rows)
        + ". The factor error against cMCF is " + ", ".join(f"{e:.3f}" for e in err)
        + f" (Spearman correlation with K {rho:.2f}; smallest {err[best_i]:.3f} at K = {ks[best_i]}), and the mean "
        f"relative residual on the unseen eigenvalues up to {state['ktot'] - 1} is "
        + ", ".join(f"{r['unseen_residual_mean']:.1e}" for r in rows)
        + f", against {cmcf_mean:.1e} for the cMCF factors themselves. The fits stop by "
        + ", ".join(f"{r['status']} (K={r['numeig']})" for r in rows)
        + ". More eigenvalues "
        + ("pull the fit towards the cMCF factors" if rho < -0.8 else "do not clearly pull the fit towards the cMCF "
           "factors")
        + f": with {mesh.nvertices} free factors even K = {ks[-1]} leaves the problem underdetermined.")
    return summary, numbers


register(Experiment(
    name="pl-numeig", title="PL inverse on a |Y_3^3| star versus the number of eigenvalues",
    reproduces="the study's Section 3.2.1.2 (performance against the number of optimized eigenvalues, p = 0.5)",
    defaults={"l": 3, "m": 3, "p": 0.5, "numeig_values": [10, 20, 40, 80, 120], "heldout": 40, "subdivisions": 3,
              "lmax_factor": 8, "starts": 1, "max_iter": 100, "reg": 0.0, "seed": 0},
    quick={"l": 3, "m": 3, "p": 0.5, "numeig_values": [8, 16, 32], "heldout": 16, "subdivisions": 2,
           "lmax_factor": 6, "starts": 1, "max_iter": 15, "reg": 0.0, "seed": 0},
    expected_minutes=1.5, run=run))
