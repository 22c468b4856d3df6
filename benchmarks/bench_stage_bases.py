"""The stages of a harmonic fit on their own bases (``FitOptions.stage_basis_tol``) against every stage on Lb.

The blob at La = 15 with the K the planner recommends for it (K = 704, Lb = 42), start 0 of seed 0, the default
degree ramp, no basin hops; one process per mode, both side by side on the two cores, one BLAS/numba thread each.
Each process reports the end of every stage on stderr (``progress``), stamped here as it arrives; the JSON holds,
per mode, the minutes from the launch of the process to the end of each stage, and at the end the chosen bases,
the final residual and the ρ error after alignment.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/bench_stage_bases.py
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import RESULTS, load_average, machine_info  # noqa: E402

MODES = {"own_bases": 1e-5, "full_basis": None}


def one(mode: str) -> None:
    """Run start 0 in this process; one JSON line per stage end and one at the end on stdout."""
    from shspec import HarmonicModel
    from shspec.inverse import FitOptions, align, blob_factor, harmonic_target
    from shspec.inverse.schedule import FitProblem, StartProgress, run_start

    truth = blob_factor(15)
    target = harmonic_target(truth, 42, 704)
    model = HarmonicModel(42, 15)
    t0 = time.perf_counter()
    options = FitOptions(starts=1, basin_hops=0, stage_basis_tol=MODES[mode], progress=True)
    problem = FitProblem(model, target, options)
    setup = time.perf_counter() - t0
    progress = StartProgress(0, 0, problem.initial(np.random.default_rng([options.seed, 0]), 0), None)
    result = run_start(problem, progress)
    history = np.asarray(result.history)  # rows (stage, energy, relative residual)
    ends = history[np.r_[np.diff(history[:, 0]) != 0, True]]
    print(json.dumps({"mode": mode, "setup_seconds": setup, "start_seconds": result.seconds,
                      "relative_residual": result.relative_residual,
                      "rho_error_after_alignment": align(model.to_factor(result.params), truth).relative_error,
                      "iterations": result.iterations, "status": result.status, "bases": problem.bases,
                      "stage_ends": [[int(s), float(r)] for s, _, r in ends]}), flush=True)


def _stage_ends(stream, launched: float, rows: list) -> None:
    pattern = re.compile(r"stage (\d+) \((.*?)\): (\S+) after (\d+) iterations, max rel. residual (\S+)")
    for line in stream:
        m = pattern.search(line)
        if m:
            rows.append({"stage": int(m[1]), "what": m[2], "minutes_since_launch": (time.time() - launched) / 60,
                         "status": m[3], "iterations": int(m[4]), "max_relative_residual": float(m[5])})


def main() -> None:
    out = {"machine": machine_info(), "load_before": load_average(), "modes": {}}
    launched = time.time()
    procs = {m: subprocess.Popen([sys.executable, __file__, m], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 text=True) for m in MODES}
    stages = {m: [] for m in MODES}
    readers = [threading.Thread(target=_stage_ends, args=(p.stderr, launched, stages[m])) for m, p in procs.items()]
    for r in readers:
        r.start()
    for mode, proc in procs.items():
        out["modes"][mode] = {"stages": stages[mode], **json.loads(proc.stdout.read().strip().splitlines()[-1])}
        proc.wait()
    for r in readers:
        r.join()
    out["load_after"] = load_average()
    path = RESULTS / "bench_stage_bases.json"
    path.write_text(json.dumps(out, indent=1) + "\n")
    print(path)


if __name__ == "__main__":
    if len(sys.argv) > 1:
        one(sys.argv[1])
    else:
        main()
