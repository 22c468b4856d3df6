"""``pl-bunny``: the regularized PL inverse of the bunny (Section 3.2.2, Figure 1), the same for spot and blub, the
recursive fit (Section 3.2.3, Figure 2), the exactly representable target and the adaptive fit from an icosphere.

Each run ``"MESH:R"`` loads the mesh MESH (shipped, or ``MESH.obj`` from ``mesh_dir``), scales it to area 4π (the mean factor is then 1), takes
its cotan spectrum (its first K = ``numeig_fraction``·n eigenvalues, target (a); the study's own runs used 95 % of
them, "e0.95" in its figure names: K = 570 for 600 vertices, 1140 for 1200) and fits log factors s = log c on its
own cMCF sphere with the study's penalty R ‖Ls‖²/2 (``reg_kind="cotan-squared"``, the form of ``eigencost.m``
behind its figures: dimensionless, so the study's R = 0.05 means the same here; ``"dirichlet"`` gives the earlier
runs' R sᵀLs/2).  The fit and the cMCF factors are compared vertex by vertex through log c (RMS of log(c/c*),
Pearson correlation over the vertices, unweighted and area weighted) and re-embedded (:func:`shspec.embed.embed`)
for the Hausdorff distance to the mesh, over its bounding diagonal.

For the first run also: target (b), the spectrum of the cMCF sphere carrying the cMCF factors (exactly
representable), fitted along a regularization path down to R = 0, with the RMS log error over the directions the
eigenvalues determine (:func:`shspec.inverse.identifiability.determined_directions`); the adaptive fit from a
generic icosphere (:func:`shspec.fitting.adaptive.adaptive_fit`, aligned to the truth by Möbius + O(3)); and the
recursive fit (:func:`shspec.fitting.recursive.recursive_fit` with ``warm_start="init"``: fit, embed, cMCF of the
embedding, fit again from the transferred factors, embed again) at the recursive R.
"""

from __future__ import annotations

import time

import numpy as np

from ..embed import EmbedOptions, embed, render_mesh, surface_distance
from ..errors import InvalidArgumentError
from ..inverse import FitOptions, fit
from ..fitting import mesh_target
from ..inverse.identifiability import determined_directions
from ..mesh import MeshModel, cmcf, plot_hammer
from ..fitting.adaptive import AdaptiveOptions, adaptive_fit
from ..fitting.recursive import RecursiveOptions, recursive_fit
from .base import Experiment, Finding, register
from .common import MESH_DIR, load_mesh_area_4pi, save_figure
from .fitting import Progress, single_threaded, vertex_factor_errors, write_h5


def _parse_run(text: str) -> tuple[str, float]:
    name, _, reg = text.partition(":")
    try:
        return name, float(reg or 0.0)
    except ValueError:
        raise InvalidArgumentError(f"a pl-bunny run is 'MESH:R', got {text!r}") from None


def _options(cfg, reg, optimizer=None, max_iter=None):
    return FitOptions(schedule=(), starts=1, basin_hops=0, start_amplitude=1e-3, reg=reg,
                      optimizer=optimizer or cfg["optimizer"], max_iter=max_iter or cfg["max_iter"], seed=cfg["seed"])


def _errors(model, c, truth) -> dict:
    """Vertex-by-vertex errors of fitted factors c against the truth on the model's own mesh (as in summary.json)."""
    w = vertex_factor_errors(model.vertex_areas, c, truth)
    return {"log_rms": w["log_rms"], "log_correlation": float(np.corrcoef(np.log(c), np.log(truth))[0, 1]),
            "log_correlation_area_weighted": w["log_correlation"], "fitted_min": float(np.min(c)),
            "fitted_max": float(np.max(c)), "cmcf_min": float(np.min(truth)), "cmcf_max": float(np.max(truth))}


def _hausdorff(sphere, c, mesh, eopt: EmbedOptions, samples: int) -> tuple:
    """The embedding of factors c on ``sphere`` and its Hausdorff distance to ``mesh`` over the bounding diagonal."""
    e = embed(sphere, c, eopt)
    return e.mesh, surface_distance(e.mesh, mesh, samples=samples).hausdorff_relative


def run(cfg: dict, out, progress: bool) -> Finding:
    state = _compute(cfg, progress)
    write_h5(out / "results.h5", state["h5"])
    files = _figures(cfg, state, out)
    summary, numbers = _summary(cfg, state)
    return Finding(summary, {"pl_bunny": numbers["runs"]}, files, numbers)


