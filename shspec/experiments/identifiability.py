"""``identifiability``: which coefficients of ρ a spectrum of K eigenvalues determines, and how noise propagates.

Linearized around a reference ρ: the Jacobian J = ∂λ/∂a (K × n) in the gauge a_1m = 0.  Its right singular vectors
with singular values above ``rank_tol``·σ_max span the locally determined directions; the rotations of ρ, which do
not change the spectrum, are always among the null directions.  Per degree l the *determined fraction*
f_l = ‖P E_l‖²_F / dim E_l measures how much of the degree-l coefficient space lies in that span (1: fully
determined).  A relative noise ε on the eigenvalues moves a by J⁺ δλ; its expected relative L2 size is
ε·‖J⁺ diag(λ)‖_F / ‖a‖ (null directions excluded), the *noise amplification*.
"""

from __future__ import annotations

import numpy as np

from ..galerkin import HarmonicModel
from ..harmonics import degrees
from .base import Experiment, Finding, register
from .common import centred_random_factor, figure, save_figure


def analyse(model: HarmonicModel, coef: np.ndarray, k: int, rank_tol: float) -> dict:
    """Singular values, determined fraction per degree and noise amplification for the first k eigenvalues."""
    spec = model.spectrum(coef, k)
    jac = model.jacobian(spec)[1:]  # λ₀ = 0 carries no information
    l = degrees(model.lmax_factor)
    free = l != 1  # gauge a_1m = 0
    j = jac[:, free]
    u, s, vt = np.linalg.svd(j, full_matrices=False)
    rank = int(np.sum(s > rank_tol * s[0]))
    basis = vt[:rank]  # (rank, nfree)
    lf = l[free]
    fraction = {int(d): float(np.sum(basis[:, lf == d] ** 2) / np.sum(lf == d)) for d in np.unique(lf)}
    pinv = (vt[:rank].T / s[:rank]) @ u[:, :rank].T
    amplification = float(np.linalg.norm(pinv * spec.eigenvalues[1:][None, :]) / np.linalg.norm(coef))
    return {"k": k, "singular_values": s, "rank": rank, "nfree": int(free.sum()), "fraction": fraction,
            "amplification": amplification}


def run(cfg: dict, out, progress: bool) -> Finding:
    rho = centred_random_factor(cfg["lmax_factor"], cfg["amplitude"], cfg["seed"])
    model = HarmonicModel(cfg["lmax"], cfg["lmax_factor"])
    results = [analyse(model, rho.coefficients, k, cfg["rank_tol"]) for k in cfg["numeig_values"]]
    degrees_ = sorted(results[0]["fraction"])
    rows = []
    for r in results:
        row = {"numeig": r["k"], "rank": r["rank"], "free_coefficients": r["nfree"],
               "noise_amplification": r["amplification"]}
        row.update({f"f_l{d}": r["fraction"][d] for d in degrees_})
        rows.append(row)
    noise_rows = [{"relative_noise": eps, **{f"K={r['k']}": eps * r["amplification"] for r in results}}
                  for eps in cfg["noise_levels"]]

    fig, axes = figure(1, 2, width=13)
    for r in results:
        axes[0].semilogy(np.arange(1, r["singular_values"].size + 1), r["singular_values"] / r["singular_values"][0],
                         ".-", ms=3, label=f"K = {r['k']}")
    axes[0].axhline(cfg["rank_tol"], color="k", lw=0.7, ls=":")
    axes[0].set_xlabel("index")
    axes[0].set_ylabel("singular value / largest")
    axes[0].set_title("singular values of d lambda / d a (gauge a_1m = 0)")
    axes[0].legend(fontsize=7)
    grid = np.array([[r["fraction"][d] for d in degrees_] for r in results])
    im = axes[1].imshow(grid.T, origin="lower", aspect="auto", vmin=0, vmax=1, cmap="magma",
                        extent=(-0.5, len(results) - 0.5, -0.5, len(degrees_) - 0.5))
    axes[1].set_xticks(range(len(results)), [str(r["k"]) for r in results])
    axes[1].set_yticks(range(len(degrees_)), [str(d) for d in degrees_])
    axes[1].set_xlabel("number of eigenvalues K")
    axes[1].set_ylabel("degree l of rho (l = 1 is the gauge a_1m = 0)")
    axes[1].set_title("determined fraction of each degree")
    fig.colorbar(im, ax=axes[1])
    save_figure(fig, out / "identifiability.png")

    full = [r for r in results if r["rank"] >= r["nfree"] - 3]
    first_full = full[0]["k"] if full else None
    best = results[-1]
    summary = (
        f"For a centred random rho of degree {cfg['lmax_factor']} ({results[0]['nfree']} free coefficients with "
        f"a_1m = 0) and Lb = {cfg['lmax']}, the Jacobian of the first K eigenvalues has numerical rank "
        + ", ".join(f"{r['rank']} (K={r['k']})" for r in results)
        + f" at tolerance {cfg['rank_tol']:g}. The 3 rotations of rho never change the spectrum, so the largest "
        f"possible rank is {results[0]['nfree'] - 3}; it is "
        + (f"reached from K = {first_full} eigenvalues on" if first_full else "not reached with these K")
        + f". Low degrees are determined first: with K = {results[0]['k']} the determined fraction is "
        + ", ".join(f"{results[0]['fraction'][d]:.2f} (l={d})" for d in degrees_)
        + f". A relative noise eps on the eigenvalues gives a relative error of about "
        f"{best['amplification']:.2g}·eps in rho with K = {best['k']} (linearized, null directions excluded), "
        f"e.g. {1e-6 * best['amplification']:.1e} for eps = 1e-6.")
    numbers = {"ranks": {r["k"]: r["rank"] for r in results}, "max_rank": results[0]["nfree"] - 3,
               "amplification": {r["k"]: r["amplification"] for r in results}}
    return Finding(summary, {"identifiability": rows, "noise_propagation": noise_rows}, ["identifiability.png"],
                   numbers)


register(Experiment(
    name="identifiability", title="What a spectrum of K eigenvalues determines",
    reproduces="beyond the study: the Jacobian's singular values per degree and linear noise propagation",
    defaults={"lmax_factor": 8, "lmax": 24, "amplitude": 0.3, "seed": 3, "rank_tol": 1e-8,
              "numeig_values": [16, 36, 64, 100, 160, 256, 400],
              "noise_levels": [1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3]},
    quick={"lmax_factor": 4, "lmax": 12, "amplitude": 0.3, "seed": 3, "rank_tol": 1e-8,
           "numeig_values": [9, 16, 36, 64], "noise_levels": [1e-8, 1e-6, 1e-4, 1e-3]},
    expected_minutes=2.0, run=run))
