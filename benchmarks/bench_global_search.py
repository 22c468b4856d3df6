"""Global search of the harmonic fit: which schedule and escape moves make random starts find the truth?

Random centred ρ (seed 1) of degree 8 (Lb 12, 100 eigenvalues, the K that ``shspec fit`` plans) and degree 10
(Lb 14, 144 eigenvalues, planned), several starts of seed 0, one BLAS/numba thread, serial.  Variants:

* ``default``: the degree ramp with 4 basin hops (half-turns and sign flips of single degree blocks);
* ``orient``: the same with ``orient_blocks`` (when a block enters, its 47 octahedral orientations and reflections
  relative to the lower blocks are tried);
* ``wide``: a degree ramp that matches twice as many eigenvalues as coefficients at each stage, 2(l + 1)²;
* ``wide_orient``: both.

A start succeeds when its relative spectral residual is ≤ 1e-10; its ρ error after Möbius + O(3) alignment is
recorded.  The load average is recorded; times are per start, on one core.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/bench_global_search.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import load_average, machine_info, main_with_only, threads  # noqa: E402

from shspec import HarmonicModel  # noqa: E402
from shspec.inverse import FitOptions, Stage, align, fit, harmonic_target  # noqa: E402
from shspec.sphere.random import random_centred_coefficients  # noqa: E402

#: name: (degree La, Lb, K, starts)
CASES = {"random degree 8 (Lb 12, K 100)": (8, 12, 100, 6), "random degree 10 (Lb 14, K 144)": (10, 14, 144, 4)}


def _wide(la: int, k: int) -> tuple:
    return tuple(Stage(lmax_factor=j, numeig=min(k, 2 * (j + 1) ** 2)) for j in range(2, la + 1)) \
        + (Stage(lmax_factor=la, numeig=k),)


def run(only: str | None) -> dict:
    out = {"machine": machine_info(), "load_before": load_average(), "cases": {}}
    for name, (la, lb, k, starts) in CASES.items():
        if only and only not in name:
            continue
        truth = random_centred_coefficients(1, la, 0.2)
        target = harmonic_target(truth, lb, k)
        model = HarmonicModel(lb, la)
        variants = {"default": FitOptions(starts=starts), "orient": FitOptions(starts=starts, orient_blocks=True),
                    "wide": FitOptions(starts=starts, schedule=_wide(la, k)),
                    "wide_orient": FitOptions(starts=starts, schedule=_wide(la, k), orient_blocks=True)}
        rows = {}
        for label, options in variants.items():
            t0 = time.perf_counter()
            with threads(1):
                r = fit(target, model, options)
            rows[label] = {"successes": r.success_count, "starts": starts, "seconds": time.perf_counter() - t0,
                           "per_start": [{"index": s.index, "relative_residual": s.relative_residual,
                                          "rho_error_after_alignment": align(model.to_factor(s.params),
                                                                             truth).relative_error,
                                          "iterations": s.iterations, "seconds": s.seconds, "success": s.success}
                                         for s in r.starts]}
            print(name, label, r.success_count, "/", starts, flush=True)
        out["cases"][name] = rows
    out["load_after"] = load_average()
    return out


if __name__ == "__main__":
    main_with_only(__doc__, "bench_global_search.json", run)
