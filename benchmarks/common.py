"""Shared helpers of the benchmarks: machine description, thread control, timing, peak memory, JSON output.

Benchmarks are not tests: they measure and write ``benchmarks/results/*.json``; nothing here asserts.  The machine
is usually shared, so absolute times are noisy; the scripts time the compared paths side by side in one process
(interleaved repeats) so that their *ratios* are meaningful, and record the load average before and after.
"""

from __future__ import annotations

import contextlib
import importlib.metadata
import json
import os
import platform
import signal
import statistics
import subprocess
import sys
import threading
import time
import tracemalloc
from datetime import datetime, timezone
from pathlib import Path

import numba
import numpy as np

from shspec.core.resources import load_average  # noqa: F401  (the benchmarks record it beside their timings)

try:
    import psutil
except ImportError:  # pragma: no cover - listed in the bench extra
    psutil = None
try:
    from threadpoolctl import threadpool_info, threadpool_limits
except ImportError:  # pragma: no cover - listed in the bench extra
    threadpool_info = threadpool_limits = None

RESULTS = Path(__file__).resolve().parent / "results"
REPO = Path(__file__).resolve().parent.parent


def _version(name: str):
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return None


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def git_commit() -> str | None:
    try:
        return subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def library_source() -> dict:
    """Where the measured shspec came from: its path, and whether the repo's library files had uncommitted edits.

    The work tree may be shared with concurrent work; to measure a committed state, export it
    (``git archive HEAD shspec | tar -x -C DIR``, with ``git rev-parse HEAD > DIR/COMMIT``) and run the benchmark
    with ``PYTHONPATH=DIR`` from outside the repository root.
    """
    import shspec

    pkg = Path(shspec.__file__).resolve().parent
    out = {"shspec_imported_from": str(pkg)}
    commit_file = pkg.parent / "COMMIT"
    if commit_file.is_file():
        out["shspec_exported_commit"] = commit_file.read_text().strip()
    try:
        out["repo_uncommitted_library_files"] = subprocess.run(
            ["git", "-C", str(REPO), "status", "--porcelain", "--", "shspec"], capture_output=True, text=True,
            check=True).stdout.split("\n")[:-1]
    except (OSError, subprocess.CalledProcessError):
        pass
    return out


def machine_info() -> dict:
    """Platform, CPU, core count, library versions, BLAS pools (threadpoolctl), load average and date."""
    info = {
        "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "affinity_cpus": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "load_average_1_5_15": load_average(),
        "git_commit": git_commit(),
        **library_source(),
        "versions": {name: _version(name) for name in
                     ("shspec", "numpy", "scipy", "numba", "pyshtools", "lapy", "sympy", "trimesh", "threadpoolctl",
                      "psutil", "matplotlib")},
        "numba_threading_layer_default_threads": numba.config.NUMBA_NUM_THREADS,
        # recorded, never changed: on some processors these are set by the environment (see the env README)
        "env": {k: os.environ.get(k) for k in ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE", "OMP_NUM_THREADS",
                                                 "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")},
        "blas": threadpool_info() if threadpool_info is not None else None,
    }
    if psutil is not None:
        info["memory_total_gib"] = round(psutil.virtual_memory().total / 2**30, 1)
    return info


@contextlib.contextmanager
def threads(n: int):
    """Limit numba's parallel loops and every BLAS/OpenMP pool of the process to ``n`` threads."""
    old = numba.get_num_threads()
    numba.set_num_threads(n)
    try:
        if threadpool_limits is not None:
            with threadpool_limits(limits=n):
                yield
        else:
            yield
    finally:
        numba.set_num_threads(old)


def timed(fn, *args, **kwargs):
    """(seconds, result) of one call."""
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return time.perf_counter() - t0, out


def summarize(times: list[float]) -> dict:
    return {"median_s": statistics.median(times), "min_s": min(times), "max_s": max(times), "repeats": len(times),
            "all_s": [round(t, 6) for t in times]}


def side_by_side(funcs: dict, repeats: int, warmup: int = 1) -> dict:
    """Time several zero-argument callables in interleaved rounds (a, b, c, a, b, c, ...); summaries per name.

    Interleaving spreads the fluctuations of a shared machine evenly over the compared paths, so that the ratios
    of the medians are fair even when the absolute times drift.
    """
    for _ in range(warmup):
        for fn in funcs.values():
            fn()
    times = {name: [] for name in funcs}
    for _ in range(repeats):
        for name, fn in funcs.items():
            times[name].append(timed(fn)[0])
    return {name: summarize(t) for name, t in times.items()}


