"""Cost of one fit iteration of the harmonic model: the cold forward solve, the Jacobian, the warm start, an LM run.

For (Lb, La, K) = (20,10,120), (30,15,256), (24,10,300), (60,30,500), on one thread, side by side in one process
(interleaved repeats, medians):

* ``jacobian``  — the quadratic forms v_iᵀ G_k v_i by the Gaunt-table kernel (``table.quadratic_forms``, what the
  Jacobian used before) and by the GLQ quadrature (``model.grid_forms``, what it uses now), and the adjoint gradient
  both ways (``table.contract`` of B = V diag(c) Vᵀ, and ``grid_forms.weighted``); max relative differences.
* ``cold``      — ``model.spectrum(a, K)`` (positivity check, assembly, Schur reduction, the driver chosen by
  :mod:`shspec.galerkin.eigen`), ``shspec.spectrum`` without the truncation estimate (``truncation_tol=None``) and
  with it (the default: the basis estimate from the eigenvectors, no second solve), against the bare
  ``scipy.linalg.eigh(S, M, subset_by_index=[0, K-1])`` on the same, pre-assembled M; and the LAPACK drivers on the
  reduced standard problem (evr and evx subsets, evd full).
* ``iteration`` — ``Objective.evaluate(x, jacobian=True)`` (spectrum, gradient, Jacobian: one LM trial point) cold,
  warm after a step of relative size 1e-10 (its start set to the spectrum at the previous point), and the path of the previous release (evr, table-kernel Jacobian and
  gradient; rebuilt here from the same pieces so that it runs in this process).
* at (30,15,256) an LM run from a perturbed start to its target, once with warm starts and once cold: evaluations,
  how many were warm, time, and the largest difference of the two final points.

Run:  OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/bench_iteration.py
Writes benchmarks/results/bench_iteration.json.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import command_line, load_average, machine_info, side_by_side, threads, write_json  # noqa: E402

import shspec  # noqa: E402
from shspec.galerkin.model import HarmonicModel, _schur_scaled_upper  # noqa: E402
from shspec.gaunt.build import build_table  # noqa: E402
from shspec.inverse.energy import Objective, eigenvalue_weights  # noqa: E402
from shspec.inverse.optimize import make_optimizer  # noqa: E402
from shspec.inverse.options import FitOptions  # noqa: E402
from shspec.inverse.parametrization import Parametrization  # noqa: E402
from shspec.spectral_model import Spectrum  # noqa: E402
from shspec.sphere.factor import ConformalFactor  # noqa: E402
from shspec.sphere.harmonics import degrees  # noqa: E402
from shspec.sphere.random import random_coefficients  # noqa: E402

CASES = [(20, 10, 120, 7), (30, 15, 256, 7), (24, 10, 300, 7), (60, 30, 500, 3)]  # (Lb, La, K, repeats)
GOALS = {"iteration_over_cold_forward_plus_jacobian": 0.5, "cold_forward_over_bare_eigh": 1.0}


def random_rho(lb, la, seed=0, amplitude=0.2):
    a = random_coefficients(np.random.default_rng(seed), la, amplitude / np.sqrt(4 * np.pi))
    a[0] = 1.0 / np.sqrt(4 * np.pi)
    a[1:4] = 0.0
    return a


class ColdModel(HarmonicModel):
    """The same model, never warm-started."""

    def spectrum(self, params, k, *, start=None):
        return super().spectrum(params, k)


class LegacyModel(HarmonicModel):
    """The previous release's path: the MRRR subset driver, the table-kernel Jacobian and gradient."""

    def spectrum(self, params, k, *, start=None):
        a = self._params(params)
        ConformalFactor(a).check_positive()
        m = self.table.mass_matrix(a, symmetrize=False)
        n = self.nbasis
        vals, vecs = np.zeros(k), np.zeros((n, k))
        vecs[0, 0] = 1.0 / np.sqrt(m[0, 0])
        h = np.empty((n - 1, n - 1))
        _schur_scaled_upper(m, self._dinv, h)
        mu, u = scipy.linalg.eigh(h, lower=False, subset_by_index=[n - k, n - 2], driver="evr", overwrite_a=True,
                                  check_finite=False)
        lam = 1.0 / mu[::-1]
        vr = (u[:, ::-1] * self._dinv[:, None]) * np.sqrt(lam)[None, :]
        vecs[1:, 1:] = vr
        vecs[0, 1:] = -(m[0, 1:] @ vr) / m[0, 0]
        vals[1:] = lam
        return Spectrum(vals, vecs)

    def jacobian(self, spec):
        return -(self.table.quadratic_forms(spec.eigenvectors) * spec.eigenvalues[None, :]).T

    def contract(self, spec, coef):
        v = spec.eigenvectors
        return -self.table.contract((v * (coef * spec.eigenvalues)[None, :]) @ v.T)