def _compute(cfg: dict, progress: bool) -> dict:
    """Every run's fit on its own cMCF sphere; for the first run also target (b), the adaptive and recursive fits."""
    if not 0 < cfg["numeig_fraction"] < 1:
        raise InvalidArgumentError(f"numeig_fraction must be in (0, 1), got {cfg['numeig_fraction']}")
    runs = [_parse_run(r) for r in cfg["runs"]]
    bar = Progress(progress, 2 * len(runs) + 3, "pl-bunny")
    eopt = EmbedOptions(final_iterations=cfg["embed_iterations"], check_intersections=False)
    rows, h5, panels, first = [], {}, [], None
    with single_threaded():
        for name, reg in runs:
            row, panel, h5[f"{name} R={reg:g}"], fitted = _own_sphere_fit(cfg, name, reg, eopt, bar)
            rows.append(row)
            panels.append(panel)
            first = first or fitted
        rows.append(_target_b(cfg, first, bar))
        rows.append(_adaptive(cfg, first, rows[0]["log_rms"], eopt, bar))
        rec, rec_rows = _recursive(cfg, first, eopt, bar)
        rows += rec_rows
    return {"rows": rows, "h5": h5, "panels": panels, "recursive": rec}


def _own_sphere_fit(cfg: dict, name: str, reg: float, eopt: EmbedOptions, bar: Progress) -> tuple:
    """Run "name:reg" on the mesh's own cMCF sphere: its row, its figure panel, its HDF5 group, and (name, reg, mesh,
    target, flow, K) for the first run's further fits."""
    mesh = load_mesh_area_4pi(cfg["mesh_dir"], name)
    k = max(2, int(round(cfg["numeig_fraction"] * mesh.nvertices)))
    flow = cmcf(mesh)
    target = mesh_target(mesh, 12, k, 6, name=name, flow=flow)
    model = MeshModel(target.sphere, transform="exp", reg_kind=cfg["reg_kind"])
    t0 = time.process_time()
    result = fit(target, model, _options(cfg, reg))
    cpu = time.process_time() - t0
    best = result.best
    row = {"run": f"{name} R={reg:g}", "case": "(a) own cMCF sphere", "vertices": mesh.nvertices,
           "relative_residual": best.relative_residual, **_errors(model, best.params, target.factors),
           "iterations": best.iterations, "status": best.status, "cpu_s": cpu}
    bar.step(f"{name} R = {reg:g}: residual {best.relative_residual:.2e}, log correlation "
             f"{row['log_correlation']:.2f}")
    samples = cfg["distance_samples"]
    emb_fit, row["embedded_hausdorff"] = _hausdorff(target.sphere, best.params, mesh, eopt, samples)
    emb_true, row["cmcf_embedded_hausdorff"] = _hausdorff(target.sphere, target.factors, mesh, eopt, samples)
    bar.step(f"{name}: embedded fit at Hausdorff {row['embedded_hausdorff']:.3f}, cMCF factors "
             f"{row['cmcf_embedded_hausdorff']:.3f}")
    row["numeig"] = k
    panel = (name, reg, target.sphere, target.factors, best.params, mesh, emb_true, emb_fit)
    group = {"sphere_vertices": target.sphere.vertices, "faces": mesh.faces, "cmcf_factors": target.factors,
             "fitted_factors": best.params, "target_eigenvalues": target.eigenvalues}
    return row, panel, group, (name, reg, mesh, target, flow, k)


def _target_b(cfg: dict, first: tuple, bar: Progress) -> dict:
    """Target (b), the exactly representable one, fitted along the regularization path ending at R = 0: its row."""
    name, reg, mesh, _, flow, k = first
    tb = mesh_target(mesh, 12, k, 6, name=name, source="cmcf", flow=flow)
    model = MeshModel(tb.sphere, transform="exp", reg_kind=cfg["reg_kind"])
    c, t0 = None, time.process_time()
    for r in cfg["path"]:
        c = fit(tb, model, _options(cfg, r), init=c).best.params
    res = fit(tb, model, _options(cfg, 0.0), init=c).best
    B = determined_directions(model, tb.factors, k)
    d = np.log(res.params) - np.log(tb.factors)
    row = {"run": f"{name} path {cfg['path']} -> 0", "case": "(b) cMCF sphere + factors",
           "vertices": mesh.nvertices, "relative_residual": res.relative_residual,
           **_errors(model, res.params, tb.factors), "iterations": res.iterations, "status": res.status,
           "cpu_s": time.process_time() - t0, "determined_directions": int(B.shape[1]),
           "log_rms_determined": float(np.linalg.norm(B.T @ d) / np.sqrt(d.size))}
    bar.step(f"(b): residual {res.relative_residual:.2e}, RMS log error over {B.shape[1]} determined "
             f"directions {row['log_rms_determined']:.3g}")
    return row


