"""Global search of the harmonic fit: which schedule and escape moves make random starts find the truth?

Random centred ρ (seed 1) of degree 8 (Lb 12, 100 eigenvalues, the K that ``shspec fit`` plans) and degree 10
(Lb 14, 144 eigenvalues, planned), several starts of seed 0, one BLAS/numba thread, serial.  Variants:

* ``default``: the (uncapped) degree ramp with 4 basin hops of the cheap moves (half-turns and sign flips of
  single degree blocks), the library's default when these were measured;
* ``orient``: the same with ``orient_blocks`` (when a block enters, its 47 octahedral orientations and reflections
  relative to the lower blocks are tried);
* ``wide``: a degree ramp that matches twice as many eigenvalues as coefficients at each stage, 2(l + 1)²;
* ``wide_orient``: both.

Two further cases ask what the degree ramp does with its starts and what capping its stages costs:

* random centred ρ (seed 1) of degree 10 at the setting of the degree-10 goal (Lb 24, 300 eigenvalues), 12 starts:
  ``capped`` (every stage but the last capped at 40 iterations, ``degree_ramp(..., stage_max_iter=40)``, 4 basin
  hops) and ``capped_no_hops`` (the same without hops), ``capped_hops12_cheap`` (up to 12 hops of the
  cheap moves, 8 starts) and ``capped_hops12`` (the same with the octahedral grid moves when the cheap ones are
  exhausted, ``hop_grid``), all with every stage on the model's basis, and ``defaults`` (the library's: the
  same with each stage before the last on its own smaller basis, ``stage_basis_tol``).  Each start records the relative residual at the end of
  every stage, which shows whether the starts still differ before the last stage;
* the blob (Lb 20, La 6, 120 eigenvalues, 8 starts): ``default`` (the library's defaults: the capped ramp, 12
  hops, the grid moves, the stages' own bases) against ``hops12_full_basis`` (the same with every stage on the
  model's basis) and ``capped`` (the capped ramp with 4 cheap hops and the full basis, the default before).

A start succeeds when its relative spectral residual is ≤ 1e-10; its ρ error after Möbius + O(3) alignment is
recorded.  The load average is recorded; times are per start, on one core.  The starts run on a pool of two
processes of one BLAS thread each (the results equal a serial run's: every start is seeded by its index).  A run
with ``--only TEXT`` runs the variants whose "case variant" name contains TEXT and replaces only those in the JSON
file.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/bench_global_search.py
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import RESULTS, load_average, machine_info, main_with_only, threads  # noqa: E402

from shspec import HarmonicModel  # noqa: E402
from shspec.inverse import FitOptions, Stage, align, blob_factor, degree_ramp, fit, harmonic_target  # noqa: E402
from shspec.parallel import make_executor  # noqa: E402
from shspec.sphere.random import random_centred_coefficients  # noqa: E402

#: name: (degree La, Lb, K, starts)
CASES = {"random degree 8 (Lb 12, K 100)": (8, 12, 100, 6), "random degree 10 (Lb 14, K 144)": (10, 14, 144, 4),
         "random degree 10 (Lb 24, K 300)": (10, 24, 300, 12), "blob (Lb 20, La 6, K 120)": (6, 20, 120, 8)}

#: Iterations of every stage but the last in the ``capped`` variants.
CAP = 40


def _wide(la: int, k: int) -> tuple:
    return tuple(Stage(lmax_factor=j, numeig=min(k, 2 * (j + 1) ** 2)) for j in range(2, la + 1)) \
        + (Stage(lmax_factor=la, numeig=k),)


def _variants(name: str, la: int, k: int, starts: int) -> dict:
    # every stage on the model's basis (stage_basis_tol=None) where that was the library's only way when measured
    full = dict(stage_basis_tol=None)
    if "K 300" in name:
        capped = degree_ramp(k, la, stage_max_iter=CAP)
        return {"capped": FitOptions(starts=starts, schedule=capped, basin_hops=4, **full),
                "capped_no_hops": FitOptions(starts=starts, schedule=capped, basin_hops=0, **full),
                "capped_hops12_cheap": FitOptions(starts=8, schedule=capped, basin_hops=12, hop_grid=False, **full),
                "capped_hops12": FitOptions(starts=8, schedule=capped, basin_hops=12, hop_grid=True, **full),
                "defaults": FitOptions(starts=8)}
    if name.startswith("blob"):
        capped = degree_ramp(k, la, stage_max_iter=CAP)
        return {"default": FitOptions(starts=starts),
                "hops12_full_basis": FitOptions(starts=starts, **full),
                "capped": FitOptions(starts=starts, schedule=capped, basin_hops=4, hop_grid=False, **full)}
    # the defaults of the time these were measured: the uncapped ramp, 4 cheap hops
    old = dict(starts=starts, basin_hops=4, hop_grid=False, **full)
    ramp = degree_ramp(k, la)
    return {"default": FitOptions(schedule=ramp, **old),
            "orient": FitOptions(schedule=ramp, orient_blocks=True, **old),
            "wide": FitOptions(schedule=_wide(la, k), **old),
            "wide_orient": FitOptions(schedule=_wide(la, k), orient_blocks=True, **old)}


def _stage_ends(history) -> list:
    """[stage, relative residual at its end, iterations] per stage (the basin hops count with the last stage)."""
    stages = sorted({int(st) for st in history[:, 0]})
    return [[st, float(history[history[:, 0] == st][-1, 2]), int((history[:, 0] == st).sum())] for st in stages]


def run(only: str | None) -> dict:
    path = RESULTS / "bench_global_search.json"
    out = json.loads(path.read_text()) if only and path.exists() else {"cases": {}}
    out.update({"machine": machine_info(), "load_before": load_average()})
    for name, (la, lb, k, starts) in CASES.items():
        if only and not any(only in f"{name} {label}" for label in _variants(name, la, k, starts)):
            continue
        if name.startswith("blob"):
            truth = blob_factor(la)
        else:
            truth = random_centred_coefficients(1, la, 0.2)
        target = harmonic_target(truth, lb, k)
        model = HarmonicModel(lb, la)
        rows = out["cases"].get(name, {})
        for label, options in _variants(name, la, k, starts).items():
            if only and only not in f"{name} {label}":
                continue
            t0 = time.perf_counter()
            with threads(1), make_executor(2) as executor:
                r = fit(target, model, options, executor=executor)
            rows[label] = {"successes": r.success_count, "starts": options.starts,
                           "wall_seconds": time.perf_counter() - t0,
                           "median_seconds_per_start": float(np.median([s.seconds for s in r.starts])),
                           "load_after": load_average(),
                           "per_start": [{"index": s.index, "relative_residual": s.relative_residual,
                                          "rho_error_after_alignment": align(model.to_factor(s.params),
                                                                             truth).relative_error,
                                          "iterations": s.iterations, "seconds": s.seconds, "success": s.success,
                                          "status": s.status, "stage_ends": _stage_ends(s.history)}
                                         for s in r.starts]}
            print(name, label, r.success_count, "/", options.starts, flush=True)
        out["cases"][name] = rows
    out["load_after"] = load_average()
    return out


if __name__ == "__main__":
    main_with_only(__doc__, "bench_global_search.json", run)