def objective_for(model, a, target):
    par = Parametrization.at(a, model.free_parameters(fit_area=False))
    return Objective(model, target, eigenvalue_weights(target), par), par


def case(lb, la, k, repeats):
    out = {"lmax": lb, "lmax_factor": la, "k": k, "nbasis": (lb + 1) ** 2, "load_average_start": load_average()}
    table = build_table(lb, la)
    model, cold_model, legacy = (cls(lb, la, table=table) for cls in (HarmonicModel, ColdModel, LegacyModel))
    a = random_rho(lb, la)
    spec = model.spectrum(a, k)
    out["cold_driver"] = spec.solver
    n = model.nbasis
    ls = degrees(lb).astype(float)
    s_mat = np.diag(ls * (ls + 1.0))
    m_full = table.mass_matrix(a)
    h_upper = np.empty((n - 1, n - 1))
    _schur_scaled_upper(table.mass_matrix(a, symmetrize=False), model._dinv, h_upper)
    forms = model.grid_forms
    v = spec.eigenvectors
    coef = np.random.default_rng(1).standard_normal(k)
    q_table, q_grid = table.quadratic_forms(v), forms(v)
    out["jacobian_max_rel_diff"] = float(np.abs(q_table - q_grid).max() / np.abs(q_table).max())
    g_table = table.contract((v * coef[None, :]) @ v.T)
    out["gradient_max_rel_diff"] = float(np.abs(g_table - forms.weighted(v, coef)).max() / np.abs(g_table).max())
    lam_bare = scipy.linalg.eigh(s_mat, m_full, subset_by_index=[0, k - 1], eigvals_only=True)
    out["forward_vs_bare_max_rel_diff"] = float(np.max(np.abs(lam_bare[1:] - spec.eigenvalues[1:])
                                                       / spec.eigenvalues[1:]))

    # one LM trial point: x, and x + a step of relative size 1e-10 evaluated right after x (warm)
    target = model.spectrum(random_rho(lb, la, seed=2, amplitude=0.21), k).eigenvalues
    obj, par = objective_for(model, a, target)
    obj_cold, _ = objective_for(cold_model, a, target)
    obj_legacy, _ = objective_for(legacy, a, target)
    x0 = par.initial()
    dx = np.random.default_rng(3).standard_normal(x0.size)
    x1 = x0 + dx * 1e-10 * np.linalg.norm(a) / np.linalg.norm(dx)
    obj.evaluate(x0, jacobian=True)
    spec0 = obj._last
    warm_solvers = []

    def warm_iteration():
        obj._last = spec0  # the previous trial point was x0
        ev = obj.evaluate(x1, jacobian=True)
        warm_solvers.append(obj._last.solver)
        return ev

    big = lb >= 60
    with threads(1):
        out["timings"] = side_by_side({
            "spectrum_cold": lambda: cold_model.spectrum(a, k),
            "shspec_spectrum_bare": lambda: shspec.spectrum(a, lb, k, table=table, truncation_tol=None),
            "shspec_spectrum_default": lambda: shspec.spectrum(a, lb, k, table=table),
            "bare_scipy_eigh_S_M": lambda: scipy.linalg.eigh(s_mat, m_full, subset_by_index=[0, k - 1]),
            "reduced_evr": lambda: scipy.linalg.eigh(h_upper, lower=False, subset_by_index=[n - k, n - 2],
                                                     driver="evr", check_finite=False),
            "reduced_evx": lambda: scipy.linalg.eigh(h_upper, lower=False, subset_by_index=[n - k, n - 2],
                                                     driver="evx", check_finite=False),
            "reduced_evd_full": lambda: scipy.linalg.eigh(h_upper, lower=False, driver="evd", check_finite=False),
            "jacobian_table_kernel": lambda: table.quadratic_forms(v),
            "jacobian_grid": lambda: forms(v),
            "gradient_table_contract": lambda: legacy.contract(spec, coef),
            "gradient_grid": lambda: model.contract(spec, coef),
            "legacy_spectrum": lambda: legacy.spectrum(a, k),
            "iteration_legacy": lambda: obj_legacy.evaluate(x1, jacobian=True),
            "iteration_cold": lambda: obj_cold.evaluate(x1, jacobian=True),
            "iteration_warm": warm_iteration,
        }, repeats, warmup=0 if big else 1)
    t = {name: r["median_s"] for name, r in out["timings"].items()}
    out["warm_solvers"] = sorted(set(warm_solvers))
    warm = t["iteration_warm"]
    old_forward_plus_jacobian = t["legacy_spectrum"] + t["jacobian_table_kernel"]
    new_cold_forward_plus_jacobian = t["spectrum_cold"] + t["jacobian_grid"]
    out["summary"] = {
        "iteration_warm_s": warm,
        "iteration_cold_s": t["iteration_cold"],
        "iteration_legacy_s": t["iteration_legacy"],
        "legacy_forward_plus_jacobian_s": old_forward_plus_jacobian,
        "cold_forward_plus_jacobian_s": new_cold_forward_plus_jacobian,
        "warm_iteration_over_legacy_forward_plus_jacobian": warm / old_forward_plus_jacobian,
        "warm_iteration_over_cold_forward_plus_jacobian": warm / new_cold_forward_plus_jacobian,
        "cold_iteration_over_legacy_forward_plus_jacobian": t["iteration_cold"] / old_forward_plus_jacobian,
        "cold_iteration_over_legacy_iteration": t["iteration_cold"] / t["iteration_legacy"],
        "jacobian_grid_over_table": t["jacobian_grid"] / t["jacobian_table_kernel"],
        "gradient_grid_over_table": t["gradient_grid"] / t["gradient_table_contract"],
        "spectrum_cold_over_bare_scipy": t["spectrum_cold"] / t["bare_scipy_eigh_S_M"],
        "shspec_spectrum_bare_over_bare_scipy": t["shspec_spectrum_bare"] / t["bare_scipy_eigh_S_M"],
        "shspec_spectrum_default_over_bare_scipy": t["shspec_spectrum_default"] / t["bare_scipy_eigh_S_M"],
        "legacy_spectrum_over_bare_scipy": t["legacy_spectrum"] / t["bare_scipy_eigh_S_M"],
        "evd_full_over_evr": t["reduced_evd_full"] / t["reduced_evr"],
        "evx_over_evr": t["reduced_evx"] / t["reduced_evr"],
    }
    out["load_average_end"] = load_average()
    print(lb, la, k, {key: round(val, 4) for key, val in out["summary"].items()}, out["load_average_end"],
          flush=True)
    return out


