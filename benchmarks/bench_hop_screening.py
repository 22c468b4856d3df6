"""Can a basin hop tell its good moves early, and do the failed degree-10 starts have any?

The degree-10 goal of the harmonic inverse (random centred ρ of seed 1, La 10, Lb 24, 300 eigenvalues) loses its
starts in local minima that the basin hops do not leave.  A hop refits up to ``hop_tries`` moves for ``hop_iter``
(15) iterations each, in the order of their energy before any refit.  This script asks two questions of the end
states of failed starts:

1. **Screening.**  Every grid move of the state (303: each degree block through the octahedral group, and the
   improper rotations of the odd blocks) is refitted for 15 iterations of plain LM, exactly as a hop screens it, and
   the energy after every iteration is recorded.  A *good* move is one that ends below the state's energy.  The
   summary gives the ranks of the good moves by energy after 0, 1, 2, 3, 5, 8 and 15 iterations: if they ranked
   first early, a successive-halving screen (short refits for all, longer ones for the best) would find them at a
   fraction of the cost.  It also counts the moves that fall back into the state's own minimum (end within 1e-3 of
   its energy).
2. **Powers.**  Every move keeps the per-degree power Σ_m a_lm² (the spectrum's second-order invariant).  The
   summary gives the relative difference of the state's powers from the truth's, per degree: where they differ, no
   sequence of moves alone reaches the truth.

``--state I:T`` runs start I of the library's defaults with ``hop_tries=T`` to its end (two at a time, one BLAS
thread each); a start that succeeds has no failed state and is recorded as such.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        python benchmarks/bench_hop_screening.py --state 0:144 --state 1:144 --state 2:144 --state 4:48
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_hop_anatomy import K, LA, LB, _problem  # noqa: E402
from common import load_average, machine_info, threads, write_json  # noqa: E402

ITERATIONS = 15
RANK_AT = (0, 1, 2, 3, 5, 8, 15)


def run_state(index: int, hop_tries: int) -> dict:
    """Start ``index`` to its end, then every grid move of its end state refitted as a hop screens it."""
    from shspec.errors import NotPositiveError
    from shspec.inverse.optimize import make_optimizer
    from shspec.inverse.schedule import StartProgress, _grid_moves, run_start

    with threads(1):
        problem, truth = _problem(hop_tries=hop_tries)
        rng = np.random.default_rng([problem.options.seed, index])
        t = time.perf_counter()
        r = run_start(problem, StartProgress(index, 0, problem.initial(rng, index), None))
        out = {"index": index, "hop_tries": hop_tries, "success": r.success, "energy": r.energy,
               "relative_residual": r.relative_residual, "start_seconds": time.perf_counter() - t,
               "power": problem.model.invariant(r.params).tolist(),
               "truth_power": problem.model.invariant(truth).tolist()}
        if r.success:
            return out
        s = len(problem.stages) - 1
        screening = replace(problem.options, lm_acceleration=False)
        moves, t = [], time.perf_counter()
        for q in _grid_moves(problem.model, r.params, problem.level(s)):
            try:
                obj = problem.objective(s, q)
                e0 = obj.values(obj.initial()).energy
                optimizer = make_optimizer(problem.optimizer, obj, obj.initial(), screening)
            except NotPositiveError:
                moves.append(None)
                continue
            energies = [e0]
            while optimizer.status is None and optimizer.iteration < ITERATIONS:
                optimizer.step()
                energies.append(optimizer.ev.energy)
            moves.append(energies)
        out["screening_seconds"] = time.perf_counter() - t
        out["moves"] = moves
        return out


def summarize(state: dict) -> dict:
    """Ranks of the good moves by energy after each number of iterations, returners, power differences."""
    p, p0 = np.array(state["power"]), np.array(state["truth_power"])
    out = {k: state[k] for k in ("index", "hop_tries", "success", "energy", "relative_residual", "start_seconds")}
    out["power_relative_difference_by_degree"] = [float(x) for x in (p[1:] - p0[1:]) / np.maximum(p0[1:], 1e-300)]
    if state["success"]:
        return out
    e = state["energy"]
    traj = np.full((len(state["moves"]), ITERATIONS + 1), np.inf)
    for i, m in enumerate(state["moves"]):
        if m is not None:
            traj[i, :len(m)] = m
            traj[i, len(m):] = m[-1]  # a refit that stopped keeps its energy
    rel = traj / e
    good = np.flatnonzero(rel[:, -1] < 1.0)
    ranks = {}
    for it in RANK_AT:
        order = np.argsort(np.argsort(rel[:, it], kind="stable"), kind="stable")
        ranks[str(it)] = sorted(int(order[g]) for g in good)
    out.update({"grid_moves": len(state["moves"]), "good_moves": good.tolist(),
                "good_move_ranks_by_iterations": ranks,
                "good_move_relative_energies": {str(int(g)): [round(float(x), 4) for x in rel[g]] for g in good},
                "returners": int(np.sum(np.abs(rel[:, -1] - 1.0) <= 1e-3)),
                "lowest_relative_energy_after_5": [round(float(x), 4) for x in np.sort(rel[:, 5])[:5]],
                "screening_seconds": state["screening_seconds"],
                "seconds_per_move": state["screening_seconds"] / len(state["moves"])})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--state", action="append", default=None, metavar="I:T",
                    help="start I of the defaults with hop_tries T (repeatable; default 0:144 1:144 2:144 4:48)")
    args = ap.parse_args()
    states = [tuple(int(v) for v in s.split(":")) for s in (args.state or ["0:144", "1:144", "2:144", "4:48"])]
    before, t = load_average(), time.perf_counter()
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        raw = list(pool.map(run_state, *zip(*states)))
    print(write_json("bench_hop_screening.json", {
        "machine": machine_info(), "load_before": before,
        "case": f"random degree {LA} (seed 1, Lb {LB}, K {K}), end states of failed starts of the defaults",
        "wall_seconds": time.perf_counter() - t, "states": [summarize(r) for r in raw], "load_after": load_average()}))


if __name__ == "__main__":
    main()
