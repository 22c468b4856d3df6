"""``sh-perturbation``: the study's Section 3.2.1 in the harmonic basis: star surfaces r = 1 + p|Y_l^m| heard by a
planned log-ρ fit, beside the PL fit, against the perturbation p.

For each shape (l, m) (the study's |Y_3^3| and |Y_3^2| stars) and each p of the sweep, the target is the cotan
spectrum of the star (icosphere of ``subdivisions``), as ``shspec fit --target star:...`` takes it:

* the harmonic fit: the spectrum Richardson-extrapolated from two subdivisions, with its error
  (:func:`~shspec.fitting.targets.refined_target`), the plan of a log-ρ fit from the first ``numeig`` eigenvalues
  (:func:`~shspec.fitting.surface_plan.plan_surface_fit`: La, K and Lb from the floor of the basis against the
  target's errors, the predicted error), and the fit (:class:`~shspec.galerkin.log_model.LogHarmonicModel`, held to
  the plan's errors).  Where the plan finds the basis beyond its reach (``beyond_basis``: the floor at every La it
  analyses exceeds the accuracy asked for) nothing is fitted, the row says why, and the sweep of that shape ends
  there.  The fitted ρ, aligned with the cMCF factors up to Möbius and O(3), is compared with them at the cMCF
  vertices (:func:`~shspec.inverse.output.surface_record`: factor error, error bar, log correlation, floor);
* the PL fit with the study's settings (Section 3.2.2: log factors on the target's own cMCF sphere, the
  cotan-squared penalty R, ``pl_numeig_fraction`` of the vertices' eigenvalues, L-BFGS from the constant factor),
  compared vertex by vertex (:meth:`MeshModel.compare <shspec.mesh.MeshModel.compare>`);
* the re-embedding (:func:`~shspec.embed.embed`) of the harmonic fit's factors (sampled at the cMCF vertices), of
  the PL fit's and of the cMCF factors themselves, each as its Hausdorff distance to the star after rigid alignment
  over the bounding-box diagonal (:func:`~shspec.embed.surface_distance`);
* at the p of ``fixed_p``, a log-ρ fit of degree ``fixed_degree`` from all ``numeig`` eigenvalues, whatever the plan
  says (its basis Lb and errors from :func:`plan_surface_fit` restricted to that La and K): what the basis does
  beyond the plan's choice.
"""

from __future__ import annotations

import time

import numpy as np

from ..embed import EmbedOptions, embed, surface_distance
from ..errors import InvalidArgumentError, ShspecError
from ..galerkin.log_model import LogHarmonicModel
from ..inverse import FitOptions, fit
from ..inverse.output import surface_record
from ..fitting.surface_plan import plan_surface_fit
from ..mesh import MeshModel, cmcf, star_surface
from ..sphere.evaluate import sample_harmonic
from ..fitting.targets import mesh_target, refined_target
from .base import Experiment, Finding, register
from .common import figure, save_figure
from .fitting import Progress, single_threaded

#: Basis degree of the target's harmonic spectrum: unused by a cotan ("pl") target, required by mesh_target.
_TARGET_LMAX = 30


def _hausdorff(sphere, factors, mesh, options: EmbedOptions) -> tuple[float, bool]:
    """Re-embed per-vertex factors on a cMCF sphere: the Hausdorff distance to ``mesh`` over its bounding-box
    diagonal, and whether the embedding succeeded (NaN, False for factors that are not positive everywhere)."""
    if not np.all(np.asarray(factors) > 0):
        return float("nan"), False
    emb = embed(sphere, factors, options)
    return surface_distance(emb.mesh, mesh).hausdorff_relative, bool(emb.success)


def _no_fit(status: str) -> dict:
    """The columns of a log-ρ fit, empty, with its status."""
    return {"fit_success": False, "factor_error": float("nan"), "error_bar": float("nan"),
            "log_correlation": float("nan"), "fit_residual_max": float("nan"), "hausdorff_fit": float("nan"),
            "fit_seconds": 0.0, "fit_status": status}