class Recorder(HarmonicModel):
    """Records, per evaluation, how it was solved, the relative change of ρ from the previous one, and its time."""

    def __init__(self, *args, warm=True, **kwargs):
        super().__init__(*args, **kwargs)
        self.warm = warm
        self.log = []
        self._prev = None

    def spectrum(self, params, k, *, start=None):
        t0 = time.perf_counter()
        spec = super().spectrum(params, k, start=start if self.warm else None)
        a = np.asarray(params, dtype=float)
        change = None if self._prev is None else float(np.linalg.norm(a - self._prev) / np.linalg.norm(a))
        self._prev = a.copy()
        self.log.append({"solver": spec.solver, "relative_change": change, "seconds": time.perf_counter() - t0})
        return spec


def lm_run(lb=30, la=15, k=256, perturbation=1e-4, iterations=40):
    table = build_table(lb, la)
    truth = random_rho(lb, la, seed=5)
    target = HarmonicModel(lb, la, table=table).spectrum(truth, k).eigenvalues
    rng = np.random.default_rng(6)
    start = truth.copy()
    start[4:] += perturbation * np.abs(truth[0]) * rng.standard_normal(truth.size - 4) / np.sqrt(truth.size)
    out = {"lmax": lb, "lmax_factor": la, "k": k, "start_perturbation": perturbation,
           "load_average_start": load_average()}
    finals = {}
    for warm in (True, False):
        model = Recorder(lb, la, table=table, warm=warm)
        obj, par = objective_for(model, start, target)
        opt = make_optimizer("lm", obj, par.initial(), FitOptions(max_iter=iterations, residual_tol=1e-13))
        t0 = time.perf_counter()
        with threads(1):
            while opt.status is None and opt.iteration < iterations:
                opt.step()
        elapsed = time.perf_counter() - t0
        finals[warm] = opt.x.copy()
        key = "warm" if warm else "cold"
        out[key] = {"seconds": elapsed, "iterations": opt.iteration, "status": opt.status,
                    "evaluations": len(model.log), "warm_evaluations": sum(e["solver"] == "warm" for e in model.log),
                    "final_relative_residual": opt.ev.relative_residual,
                    "trace": [{"solver": e["solver"], "relative_change": e["relative_change"],
                               "seconds": round(e["seconds"], 5)} for e in model.log]}
        print("LM", key, round(elapsed, 2), "s", opt.iteration, "iterations", len(model.log), "evaluations",
              out[key]["warm_evaluations"], "warm", opt.status, f"{opt.ev.relative_residual:.2e}", flush=True)
    out["final_x_max_rel_diff_warm_vs_cold"] = float(np.abs(finals[True] - finals[False]).max()
                                                     / np.abs(finals[False]).max())
    out["load_average_end"] = load_average()
    return out