def _adaptive(cfg: dict, first: tuple, own_log_rms: float, eopt: EmbedOptions, bar: Progress) -> dict:
    """The adaptive fit from an icosphere of the first run's target: its row."""
    name, reg, mesh, target, _, _ = first
    t0 = time.process_time()
    ad = adaptive_fit(target, AdaptiveOptions(subdivisions=cfg["adaptive_subdivisions"],
                                              reg_kind=cfg["reg_kind"], fit=_options(cfg, reg)))
    cmp = ad.result.model.compare(ad.result.best.params, target)
    row = {"run": f"{name} R={reg:g} sizes {[st.nvertices for st in ad.stages]}",
           "case": "(a) adaptive from an icosphere", "vertices": ad.stages[-1].nvertices,
           "relative_residual": ad.result.best.relative_residual, "log_rms": cmp["log_rms"],
           "log_rms_centred": cmp["log_rms_centred"],
           "log_correlation": cmp["log_correlation"], "fitted_min": cmp["fitted_range"][0],
           "fitted_max": cmp["fitted_range"][1], "iterations": ad.result.best.iterations,
           "status": ad.result.best.status, "cpu_s": time.process_time() - t0,
           "log_rms_ratio_to_own_sphere": cmp["log_rms"] / own_log_rms}
    # the re-embedding needs no alignment, which the log error does (a Möbius centring weighted by the fit)
    row["embedded_hausdorff"] = _hausdorff(ad.result.model.mesh, ad.result.best.params, mesh, eopt,
                                           cfg["distance_samples"])[1]
    bar.step(f"adaptive: log RMS {cmp['log_rms']:.3f} ({row['log_rms_ratio_to_own_sphere']:.2f}x own "
             f"sphere), embedded at Hausdorff {row['embedded_hausdorff']:.3f}")
    return row


def _recursive(cfg: dict, first: tuple, eopt: EmbedOptions, bar: Progress) -> tuple:
    """The recursive fit (Figure 2) of the first run's target: the result and a row per pass."""
    name, _, mesh, target, _, _ = first
    rec = recursive_fit(target, options=RecursiveOptions(
        passes=2, fit=_options(cfg, cfg["recursive_reg"]), embed=eopt, warm_start="init", log_factors=True,
        reg_kind=cfg["reg_kind"]))
    rows = [{"run": f"{name} R={cfg['recursive_reg']:g} pass {j + 1}", "case": "recursive",
             "vertices": mesh.nvertices, "relative_residual": ps.fit_residual,
             "fitted_min": float(ps.factors.min()), "fitted_max": float(ps.factors.max()),
             "status": ps.fit_status, "cpu_s": ps.cpu_seconds, "embedded_hausdorff": ps.hausdorff_relative}
            for j, ps in enumerate(rec.passes)]
    bar.step(f"recursive: Hausdorff {rec.passes[0].hausdorff_relative:.3f} -> {rec.final.hausdorff_relative:.3f}")
    return rec, rows