def _log_fit(target, plan, mesh, cfg, eopt) -> dict:
    """The log-ρ fit of ``plan`` on the refined ``target``: its errors against the cMCF factors, its re-embedding."""
    out = _no_fit("")
    t0 = time.perf_counter()
    try:
        result = fit(plan.fitted_target(target), LogHarmonicModel(plan.lmax, plan.lmax_factor),
                     FitOptions(starts=cfg["starts"], seed=cfg["seed"]))
        record = surface_record(result) or {}
        best = result.best
        out.update(fit_success=bool(best.success), fit_residual_max=best.relative_residual,
                   fit_status=best.status, **{k: float(record[k]) for k in ("factor_error", "error_bar",
                                                                           "log_correlation") if k in record})
        if "skipped" in record:
            out["fit_status"] += f"; {record['skipped']}"
        else:
            c_fit = sample_harmonic(result.alignment().aligned, target.sphere.vertices)
            out["hausdorff_fit"] = _hausdorff(target.sphere, c_fit, mesh, eopt)[0]
    except ShspecError as exc:  # a failed fit is a result of the sweep, said in its row
        out["fit_status"] = f"failed: {exc}"
    out["fit_seconds"] = time.perf_counter() - t0
    return out


def _pl_fit(mesh, flow, cfg, eopt) -> dict:
    """The PL fit with the study's settings on the star's own cMCF sphere, and its re-embedding."""
    k = min(max(2, round(cfg["pl_numeig_fraction"] * mesh.nvertices)), mesh.nvertices - 1)
    target = mesh_target(mesh, _TARGET_LMAX, k, cfg["truth_degree"], flow=flow)
    model = MeshModel(target.sphere, transform="exp", reg_kind=cfg["pl_reg_kind"])
    t0 = time.perf_counter()
    result = fit(target, model, FitOptions(optimizer=cfg["pl_optimizer"], schedule=(), starts=1, basin_hops=0,
                                           start_amplitude=1e-3, reg=cfg["pl_reg"], max_iter=cfg["pl_max_iter"],
                                           seed=cfg["seed"]))
    best = result.best
    compared = model.compare(best.params, target)
    return {"pl_numeig": k, "pl_factor_error": compared["factor_error"],
            "pl_log_correlation": compared["log_correlation"], "pl_residual_max": best.relative_residual,
            "hausdorff_pl": _hausdorff(target.sphere, best.params, mesh, eopt)[0],
            "pl_seconds": time.perf_counter() - t0}


def _check(cfg: dict) -> list[tuple[int, int]]:
    shapes = []
    for shape in cfg["shapes"]:
        if not (isinstance(shape, list) and len(shape) == 2 and all(isinstance(x, int) for x in shape)):
            raise InvalidArgumentError(f"sh-perturbation.shapes holds [l, m] pairs of integers, got {shape!r}")
        shapes.append((shape[0], shape[1]))
    if list(cfg["p_values"]) != sorted(cfg["p_values"]) or not all(p > 0 for p in cfg["p_values"]):
        raise InvalidArgumentError(f"sh-perturbation.p_values must be positive and increasing (the sweep stops at "
                                   f"the first p beyond the basis), got {cfg['p_values']}")
    if not 0 < cfg["pl_numeig_fraction"] < 1:
        raise InvalidArgumentError(f"pl_numeig_fraction must be in (0, 1), got {cfg['pl_numeig_fraction']}")
    return shapes


