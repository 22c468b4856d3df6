"""Does orienting each new degree block (FitOptions.orient_blocks) raise the success rate of harmonic fits?

Cases: the built-in blob (La = 6, Lb = 20, 120 eigenvalues) and a random centred rho of degree 8 (Lb = 18, 150
eigenvalues); degree ramp with 4 basin hops (the defaults), with and without the orientation search, the same
seeds.  One BLAS/numba thread; success rates and times per start; the load average is recorded (the machine is
shared, so the times are indicative; the success rates are not affected).

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/bench_orient_blocks.py [--starts 4]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import load_average, machine_info, threads, write_json  # noqa: E402

from shspec import HarmonicModel  # noqa: E402
from shspec.inverse import FitOptions, align, blob_factor, fit, harmonic_target  # noqa: E402
from shspec.sphere.random import random_centred_coefficients  # noqa: E402

CASES = {"blob (La 6, Lb 20, K 120)": (lambda: blob_factor().coefficients, 20, 6, 120),
         "random degree 8 (Lb 18, K 150)": (lambda: random_centred_coefficients(1, 8, 0.2), 18, 8, 150)}


def run(starts: int, seed: int) -> dict:
    out = {"machine": machine_info(), "load_before": load_average(), "starts": starts, "seed": seed, "cases": {}}
    for name, (make, lb, la, k) in CASES.items():
        truth = make()
        target = harmonic_target(truth, lb, k)
        model = HarmonicModel(lb, la)
        rows = {}
        for orient in (False, True):
            t0 = time.perf_counter()
            with threads(1):
                r = fit(target, model, FitOptions(starts=starts, seed=seed, max_iter=150, orient_blocks=orient))
            rows["orient" if orient else "plain"] = {
                "successes": r.success_count, "seconds": time.perf_counter() - t0,
                "best_relative_residual": r.best.relative_residual,
                "rho_error_after_alignment": align(r.factor(), truth).relative_error,
                "per_start": [{"index": s.index, "relative_residual": s.relative_residual, "seconds": s.seconds,
                               "iterations": s.iterations, "success": s.success} for s in r.starts]}
            print(name, "orient" if orient else "plain", rows["orient" if orient else "plain"]["successes"], flush=True)
        out["cases"][name] = rows
    out["load_after"] = load_average()
    return out


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--starts", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    print(write_json("bench_orient_blocks.json", run(a.starts, a.seed)))
