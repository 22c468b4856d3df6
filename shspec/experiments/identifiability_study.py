"""``identifiability``: which coefficients of ρ a spectrum of K eigenvalues determines, and how noise propagates.

Linearized around a reference ρ: the Jacobian J = ∂λ/∂a (K × n) in the gauge a_1m = 0.  Its right singular vectors
with singular values above ``rank_tol``·σ_max span the locally determined directions; the rotations of ρ, which do
not change the spectrum, are always among the null directions.  Per degree l the *determined fraction*
f_l = ‖P E_l‖²_F / dim E_l measures how much of the degree-l coefficient space lies in that span (1: fully
determined).  A relative noise ε on the eigenvalues moves a by J⁺ δλ; its expected relative L2 size is
ε·‖J⁺ diag(λ)‖_F / ‖a‖ (null directions excluded), the *noise amplification*.

Real fits check the prediction: the spectrum of K = ``fit_numeig`` eigenvalues gets a relative noise
λ*_i (1 + ε n_i) (one fixed draw n, scaled by each ε), and Levenberg–Marquardt with absolute weights (so that its
linearized step is exactly J⁺ δλ) is started at the true ρ, in the same gauge as J (a_1m = 0, a_00 free).  The
observed error of ρ (its component outside the null directions of J) is compared with the linear prediction for that draw,
‖J⁺ diag(λ) ε n‖ / ‖a‖, and with the expected size ε·amplification.
"""

from __future__ import annotations

import numpy as np

from ..galerkin.model import HarmonicModel
from ..inverse import FitOptions, Objective, Parametrization, eigenvalue_weights
from ..inverse.optimize import make_optimizer
from ..sphere.harmonics import degrees
from .base import Experiment, Finding, register
from .common import centred_random_factor, figure, save_figure
from .fitting import Progress, single_threaded


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
            "amplification": amplification, "pinv": pinv, "free": free, "eigenvalues": spec.eigenvalues, "basis": basis}


def noisy_fits(cfg: dict, model: HarmonicModel, coef: np.ndarray, progress: bool) -> tuple[list, dict]:
    """Fits of noisy spectra started at the truth; rows of observed against predicted errors of ρ."""
    k = cfg["fit_numeig"]
    lin = analyse(model, coef, k, cfg["rank_tol"])
    lam = lin["eigenvalues"]
    draw = np.random.default_rng(cfg["noise_seed"]).standard_normal(k)
    draw[0] = 0.0
    free = np.flatnonzero(lin["free"])
    norm = np.linalg.norm(coef)
    options = FitOptions(schedule=(), basin_hops=0, max_iter=cfg["fit_max_iter"], residual_tol=1e-15, energy_tol=1e-10)
    rows = []
    bar = Progress(progress, len(cfg["fit_noise_levels"]), "identifiability fits")
    for eps in cfg["fit_noise_levels"]:
        noisy = np.sort(lam * (1.0 + eps * draw))
        noisy[0] = 0.0
        obj = Objective(model, noisy, eigenvalue_weights(noisy, "absolute"), Parametrization(coef, free))
        opt = make_optimizer("lm", obj, obj.initial(), options)
        while opt.status is None and opt.iteration < options.max_iter:
            opt.step()
        fitted = obj.params(opt.x)
        # The linear prediction for this draw: J⁺ δλ over the free coefficients (null directions excluded).
        predicted = float(np.linalg.norm(lin["pinv"] @ (noisy - lam)[1:]) / norm)
        # Null directions (the rotations) excluded, as in the prediction: project the change onto the row space of J.
        # (This replaces align(), 5-10 s per call on this machine; the fit starts at the truth, so it cannot have
        # moved to a distant rotated copy.)
        delta = (fitted - coef)[free]
        observed = float(np.linalg.norm(lin["basis"] @ delta) / norm)
        rows.append({"relative_noise": eps, "observed_error": float(np.linalg.norm(fitted - coef) / norm),
                     "observed_error_determined": observed, "predicted_this_draw": predicted,
                     "predicted_expected": eps * lin["amplification"],
                     "ratio_observed_to_predicted": observed / predicted if predicted > 0 else float("nan"),
                     "residual_max": opt.ev.relative_residual, "iterations": opt.iteration,
                     "status": opt.status or "max_iter"})
        bar.step(f"eps = {eps:g}: error {observed:.2e}, predicted {predicted:.2e}")
    return rows, lin