def main():
    command_line(__doc__)
    out = {"benchmark": "bench_iteration", "machine": machine_info(), "goals": GOALS, "threads": 1, "cases": []}
    print(out["machine"]["cpu"], "load", out["machine"]["load_average_1_5_15"], flush=True)
    for lb, la, k, repeats in CASES:
        out["cases"].append(case(lb, la, k, repeats))
    out["lm_run"] = lm_run()
    main_case = next(c for c in out["cases"] if (c["lmax"], c["lmax_factor"], c["k"]) == (30, 15, 256))["summary"]
    out["goal_check"] = {
        "warm_iteration_over_legacy_cold_forward_plus_jacobian":
            main_case["warm_iteration_over_legacy_forward_plus_jacobian"],
        "warm_iteration_over_new_cold_forward_plus_jacobian": main_case["warm_iteration_over_cold_forward_plus_jacobian"],
        "cold_iteration_over_legacy_cold_forward_plus_jacobian":
            main_case["cold_iteration_over_legacy_forward_plus_jacobian"],
        "met_iteration_when_warm": main_case["warm_iteration_over_legacy_forward_plus_jacobian"] <= 0.5,
        "met_iteration_when_cold": main_case["cold_iteration_over_legacy_forward_plus_jacobian"] <= 0.5,
        "cold_forward_over_bare_scipy": {f"({c['lmax']},{c['lmax_factor']},{c['k']})":
                                         c["summary"]["spectrum_cold_over_bare_scipy"] for c in out["cases"]},
        "shspec_spectrum_bare_over_bare_scipy": {f"({c['lmax']},{c['lmax_factor']},{c['k']})":
                                                 c["summary"]["shspec_spectrum_bare_over_bare_scipy"]
                                                 for c in out["cases"]},
    }
    out["machine"]["load_average_end"] = load_average()
    print("wrote", write_json("bench_iteration.json", out), flush=True)


if __name__ == "__main__":
    main()
