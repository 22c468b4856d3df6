"""``sh-convergence``: forward convergence, harmonic from above against piecewise-linear from below (Section 3.3)."""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError
from ..galerkin.convergence import convergence, convergence_in_factor
from ..mesh.factor_spectrum import pl_spectrum_of_factor
from .base import Experiment, Finding, register
from .common import centred_random_factor, figure, save_figure


def run(cfg: dict, out, progress: bool) -> Finding:
    rho = centred_random_factor(cfg["lmax_factor"], cfg["amplitude"], cfg["seed"])
    k = cfg["numeig"]
    lb = convergence(rho, cfg["lmax_values"], k)
    la = convergence_in_factor(rho, cfg["factor_values"], max(cfg["lmax_values"]), k)
    reference = lb.reference
    too_small = [sub for sub in cfg["pl_subdivisions"] if 10 * 4**sub + 2 < k]
    if too_small:
        raise InvalidArgumentError(f"pl_subdivisions {too_small} give icospheres with fewer than numeig = {k} "
                                   "vertices")
    pl_rows = []
    for sub in cfg["pl_subdivisions"]:
        lam = pl_spectrum_of_factor(rho, k, sub)
        lb.pl_eigenvalues[f"PL icosphere({sub})"] = lam
        nv = 10 * 4**sub + 2
        rel = (lam[1:] - reference[1:]) / reference[1:]
        pl_rows.append({"method": "PL icosphere", "dof": nv, "max_rel_error": float(np.abs(rel).max()),
                        "mean_signed_rel_error": float(rel.mean())})
    harm_rows = []
    for value, lam in zip(lb.values[:-1], lb.eigenvalues[:-1]):
        rel = (lam[1:] - reference[1:]) / reference[1:]
        harm_rows.append({"method": "harmonic", "dof": int((value + 1) ** 2), "max_rel_error": float(np.abs(rel).max()),
                          "mean_signed_rel_error": float(rel.mean())})

    fig, axes = figure(1, 3, width=16)
    lb.plot(axes[0])
    axes[0].set_title("harmonic: change vs basis band limit")
    la.plot(axes[1])
    axes[1].set_title(f"harmonic: truncating rho (Lb = {la.fixed})")
    for rows, style, label in ((harm_rows, "o-", "harmonic (from above)"), (pl_rows, "s--", "PL cotan (from below)")):
        axes[2].loglog([r["dof"] for r in rows], [max(r["max_rel_error"], 1e-16) for r in rows], style, label=label)
    axes[2].set_xlabel("degrees of freedom ((Lb+1)^2 or vertices)")
    axes[2].set_ylabel(f"max relative error, first {k} eigenvalues")
    axes[2].grid(True, which="both", alpha=0.3)
    axes[2].legend()
    save_figure(fig, out / "convergence.png")

    fig, ax = figure(1, 1, width=8)
    lb.pl_eigenvalues = {key: lb.pl_eigenvalues[key] for key in list(lb.pl_eigenvalues)[-2:]}
    lb.plot_spectra(ax[0])
    save_figure(fig, out / "spectra.png")

    rates = lb.rates()
    finite = rates[np.isfinite(rates)]
    above = all(r["mean_signed_rel_error"] >= -1e-14 for r in harm_rows)
    below = all(r["mean_signed_rel_error"] < 0 for r in pl_rows)
    dof = np.array([r["dof"] for r in pl_rows], dtype=float)
    err = np.array([r["max_rel_error"] for r in pl_rows])
    pl_order = -np.polyfit(np.log(dof[-3:]), np.log(err[-3:]), 1)[0] if len(dof) >= 3 else float("nan")
    numbers = {"harmonic_rate_median": float(np.median(finite)) if finite.size else None,
               "harmonic_error_next_to_finest": harm_rows[-1]["max_rel_error"],
               "pl_error_finest": pl_rows[-1]["max_rel_error"], "pl_order_in_vertices": float(pl_order),
               "harmonic_from_above": bool(above), "pl_from_below": bool(below)}
    summary = (
        f"For a smooth centred random rho of degree {cfg['lmax_factor']} (first {k} eigenvalues, reference Lb = "
        f"{lb.values[-1]}), the harmonic Galerkin eigenvalues converge {'from above' if above else 'NOT from above'} "
        f"and exponentially: the change falls at a median rate of {numbers['harmonic_rate_median']:.2f} per degree "
        f"and is {harm_rows[-1]['max_rel_error']:.1e} at Lb = {lb.values[-2]} ({harm_rows[-1]['dof']} functions). "
        f"The piecewise-linear cotan spectrum of an icosphere carrying the same rho converges "
        f"{'from below' if below else 'NOT from below'} and algebraically, with error ~ V^-{pl_order:.2f} in the "
        f"number of vertices (h^{2 * pl_order:.1f}): {pl_rows[-1]['max_rel_error']:.1e} with {pl_rows[-1]['dof']} "
        f"vertices. Truncating rho below its own degree {cfg['lmax_factor']} changes the spectrum by "
        f"{la.group_change()[0].max():.1e} at La = {la.values[0]}.")
    return Finding(summary, {"harmonic_vs_pl": harm_rows + pl_rows, "convergence_lmax": lb.table(),
                             "convergence_lmax_factor": la.table()}, ["convergence.png", "spectra.png"], numbers)


register(Experiment(
    name="sh-convergence", title="Forward convergence: harmonic basis from above, PL from below",
    reproduces="the study's Section 3.3 (convergence w.r.t. maximal degree and number of free SH coefficients)",
    defaults={"lmax_factor": 8, "amplitude": 0.3, "seed": 1, "numeig": 64,
              "lmax_values": [8, 10, 12, 14, 16, 18, 20, 24, 28, 32], "factor_values": [2, 4, 6, 8],
              "pl_subdivisions": [2, 3, 4, 5]},
    quick={"lmax_factor": 6, "amplitude": 0.3, "seed": 1, "numeig": 25,
           "lmax_values": [6, 8, 10, 12, 16], "factor_values": [2, 4, 6], "pl_subdivisions": [1, 2, 3]},
    expected_minutes=3.0, run=run))