def run(cfg: dict, out, progress: bool) -> Finding:
    rho = centred_random_factor(cfg["lmax_factor"], cfg["amplitude"], cfg["seed"])
    model = HarmonicModel(cfg["lmax"], cfg["lmax_factor"])
    with single_threaded():
        results = [analyse(model, rho.coefficients, k, cfg["rank_tol"]) for k in cfg["numeig_values"]]
        fit_rows, fit_lin = noisy_fits(cfg, model, rho.coefficients, progress)
    degrees_ = sorted(results[0]["fraction"])
    rows = []
    for r in results:
        row = {"numeig": r["k"], "rank": r["rank"], "free_coefficients": r["nfree"],
               "noise_amplification": r["amplification"]}
        row.update({f"f_l{d}": r["fraction"][d] for d in degrees_})
        rows.append(row)
    noise_rows = [{"relative_noise": eps, **{f"K={r['k']}": eps * r["amplification"] for r in results}}
                  for eps in cfg["noise_levels"]]

    fig, axes = figure(1, 3, width=19)
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
    eps = np.array([r["relative_noise"] for r in fit_rows])
    axes[2].loglog(eps, [max(r["observed_error_determined"], 1e-17) for r in fit_rows], "o-", label="fit (null directions excluded)")
    axes[2].loglog(eps, [r["predicted_this_draw"] for r in fit_rows], "s--", label="linear, this noise draw")
    axes[2].loglog(eps, [r["predicted_expected"] for r in fit_rows], "k:", label="eps x amplification")
    axes[2].set_xlabel("relative noise eps on the eigenvalues")
    axes[2].set_ylabel("relative L2 error of rho")
    axes[2].set_title(f"noisy fits, K = {cfg['fit_numeig']}")
    axes[2].grid(True, which="both", alpha=0.3)
    axes[2].legend(fontsize=8)
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
        f"e.g. {1e-6 * best['amplification']:.1e} for eps = 1e-6. Real fits of noisy spectra (K = "
        f"{cfg['fit_numeig']}, Levenberg-Marquardt started at the truth, one noise draw scaled by eps) give errors "
        + ", ".join(f"{r['observed_error_determined']:.1e} (eps={r['relative_noise']:g})" for r in fit_rows)
        + ", i.e. " + ", ".join(f"{r['ratio_observed_to_predicted']:.2f}" for r in fit_rows)
        + f" times the linear prediction for the same draw (expected size {fit_lin['amplification']:.2g}·eps): "
        f"the linearization {'holds' if all(0.5 < r['ratio_observed_to_predicted'] < 2 for r in fit_rows) else 'holds only partly'} "
        f"over this noise range.")
    numbers = {"ranks": {r["k"]: r["rank"] for r in results}, "max_rank": results[0]["nfree"] - 3,
               "amplification": {r["k"]: r["amplification"] for r in results},
               "noisy_fit_ratio": [r["ratio_observed_to_predicted"] for r in fit_rows],
               "noisy_fit_error": [r["observed_error_determined"] for r in fit_rows]}
    return Finding(summary, {"identifiability": rows, "noise_propagation": noise_rows, "noisy_fits": fit_rows},
                   ["identifiability.png"], numbers)


register(Experiment(
    name="identifiability", title="What a spectrum of K eigenvalues determines",
    reproduces="beyond the study: the Jacobian's singular values per degree and linear noise propagation",
    defaults={"lmax_factor": 8, "lmax": 24, "amplitude": 0.3, "seed": 3, "rank_tol": 1e-8,
              "numeig_values": [16, 36, 64, 100, 160, 256, 400],
              "noise_levels": [1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3], "fit_numeig": 100,
              "fit_noise_levels": [1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3], "fit_max_iter": 15, "noise_seed": 11},
    quick={"lmax_factor": 4, "lmax": 12, "amplitude": 0.3, "seed": 3, "rank_tol": 1e-8,
           "numeig_values": [9, 16, 36, 64], "noise_levels": [1e-8, 1e-6, 1e-4, 1e-3],
           "fit_numeig": 36, "fit_noise_levels": [1e-8, 1e-5, 1e-3], "fit_max_iter": 10, "noise_seed": 11},
    expected_minutes=2.0, run=run))