def _wide_figure():
    """An empty figure for a row of five panels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.figure(figsize=(22, 4.2))


def _render_row(fig, meshes) -> None:
    """Panels 3 to 5 of ``fig``: the (title, mesh) pairs rendered in 3D."""
    for j, (title, m) in enumerate(meshes):
        render_mesh(m, ax=fig.add_subplot(1, 5, j + 3, projection="3d"), up="y", view=(15.0, 30.0), title=title)


def _figures(cfg: dict, state: dict, out) -> list:
    """Figure 1 for every run and Figure 2 for the recursive fit; returns the file names."""
    files = []
    for (name, reg, sphere, truth, c, mesh, emb_true, emb_fit) in state["panels"]:
        fig = _wide_figure()
        lo, hi = np.log10(truth).min(), np.log10(truth).max()
        for j, (title, v) in enumerate((("log10 c: cMCF factors", truth), ("log10 c: fit", c))):
            ax = fig.add_subplot(1, 5, j + 1, projection="hammer")
            plot_hammer(sphere, np.clip(np.log10(v), lo, hi), ax=ax, title=title, percentiles=(0.0, 100.0))
        _render_row(fig, ((f"{name} (target)", mesh), ("embedded cMCF factors", emb_true),
                          (f"embedded fit, R = {reg:g}", emb_fit)))
        files.append(f"figure1_{name}.png" if f"figure1_{name}.png" not in files else f"figure1_{name}_R{reg:g}.png")
        save_figure(fig, out / files[-1])
    name, mesh = state["panels"][0][0], state["panels"][0][5]  # the recursive fit is the first run's
    fig = _wide_figure()
    p1, p2 = state["recursive"].passes
    for j, (title, sphere, c) in enumerate((("log10 c: pass 1 (cMCF sphere)", p1.sphere, p1.factors),
                                            ("log10 c: pass 2 (its own sphere)", p2.sphere, p2.factors))):
        plot_hammer(sphere, np.log10(c), ax=fig.add_subplot(1, 5, j + 1, projection="hammer"), title=title)
    _render_row(fig, ((f"{name} (target)", mesh), ("embedded pass 1", p1.embedding.mesh),
                      ("embedded pass 2 (recursive)", p2.embedding.mesh)))
    files.append("figure2_recursive.png")
    save_figure(fig, out / files[-1])
    return files


def _summary(cfg: dict, state: dict) -> tuple[str, dict]:
    """The Finding's text and its key numbers (every row, padded to one table of equal keys)."""
    rows = state["rows"]
    fits = [r for r in rows if r["case"] == "(a) own cMCF sphere"]
    b = next(r for r in rows if r["case"].startswith("(b)"))
    a = next(r for r in rows if r["case"].startswith("(a) adaptive"))
    recs = [r for r in rows if r["case"] == "recursive"]
    summary = (
        f"Log-factor PL fits with the penalty {cfg['reg_kind']} (area 4π, the first {cfg['numeig_fraction']:.0%} of "
        f"the cotan eigenvalues, "
        f"one start from the constant factors on the mesh's own cMCF sphere, {cfg['optimizer']}, at most "
        f"{cfg['max_iter']} iterations): "
        + "; ".join(f"{r['run']} (K = {r['numeig']}): residual {r['relative_residual']:.2e}, fitted "
                    f"{r['fitted_min']:.2g}..{r['fitted_max']:.2g}"
                    f" against cMCF {r['cmcf_min']:.2g}..{r['cmcf_max']:.2g}, log RMS {r['log_rms']:.2f}, log "
                    f"correlation {r['log_correlation']:.2f} (area weighted {r['log_correlation_area_weighted']:.2f}), "
                    f"re-embedded at Hausdorff {r['embedded_hausdorff']:.3f} of the diagonal (cMCF factors "
                    f"{r['cmcf_embedded_hausdorff']:.3f}), {r['cpu_s']:.0f} s CPU" for r in fits)
        + f". Target (b) (the cMCF sphere carrying the cMCF factors, exactly representable), R path {cfg['path']} "
        f"then 0: residual {b['relative_residual']:.2e}, RMS log error {b['log_rms']:.3g} over all vertices and "
        f"{b['log_rms_determined']:.3g} over the {b['determined_directions']} directions the eigenvalues determine. "
        f"Adaptive from an icosphere ({a['run']}): log RMS {a['log_rms']:.3f} after the best Möbius + O(3) "
        f"alignment ({a['log_rms_centred']:.3f} with the centring alone), "
        f"{a['log_rms_ratio_to_own_sphere']:.2f}x the own-sphere fit, correlation {a['log_correlation']:.2f}, "
        f"re-embedded at Hausdorff {a['embedded_hausdorff']:.3f} (no alignment needed). "
        f"Recursive fit (R = {cfg['recursive_reg']:g}): Hausdorff "
        + " -> ".join(f"{r['embedded_hausdorff']:.3f}" for r in recs) + ".")
    keys = list(dict.fromkeys(key for r in rows for key in r))
    return summary, {"runs": [{key: r.get(key, float("nan")) for key in keys} for r in rows]}


register(Experiment(
    name="pl-bunny", title="Regularized, recursive and adaptive PL fits of the bunny, spot and blub in log factors",
    reproduces="the study's Sections 3.2.2 (regularized fit, Figure 1, R = 0.05) and 3.2.3 (recursive fit, Figure "
               "2, R = 0.1), and its open problem A.5 (adaptive refinement)",
    defaults={"runs": ["bunny_600:0.05", "spot_600:0.05", "blub_600:0.05", "bunny_600:0.001", "bunny_1200:0.05"],
              "mesh_dir": MESH_DIR,
              "numeig_fraction": 0.95, "reg_kind": "cotan-squared", "max_iter": 300, "optimizer": "lbfgs", "seed": 0,
              "path": [1.0, 0.1, 0.01, 0.001, 0.0001],
              "recursive_reg": 0.1, "adaptive_subdivisions": 2, "embed_iterations": 100, "distance_samples": 5000},
    quick={"runs": ["bunny_600:0.05"], "mesh_dir": MESH_DIR, "numeig_fraction": 0.02,
           "reg_kind": "cotan-squared", "max_iter": 5,
           "optimizer": "lbfgs", "seed": 0, "path": [0.05], "recursive_reg": 0.1, "adaptive_subdivisions": 2,
           "embed_iterations": 10, "distance_samples": 500},
    expected_minutes=5.0, run=run))