class _RssSampler:
    """Peak resident set size while a block runs, sampled every ``interval`` seconds in a thread."""

    def __init__(self, interval: float = 0.002):
        self.interval = interval
        self.peak = 0
        self._stop = threading.Event()

    def _run(self):
        proc = psutil.Process()
        while not self._stop.is_set():
            self.peak = max(self.peak, proc.memory_info().rss)
            time.sleep(self.interval)

    def __enter__(self):
        self.base = psutil.Process().memory_info().rss
        self.peak = self.base
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, psutil.Process().memory_info().rss)


def peak_memory(fn) -> dict:
    """Peak memory of one (untimed) call: numpy/Python allocations by tracemalloc, and the RSS growth by psutil.

    tracemalloc sees every numpy array (numpy reports to it) but not numba's internal temporaries; the RSS
    high-water mark sees everything but is coarser (page granularity, allocator caching, 2 ms sampling).
    """
    out = {}
    tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    result = fn()
    out["tracemalloc_peak_bytes"] = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    del result
    if psutil is not None:
        with _RssSampler() as s:
            result = fn()
        out["rss_growth_bytes"] = s.peak - s.base
        del result
    return out


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        x = float(x)
    if isinstance(x, float) and not np.isfinite(x):
        return None if np.isnan(x) else ("inf" if x > 0 else "-inf")
    return x


def write_json(name: str, data: dict) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / name
    path.write_text(json.dumps(_jsonable(data), indent=1) + "\n")
    return path


def updated_record(name: str) -> dict:
    """The record ``name`` as written before (empty if none), with this run's machine, commit and core count: for
    benchmarks that add their cases to it run by run."""
    path = RESULTS / name
    report = json.loads(path.read_text()) if path.exists() else {}
    report.update(machine=machine_info(), commit=git_commit(), cpu_count=os.cpu_count())
    return report


def command_line(doc: str):
    """The command line of a benchmark without options: ``--help`` says what it measures; returns the parsed
    arguments."""
    import argparse

    return argparse.ArgumentParser(description=doc.splitlines()[0]).parse_args()


def main_with_only(doc: str, name: str, run) -> None:
    """The command line of a benchmark of named cases: ``--only TEXT`` runs the cases whose name contains TEXT;
    ``run(only)`` returns the JSON written to ``results/name``."""
    import argparse

    p = argparse.ArgumentParser(description=doc.splitlines()[0])
    p.add_argument("--only", help="run only the cases whose name contains this text")
    print(write_json(name, run(p.parse_args().only)))


def run_fit_command(command: list, out: Path, goal: float) -> dict:
    """Run ``shspec`` with ``command`` (a fit writing into ``out``) in a fresh process, stopped by SIGTERM at
    ``goal`` seconds (shspec fit takes it as Ctrl-C and keeps its states), and what its summary says of the truth.

    Returns the wall time, the load average before and after, whether it was stopped, and from ``summary.json``:
    success, starts run, K, model, residual, the aligned errors of rho and of its per-degree power, the rho_error it
    reported, and each start's residual, iterations, time and work.
    """
    load, t0 = load_average(), time.perf_counter()
    fit = subprocess.Popen([sys.executable, "-m", "shspec", *command], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    try:
        _, stderr = fit.communicate(timeout=goal)
        stopped = False
    except subprocess.TimeoutExpired:
        # past the goal the goal is missed anyway: stop it as a batch system would (shspec fit takes SIGTERM as
        # Ctrl-C; SIGINT would be ignored in a background job) and record the states it kept
        fit.send_signal(signal.SIGTERM)
        _, stderr = fit.communicate()
        stopped = True
    wall = time.perf_counter() - t0
    record = {"exit_code": fit.returncode, "stopped_at_goal": stopped, "wall_s": wall, "goal_wall_s": goal,
              "load_average_before_after": [load, load_average()]}
    if not (out / "summary.json").exists():
        return {**record, "stderr": stderr[-2000:]}
    summary = json.loads((out / "summary.json").read_text())
    alignment = summary.get("alignment") or {}
    record.update(success=summary["successes"] > 0, starts_run=len(summary["starts"]),
                  numeig=summary["numeig"], model=summary["model"],
                  relative_residual=summary["relative_residual"],
                  rho_error=alignment.get("relative_error"), power_error=alignment.get("power_error"),
                  reported_rho_error=(summary.get("rho_error") or {}).get("value"),
                  per_start=[{k: st[k] for k in ("index", "relative_residual", "iterations", "time_s", "work",
                                                 "success")} for st in summary["starts"]])
    return record
