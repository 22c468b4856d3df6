"""Cost of the certified positivity check of ρ (run before every forward solve) against the old grid sample.

"grid_sample" is what check_positive did before: evaluate ρ on the GLQ grid of degree max(2·La, 64) and take the
smallest node.  "certified" is :meth:`shspec.ConformalFactor.check_positive` now (grid + derivative bounds + the
cell bound; refinement only where that is inconclusive).  Cases: random smooth ρ (the test suite's generator,
amplitude 0.08) at La = 15 and 30, and the Möbius boost k = 5 (min/mean 1/600, which needs refinement).
Writes benchmarks/results/bench_positivity.json.  Run with one thread:

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_positivity.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_info, side_by_side, threads, write_json  # noqa: E402

from shspec.sphere.factor import ConformalFactor  # noqa: E402


def _random(la: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    l = np.repeat(np.arange(la + 1), 2 * np.arange(la + 1) + 1)
    a = rng.standard_normal(l.size) * 0.08 / (1.0 + l)
    a[0] = np.sqrt(4 * np.pi)
    return a


def _grid_sample(a: np.ndarray) -> float:
    values, _ = ConformalFactor(a).evaluate()
    return float(values.min())


def main() -> None:
    cases = {"random_La15": _random(15, 1), "random_La30": _random(30, 2),
             "boost_k5_La20": ConformalFactor.mobius_boost(5.0, 20).coefficients,
             "boost_k2_La30": ConformalFactor.mobius_boost(2.0, 30).coefficients}
    out = {"machine": machine_info(), "cases": {}}
    with threads(1):
        for name, a in cases.items():
            reps = 20 if name.startswith("boost_k5") else 300
            timing = side_by_side({"grid_sample": lambda: _grid_sample(a),
                                   "certified": lambda: ConformalFactor(a).check_positive()}, reps, warmup=2)
            low = ConformalFactor(a).check_positive()
            out["cases"][name] = {"timings": timing, "minimum": low.value, "lower_bound": low.lower_bound,
                                  "ratio": timing["certified"]["median_s"] / timing["grid_sample"]["median_s"]}
            print(name, {k: f"{v['median_s'] * 1e3:.3f} ms" for k, v in timing.items()},
                  f"bound {low.lower_bound:.4g} <= min {low.value:.4g}", flush=True)
    print(write_json("bench_positivity.json", out))


if __name__ == "__main__":
    main()