def _row(l, m, p, mesh, flow, cfg, eopt) -> tuple[dict, dict | None]:
    """One (shape, p): the plan, the harmonic fit (unless beyond the basis), the PL fit, the re-embeddings; and the
    row of the fit at the fixed degree when p is one of ``fixed_p``."""
    target = refined_target(mesh_target(mesh, _TARGET_LMAX, cfg["numeig"], cfg["truth_degree"],
                                        name=f"star({l},{m},{p:g})", flow=flow))
    t0 = time.perf_counter()
    plan = plan_surface_fit(target, accuracy=cfg["accuracy"])
    blind = [r for r in plan.rows if not np.isfinite(r.noise)]
    row = {"shape": f"Y_{l}^{m}", "p": p, "vertices": mesh.nvertices,
           "factor_min": float(flow.factors.min()), "factor_max": float(flow.factors.max()),
           "plan": "beyond basis" if plan.beyond_basis else ("feasible" if plan.feasible else "infeasible"),
           "lmax_factor": plan.lmax_factor, "numeig": plan.numeig, "lmax": plan.lmax, "floor": plan.floor,
           "predicted": plan.predicted, "floor_degree": plan.floor_degree,
           "best_floor_analysed": min(r.floor for r in plan.rows),
           "candidates_without_error_bar": f"{len(blind)}/{len(plan.rows)}",
           "plan_seconds": time.perf_counter() - t0}
    if plan.beyond_basis:
        row.update(_no_fit("not attempted: beyond the basis"))
    else:
        row.update(_log_fit(target, plan, mesh, cfg, eopt))
    row.update(_pl_fit(mesh, flow, cfg, eopt))
    row["hausdorff_cmcf"], row["cmcf_embedding_success"] = _hausdorff(flow.sphere, flow.factors, mesh, eopt)
    row["diagnosis"] = plan.diagnosis()
    fixed = None
    if cfg["fixed_degree"] and p in cfg["fixed_p"]:
        forced = plan_surface_fit(target, accuracy=cfg["accuracy"], candidates=[cfg["fixed_degree"]],
                                  numeigs=[target.numeig])
        fixed = {"shape": row["shape"], "p": p, "lmax_factor": forced.lmax_factor, "numeig": forced.numeig,
                 "lmax": forced.lmax, "floor": forced.floor,
                 "first_order_error_bar": forced.rows[0].noise, **_log_fit(target, forced, mesh, cfg, eopt),
                 "planned_factor_error": row["factor_error"]}
    return row, fixed


def _range(values) -> str:
    """The finite values of a sweep as 'smallest to largest', or the one value, or 'none'."""
    v = [x for x in values if np.isfinite(x)]
    return "none" if not v else f"{v[0]:.2g}" if len(v) == 1 else f"{min(v):.2g} to {max(v):.2g}"


def _span(values) -> str:
    """Integers as 'a' or 'a to b' (smallest, largest)."""
    lo, hi = min(values), max(values)
    return f"{lo}" if lo == hi else f"{lo} to {hi}"


def _shape_summary(shape: str, rows: list, largest_p: float) -> str:
    fitted = [r for r in rows if r["plan"] != "beyond basis"]
    text = f"On the |{shape}| star"
    if fitted:
        text += (f", p = {_range([r['p'] for r in fitted])}: the plan took La = "
                 f"{_span([r['lmax_factor'] for r in fitted])} from K = {_span([r['numeig'] for r in fitted])} "
                 f"eigenvalues on Lb = {_span([r['lmax'] for r in fitted])}; the harmonic fit's factor error was "
                 f"{_range([r['factor_error'] for r in fitted])} (floor {_range([r['floor'] for r in fitted])}, "
                 f"predicted {_range([r['predicted'] for r in fitted])}, within the accuracy asked at "
                 f"{sum(r['plan'] == 'feasible' for r in fitted)} of {len(fitted)} p; "
                 f"{sum(r['fit_success'] for r in fitted)} of {len(fitted)} fits reached the target within its "
                 f"errors; correlation of log rho with log c {_range([r['log_correlation'] for r in fitted])}), the PL "
                 f"fit's {_range([r['pl_factor_error'] for r in fitted])} (log correlation "
                 f"{_range([r['pl_log_correlation'] for r in fitted])}); re-embedded, the harmonic fit lies at a "
                 f"Hausdorff distance of {_range([r['hausdorff_fit'] for r in fitted])}, the PL fit at "
                 f"{_range([r['hausdorff_pl'] for r in fitted])} and the cMCF factors themselves at "
                 f"{_range([r['hausdorff_cmcf'] for r in fitted])} (their embedding flagged unsuccessful at "
                 f"{sum(not r['cmcf_embedding_success'] for r in fitted)} of {len(fitted)} p)")
    beyond = [r for r in rows if r["plan"] == "beyond basis"]
    if beyond:
        r = beyond[0]
        text += (f"; at p = {r['p']:g} the basis fails, and the sweep ends: {r['diagnosis']} (the PL fit there: "
                 f"factor error {r['pl_factor_error']:.2g}, Hausdorff {r['hausdorff_pl']:.2g})")
    else:
        text += f"; the basis did not fail up to the largest p of the sweep, {largest_p:g}"
    return text + "."


