"""How large is the truth's basin? Levenberg–Marquardt from the truth plus a random perturbation, at full degree.

Two settings, both zero-residual problems (the truth is in the model):

* ``study``: the blob in the study's setting (Lb 30, La 15, K = 256 eigenvalues, R = 0), where the fits from
  random starts end at relative residuals near 1e-6 with ρ errors of a few percent;
* ``degree10``: a random centred ρ of degree 10 (seed 1) at the degree-10 goal's setting (Lb 24, K = 300).

The perturbation adds ε ‖a_{l≥2}‖ times a random unit direction (seed [7, trial]) to the coefficients of degree
≥ 2; the ρ error is measured after Möbius + O(3) alignment, before and after the fit.  For the end state of the
study case with ε = 0.05 (a fit that stalled), the full Hessian of the energy on the twelve flattest right singular
directions of the Jacobian (central differences of the exact gradient) is compared with its Gauss–Newton part
JᵀJ: positive eigenvalues far above the Gauss–Newton ones mean a genuine local minimum held by the second-order
term, not a slow valley.  One BLAS/numba thread, serial; the load is recorded.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/bench_basin.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import load_average, machine_info, main_with_only, threads  # noqa: E402

from shspec import HarmonicModel  # noqa: E402
from shspec.inverse import FitOptions, Stage, align, blob_factor, harmonic_target  # noqa: E402
from shspec.inverse.optimize import make_optimizer  # noqa: E402
from shspec.inverse.schedule import FitProblem  # noqa: E402
from shspec.sphere.factor import ConformalFactor  # noqa: E402
from shspec.sphere.random import random_centred_coefficients  # noqa: E402

#: name: (truth, Lb, K, perturbations ε, trials, iterations)
CASES = {"study": (lambda: blob_factor(15), 30, 256, (0.01, 0.05, 0.2), 1, 150),
         "degree10": (lambda: ConformalFactor(random_centred_coefficients(1, 10, 0.2)), 24, 300,
                      (0.05, 0.1, 0.2, 0.4, 0.7), 3, 300)}


def _fit_from(problem: FitProblem, x: np.ndarray, iterations: int):
    obj = problem.objective(0, x)
    opt = make_optimizer(problem.optimizer, obj, obj.initial(), problem.options)
    trace = [opt.ev.relative_residual]
    while opt.status is None and opt.iteration < iterations:
        opt.step()
        trace.append(opt.ev.relative_residual)
    return problem.merge(0, x, obj, opt.x), opt, trace


def _hessian_check(problem: FitProblem, x: np.ndarray, ndir: int = 12) -> dict:
    obj = problem.objective(0, x)
    x0 = obj.initial()
    ev = obj.evaluate(x0, jacobian=True)
    _, s, vt = np.linalg.svd(ev.jacobian, full_matrices=False)
    v = vt[-ndir:].T
    h = 1e-5 * np.linalg.norm(x0)
    g = np.array([(obj.evaluate(x0 + h * v[:, j]).gradient - obj.evaluate(x0 - h * v[:, j]).gradient) / (2 * h)
                  for j in range(ndir)])
    full = 0.5 * (v.T @ g.T + g @ v)
    return {"energy": ev.energy, "gradient_norm": float(np.linalg.norm(ev.gradient)),
            "singular_values_flattest": s[-ndir:].tolist(),
            "gauss_newton_eigenvalues": np.linalg.eigvalsh(v.T @ ev.jacobian.T @ ev.jacobian @ v).tolist(),
            "full_hessian_eigenvalues": np.linalg.eigvalsh(full).tolist(),
            "note": "the three exactly flat directions are the rotations; their full-Hessian eigenvalues show the "
                    "finite-difference noise"}


def run(only: str | None) -> dict:
    out = {"machine": machine_info(), "load_before": load_average(), "cases": {}}
    for name, (make_truth, lb, k, epsilons, trials, iterations) in CASES.items():
        if only and only not in name:
            continue
        truth = make_truth()
        target = harmonic_target(truth, lb, k)
        model = HarmonicModel(lb, truth.lmax)
        problem = FitProblem(model, target, FitOptions(starts=1, schedule=(Stage(),), basin_hops=0))
        rows = []
        a = truth.coefficients
        for eps in epsilons:
            for trial in range(trials):
                d = np.random.default_rng([7, trial]).standard_normal(a.size)
                d[:4] = 0
                x = a.copy()
                x[4:] += eps * d[4:] * np.linalg.norm(a[4:]) / np.linalg.norm(d[4:])
                start_error = align(model.to_factor(x), truth).relative_error
                t0 = time.perf_counter()
                with threads(1):
                    end, opt, trace = _fit_from(problem, x, iterations)
                row = {"epsilon": eps, "trial": trial, "start_rho_error": start_error,
                       "end_relative_residual": float(opt.ev.relative_residual),
                       "end_rho_error": align(model.to_factor(end), truth).relative_error,
                       "iterations": opt.iteration, "status": opt.status or "max_iter",
                       "seconds": time.perf_counter() - t0, "residual_every_10": trace[::10]}
                if name == "study" and eps == 0.05:
                    with threads(1):
                        row["hessian_check"] = _hessian_check(problem, end)
                rows.append(row)
                print(name, eps, trial, f"{start_error:.2e} -> residual {row['end_relative_residual']:.1e}, "
                      f"rho error {row['end_rho_error']:.1e}", flush=True)
        out["cases"][name] = {"lmax": lb, "lmax_factor": truth.lmax, "numeig": k, "runs": rows,
                              "load_after": load_average()}
    out["load_after"] = load_average()
    return out


if __name__ == "__main__":
    main_with_only(__doc__, "bench_basin.json", run)
