"""Where a degree-10 start spends its time: the degree ramp, its last stage, and each basin hop.

The degree-10 goal of the harmonic inverse (random centred ρ of seed 1, La 10, Lb 24, 300 eigenvalues; ≥ 3 of 4
starts, median ≤ 2 minutes per start) misses its time by about a factor of two (bench_global_search.json).  This
script runs N starts (``--starts``, default 8) of the library's defaults (the capped degree ramp on the stages' own
bases, 12 basin hops with the octahedral grid moves, at most 144 refits per round of moves, a refit still falling
fast at 15 iterations extended to at most 45), N without that extension (the default before), N with 48 refits per
round (the default before that) and N with every stage on the model's basis (``--only`` picks variants, comma-
separated; the others' records in the JSON are kept, each with its commit and CPU), and records for each start the
time to the end of the stages and, for every round of moves (one call of ``shspec.inverse.schedule._hop_once``:
the cheap moves of a hop, or the grid moves it tries after them), the moves screened, its time, whether a move was
accepted and the energy before and after.  The rounds are timed by wrapping ``_hop_once`` inside each worker; the
fit itself is unchanged.

The starts run on a pool of two processes (spawned) with one BLAS/numba thread each; the load average is recorded.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/bench_hop_anatomy.py [--starts 16]
"""

from __future__ import annotations

import json
import multiprocessing
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import RESULTS, load_average, machine_info, threads, write_json  # noqa: E402

LA, LB, K = 10, 24, 300
VARIANTS = {"defaults": {}, "no_extension": {"hop_extend": 15}, "hop_tries_48": {"hop_tries": 48},
            "full_basis": {"stage_basis_tol": None}}


def _problem(**options):
    """The degree-10 goal case under FitOptions(**options), and its truth (coefficients)."""
    from shspec import HarmonicModel
    from shspec.inverse import FitOptions, harmonic_target
    from shspec.inverse.schedule import FitProblem
    from shspec.sphere.random import random_centred_coefficients

    truth = random_centred_coefficients(1, LA, 0.2)
    model = HarmonicModel(LB, LA)
    return FitProblem(model, harmonic_target(truth, LB, K), FitOptions(**options)), truth


def run_one(variant: str, index: int) -> dict:
    """One start of ``variant`` with its hops timed (runs in a worker process)."""
    import shspec.inverse.schedule as schedule
    from shspec.inverse import align
    from shspec.inverse.schedule import StartProgress, run_start

    hops, t0 = [], time.perf_counter()
    plain = schedule._hop_once

    def timed(problem, progress, s, moves, status):
        if not hops:
            hops.append({"stages_end_seconds": time.perf_counter() - t0})
        t, before = time.perf_counter(), progress.energy
        accepted, status = plain(problem, progress, s, moves, status)
        hops.append({"moves": len(moves), "seconds": time.perf_counter() - t, "accepted": bool(accepted),
                     "energy_before": float(before), "energy_after": float(progress.energy)})
        return accepted, status

    schedule._hop_once = timed
    with threads(1):
        problem, truth = _problem(**VARIANTS[variant])
        t0 = time.perf_counter()
        rng = np.random.default_rng([problem.options.seed, index])
        r = run_start(problem, StartProgress(index, 0, problem.initial(rng, index), None))
    stages_end = hops.pop(0)["stages_end_seconds"] if hops else r.seconds
    return {"index": index, "success": r.success, "relative_residual": r.relative_residual,
            "rho_error_after_alignment": align(problem.model.to_factor(r.params), truth).relative_error,
            "iterations": r.iterations, "seconds": r.seconds, "stages_seconds": stages_end,
            "hops_seconds": float(sum(h["seconds"] for h in hops)), "hops": hops}


def run(only: str | None, nstarts: int = 8) -> dict:
    out = {"machine": machine_info(), "load_before": load_average(), "case": f"random degree {LA} (Lb {LB}, K {K})",
           "variants": {}}
    for variant in VARIANTS:
        if only and not any(name in variant for name in only.split(",")):
            continue
        t0, load_before = time.perf_counter(), load_average()
        with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
            starts = list(pool.map(run_one, [variant] * nstarts, range(nstarts)))
        secs = [s["seconds"] for s in starts]
        out["variants"][variant] = {
            "successes": sum(s["success"] for s in starts), "starts": nstarts,
            "successes_of_first_four": sum(s["success"] for s in starts[:4]), "wall_seconds": time.perf_counter() - t0,
            "median_seconds_per_start": float(np.median(secs)),
            "median_stages_seconds": float(np.median([s["stages_seconds"] for s in starts])),
            "median_hops_seconds": float(np.median([s["hops_seconds"] for s in starts])),
            "failed_hop_seconds": [h["seconds"] for s in starts for h in s["hops"] if not h["accepted"]],
            "options": VARIANTS[variant], "git_commit": out["machine"].get("git_commit"),
            "cpu": out["machine"].get("cpu"),
            "load_before": load_before, "load_after": load_average(), "per_start": starts}
        print(variant, out["variants"][variant]["successes"], "/", nstarts, flush=True)
        out["load_after"] = load_average()
        print(_write(out, only))  # after every variant: an interrupted run keeps the variants it finished
    return out


def _write(result: dict, only: str | None) -> str:
    """Write ``result``, keeping the previous file's variants this run has not run: with ``only`` every other one
    (each with its own record and CPU), without it those still to come."""
    previous = RESULTS / "bench_hop_anatomy.json"
    if previous.exists():
        old = json.loads(previous.read_text())
        kept = {k: {"cpu": old["machine"].get("cpu"), **v} for k, v in old["variants"].items()
                if k not in result["variants"] and (only or k in VARIANTS)}
        result = {**result, "variants": {**kept, **result["variants"]}}
    return write_json("bench_hop_anatomy.json", result)


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", help="run only the variants whose name contains this text (or one of these, "
                        "comma-separated)")
    parser.add_argument("--starts", type=int, default=8, help="starts per variant, indices 0 … N−1 (default 8)")
    args = parser.parse_args()
    run(args.only, args.starts)