#: What the figure's panels plot per shape: column, line style, legend.
_ERROR_LINES = (("factor_error", "o-", "harmonic fit"), ("pl_factor_error", "s--", "PL fit"),
                ("floor", ":", "floor of the planned La"), ("predicted", "x", "predicted by the plan"))
_DISTANCE_LINES = (("hausdorff_fit", "o-", "harmonic fit"), ("hausdorff_pl", "s--", "PL fit"),
                   ("hausdorff_cmcf", "^:", "cMCF factors"))


def _figure(rows: list, fixed: list, out) -> None:
    from matplotlib.lines import Line2D

    fig, axes = figure(1, 2, width=13, height=5.4)
    shapes = list(dict.fromkeys(r["shape"] for r in rows))
    for i, shape in enumerate(shapes):
        sub = [r for r in rows if r["shape"] == shape]
        ps, colour = np.array([r["p"] for r in sub]), f"C{i}"
        for ax, lines in ((axes[0], _ERROR_LINES), (axes[1], _DISTANCE_LINES)):
            for key, style, _ in lines:
                ax.plot(ps, [r[key] for r in sub], style, color=colour)
            for r in sub:
                if r["plan"] == "beyond basis":
                    ax.axvline(r["p"], color=colour, alpha=0.3, lw=4)
        extra = [r for r in fixed if r["shape"] == shape and np.isfinite(r["factor_error"])]
        axes[0].plot([r["p"] for r in extra], [r["factor_error"] for r in extra], "D", color=colour, mfc="none")
    shape_handles = [Line2D([], [], color=f"C{i}", lw=4, alpha=0.6, label=f"$|{s}|$ star")
                     for i, s in enumerate(shapes)]
    degrees = sorted({r["lmax_factor"] for r in fixed})
    extra_handles = ([Line2D([], [], color="k", ls="", marker="D", mfc="none",
                             label=f"fit at La = {', '.join(map(str, degrees))}, beyond the plan")] if fixed else [])
    for ax, lines in ((axes[0], _ERROR_LINES), (axes[1], _DISTANCE_LINES)):
        handles = [Line2D([], [], color="k", ls=style.lstrip("osx^") or "", marker=style[0] if style[0] in "osx^"
                          else "", label=label) for _, style, label in lines]
        # below the panel: inside, it hides points wherever the sweep puts them
        ax.legend(handles=handles + (extra_handles if ax is axes[0] else []) + shape_handles, fontsize=8, ncol=3,
                  loc="upper center", bbox_to_anchor=(0.5, -0.14))
        ax.set_xlabel("perturbation p")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_yscale("log")
    axes[0].set_ylabel("relative L2 error of the factors against cMCF")
    axes[0].set_title("factor error (shaded: the plan finds the basis beyond reach; the sweep ends)", fontsize=10)
    axes[1].set_ylabel("Hausdorff distance / bounding-box diagonal")
    axes[1].set_title("re-embedded factors against the star", fontsize=10)
    save_figure(fig, out / "error_vs_p.png")


