"""Final convergence of the harmonic fit: Levenberg–Marquardt with and without geodesic acceleration, and scipy.

Each case starts 1e-3 (relative RMS, degree l weighted 1/√index) away from a zero-residual truth and runs one
stage at the full degree: shspec's LM with geodesic acceleration (the default), shspec's LM without it (the
optimizer of the previous release, the same iterations up to the SVD), and the peer,
``scipy.optimize.least_squares`` (trust-region reflective, ``x_scale="jac"``) on the same residuals and analytic
Jacobian.  Traces give the relative residual max|λ−λ*|/λ* after every iteration (scipy: after every evaluation)
with the elapsed time.  One BLAS/numba thread; the load average is recorded.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/bench_convergence.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import scipy.optimize

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import load_average, machine_info, main_with_only, threads  # noqa: E402

from shspec import HarmonicModel  # noqa: E402
from shspec.errors import NotPositiveError  # noqa: E402
from shspec.inverse import FitOptions
from shspec.fitting import blob_factor, harmonic_target  # noqa: E402
from shspec.inverse.energy import Objective, eigenvalue_weights  # noqa: E402
from shspec.inverse.optimize import make_optimizer  # noqa: E402
from shspec.inverse.parametrization import Parametrization  # noqa: E402
from shspec.sphere.random import random_centred_coefficients  # noqa: E402

#: name: (truth maker, Lb, La, K, iterations)
CASES = {
    "blob La 15, Lb 30, K 256 (the study's setting)": (lambda la: blob_factor(la).coefficients, 30, 15, 256, 150),
    "blob La 15, Lb 40, K 600 (recommended K)": (lambda la: blob_factor(la).coefficients, 40, 15, 600, 60),
    "random degree 10, Lb 24, K 300": (lambda la: random_centred_coefficients(1, la, 0.2), 24, 10, 300, 80),
}
OFFSET = 1e-3


def _objective(truth, lb, la, k):
    model = HarmonicModel(lb, la)
    target = harmonic_target(truth, lb, k)
    free = model.free_parameters(False)
    start = np.array(truth, dtype=float)
    rng = np.random.default_rng(0)
    start[free] += OFFSET * start[0] * rng.standard_normal(free.size) / np.sqrt(np.arange(1, free.size + 1))
    par = Parametrization.at(start, free)
    return Objective(model, target.eigenvalues, eigenvalue_weights(target.eigenvalues), par), par.initial()


def _shspec(obj, x0, iterations, acceleration):
    opt = make_optimizer("lm", obj, x0, FitOptions(max_iter=iterations, lm_acceleration=acceleration))
    t0, trace = time.perf_counter(), []
    while opt.status is None and opt.iteration < iterations:
        opt.step()
        trace.append([opt.iteration, opt.ev.relative_residual, round(time.perf_counter() - t0, 3)])
    return {"status": opt.status or "max_iter", "iterations": opt.iteration, "evaluations": obj.evaluations,
            "final_relative_residual": opt.ev.relative_residual, "seconds": time.perf_counter() - t0,
            "iterations_to_1e-12": next((it for it, r, _ in trace if r <= 1e-12), None), "trace": trace}


def _scipy(obj, x0, evaluations):
    t0, trace = time.perf_counter(), []

    size = obj.evaluate(x0).residuals.size

    def fun(x):
        try:
            ev = obj.evaluate(x)
        except NotPositiveError:
            # scipy needs finite residuals: a point that is not a metric gets a huge one, so the step is rejected
            return np.full(size, 1e6)
        trace.append([len(trace) + 1, ev.relative_residual, round(time.perf_counter() - t0, 3)])
        return ev.residuals

    def jac(x):
        return obj.evaluate(x, jacobian=True).jacobian

    res = scipy.optimize.least_squares(fun, x0, jac=jac, method="trf", x_scale="jac", xtol=1e-15, ftol=1e-15,
                                       gtol=1e-15, max_nfev=evaluations)
    best = min(r for _, r, _ in trace)
    return {"status": res.message, "evaluations": res.nfev, "jacobians": res.njev, "final_relative_residual": best,
            "seconds": time.perf_counter() - t0,
            "evaluations_to_1e-12": next((it for it, r, _ in trace if r <= 1e-12), None), "trace": trace}


def run(only: str | None) -> dict:
    out = {"machine": machine_info(), "load_before": load_average(), "offset": OFFSET, "cases": {}}
    for name, (make, lb, la, k, iterations) in CASES.items():
        if only and only not in name:
            continue
        truth = make(la)
        rows = {}
        with threads(1):
            for label, method in (("shspec lm, geodesic acceleration", lambda o, x: _shspec(o, x, iterations, True)),
                                  ("shspec lm, no acceleration", lambda o, x: _shspec(o, x, iterations, False)),
                                  ("scipy least_squares trf", lambda o, x: _scipy(o, x, 2 * iterations))):
                obj, x0 = _objective(truth, lb, la, k)
                rows[label] = method(obj, x0)
                print(f"{name} | {label}: {rows[label]['final_relative_residual']:.2e} in "
                      f"{rows[label]['seconds']:.1f} s", flush=True)
        out["cases"][name] = rows
    out["load_after"] = load_average()
    return out


if __name__ == "__main__":
    main_with_only(__doc__, "bench_convergence.json", run)