def run(cfg: dict, out, progress: bool) -> Finding:
    shapes = _check(cfg)
    eopt = EmbedOptions()
    rows, fixed = [], []
    bar = Progress(progress, len(shapes) * len(cfg["p_values"]), "sh-perturbation")
    with single_threaded():
        for l, m in shapes:
            for p in cfg["p_values"]:
                mesh = star_surface(l, m, p, cfg["subdivisions"])
                row, extra = _row(l, m, p, mesh, cmcf(mesh), cfg, eopt)
                rows.append(row)
                if extra is not None:
                    fixed.append(extra)
                bar.step(f"|Y_{l}^{m}| p = {p:g}: plan {row['plan']} (La {row['lmax_factor']}, floor "
                         f"{row['floor']:.2g}), harmonic {row['factor_error']:.2g}, PL {row['pl_factor_error']:.2g}")
                if row["plan"] == "beyond basis":
                    break
    bar.bar.close()  # the sweeps that end early leave steps undone
    _figure(rows, fixed, out)
    blind = [tuple(map(int, r["candidates_without_error_bar"].split("/"))) for r in rows]
    summary = (f"Star surfaces r = 1 + p|Y_l^m| ({rows[0]['vertices']} vertices) heard by a log-rho fit planned from "
               f"the first {cfg['numeig']} cotan eigenvalues extrapolated from two subdivisions (accuracy asked "
               f"{cfg['accuracy']:g}), beside the PL fit with the study's settings (log factors, R = "
               f"{cfg['pl_reg']:g}, {cfg['pl_numeig_fraction']:.0%} of the eigenvalues). "
               + " ".join(_shape_summary(s, [r for r in rows if r["shape"] == s], cfg["p_values"][-1])
                          for s in dict.fromkeys(r["shape"] for r in rows)))
    if any(b for b, _ in blind):
        summary += (f" The plan had no first-order error bar (a rank-deficient Jacobian: the spectrum does not see "
                    f"some directions of rho at first order) at {sum(b for b, _ in blind)} of its "
                    f"{sum(n for _, n in blind)} candidate (La, K) pairs, and chose among the others.")
    if fixed:
        summary += (" Fits of degree La = " + ", ".join(sorted({str(r["lmax_factor"]) for r in fixed}))
                    + " from all eigenvalues, beyond the plan: "
                    + "; ".join(f"|{r['shape']}| p = {r['p']:g}: "
                                + (f"factor error {r['factor_error']:.2g} (floor {r['floor']:.2g}, the planned fit "
                                   f"{r['planned_factor_error']:.2g})" if np.isfinite(r["factor_error"])
                                   else r["fit_status"])
                                for r in fixed) + ".")
    numbers = {shape: {key: [r[key] for r in rows if r["shape"] == shape]
                       for key in ("p", "plan", "lmax_factor", "numeig", "lmax", "floor", "predicted",
                                   "factor_error", "error_bar", "pl_factor_error", "hausdorff_fit", "hausdorff_pl",
                                   "hausdorff_cmcf")}
               for shape in dict.fromkeys(r["shape"] for r in rows)}
    for shape, v in numbers.items():
        v["beyond_basis_p"] = next((p for p, s in zip(v["p"], v["plan"]) if s == "beyond basis"), None)
    for shape, v in numbers.items():
        v["diagnosis"] = [r["diagnosis"] for r in rows if r["shape"] == shape]
    tables = {"sh_perturbation": [{k: v for k, v in r.items() if k != "diagnosis"} for r in rows]}
    if fixed:
        tables["sh_perturbation_fixed_degree"] = fixed
    return Finding(summary, tables, ["error_vs_p.png"], numbers)


register(Experiment(
    name="sh-perturbation", title="Harmonic (log-rho) inverse on star surfaces versus the perturbation p",
    reproduces="the study's Section 3.2.1 (|Y_3^3| and |Y_3^2| stars) in the harmonic basis, beside the PL fit",
    defaults={"shapes": [[3, 3], [3, 2]], "p_values": [0.1, 0.2, 0.3, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0],
              "subdivisions": 3, "numeig": 160, "truth_degree": 16, "accuracy": 0.05, "starts": 4, "seed": 0,
              "pl_numeig_fraction": 0.95, "pl_reg": 0.05, "pl_reg_kind": "cotan-squared", "pl_optimizer": "lbfgs",
              "pl_max_iter": 300, "fixed_degree": 6, "fixed_p": [1.0]},
    quick={"shapes": [[3, 3], [3, 2]], "p_values": [0.1, 1.0], "subdivisions": 2, "numeig": 40, "truth_degree": 8,
           "accuracy": 0.05, "starts": 1, "seed": 0, "pl_numeig_fraction": 0.95, "pl_reg": 0.05,
           "pl_reg_kind": "cotan-squared", "pl_optimizer": "lbfgs", "pl_max_iter": 30, "fixed_degree": 3,
           "fixed_p": [0.1]},
    expected_minutes=15.0, run=run))
