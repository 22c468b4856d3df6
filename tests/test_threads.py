"""Many threads share one HarmonicModel and get the serial results bit for bit; a forked pool after a spectrum
works (issue 34 items 7 and 8).  Each runs in a subprocess, so that a crash or a hang is a failed test."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

THREADS = """
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from shspec import ConformalFactor
from shspec.galerkin import HarmonicModel, spectrum

model = HarmonicModel(10, 6)
rng = np.random.default_rng(0)
params = []
for i in range(96):
    a = np.zeros(49)
    a[0] = np.sqrt(4 * np.pi)
    a[1:] = 0.08 * rng.standard_normal(48)
    params.append((i, a, 30 + 7 * (i % 9)))  # grids of different sizes interleave in pyshtools


def job(p):
    i, a, grid = p
    rho = ConformalFactor(a)
    out = [rho.evaluate(grid)[0], rho.check_positive().value, rho.rotated(10, 20, 30).coefficients]
    if i % 4 == 0:  # the model's calls, fewer: they take longer
        out += [model.spectrum(a, 20).eigenvalues, model.eigenvalues(a, 12), model.energy(a, np.arange(20.0))[1],
                model.jacobian(model.spectrum(a, 12)), spectrum(a, 10, 8, truncation_tol=None).eigenvalues]
    return out


serial = [job(p) for p in params]
for rnd in range(2):
    with ThreadPoolExecutor(8) as pool:
        threaded = list(pool.map(job, params))
    for i, (s, t) in enumerate(zip(serial, threaded)):
        for x, y in zip(s, t):
            if not np.array_equal(x, y):
                sys.exit(f"round {rnd}, job {i}: a threaded result differs from the serial one")
print("ok")
"""

FORK = """
import multiprocessing

import numpy as np

from shspec.galerkin import spectrum
from shspec.fitting import blob_factor


def job(scale):
    return spectrum(blob_factor().scaled(scale), 8, 6, truncation_tol=None).eigenvalues


parent = job(1.0)  # a parallel kernel runs in the parent before the fork
with multiprocessing.get_context("fork").Pool(2) as pool:
    children = pool.map(job, [1.0, 2.0])
assert np.array_equal(children[0], parent) and np.allclose(children[1], parent / 2, rtol=1e-12)
print("ok")
"""


FORK_ON_GNU_OPENMP = """
import multiprocessing

from shspec.galerkin import spectrum
from shspec.fitting import blob_factor


def job(scale):
    return spectrum(blob_factor().scaled(scale), 8, 6, truncation_tol=None).eigenvalues


job(1.0)
with multiprocessing.get_context("fork").Pool(2) as pool:
    try:
        pool.map(job, [1.0, 2.0])
    except Exception as exc:
        print(type(exc).__name__)
"""


def _run(code: str, timeout: float, threads: int = 2, layer: str | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_NUM_THREADS=str(threads), OMP_NUM_THREADS="1")
    env.pop("NUMBA_THREADING_LAYER", None)
    if layer is not None:
        env["NUMBA_THREADING_LAYER"] = layer
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True, text=True,
                          check=False, timeout=timeout)


@pytest.mark.slow
def test_eight_threads_share_a_model_and_get_the_serial_results():
    # 4 threads crashed the interpreter in 2 of 4 runs (pyshtools' MakeGridGLQ from check_positive)
    done = _run(THREADS, timeout=240)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]


@pytest.mark.slow
def test_a_forked_pool_after_a_spectrum_in_the_parent_works():
    # numba's GNU OpenMP layer killed every forked worker ("fork() called from a process already using GNU
    # OpenMP, this is unsafe") and Pool.map waited for ever
    done = _run(FORK, timeout=60)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]


@pytest.mark.slow
def test_a_fork_after_gnu_openmp_fails_in_the_child_with_a_clear_error():
    # chosen by the user, GNU OpenMP still cannot survive a fork: the child now raises instead of being killed
    pytest.importorskip("numba.np.ufunc.omppool")
    done = _run(FORK_ON_GNU_OPENMP, timeout=60, layer="omp")
    assert done.returncode == 0 and done.stdout.strip() == "UnsafeForkError", done.stderr[-2000:]


FORK_WHILE_LOCKED = """
import os
import signal
import threading

from shspec.core import threads
from shspec.galerkin import spectrum
from shspec.fitting import blob_factor

spectrum(blob_factor(), 8, 6, truncation_tol=None)
held, release = threading.Event(), threading.Event()


def hold():
    with threads.PYSHTOOLS_LOCK, threads.NUMBA_LOCK:
        held.set()
        release.wait()


worker = threading.Thread(target=hold)
worker.start()
held.wait()
pid = os.fork()
if pid == 0:
    signal.alarm(20)  # a deadlocked child dies instead of outliving the test
    spectrum(blob_factor(), 8, 6, truncation_tol=None)  # would wait for ever for the parent thread's locks
    os._exit(0)
release.set()
worker.join()
print("ok" if os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) == 0 else "child failed")
"""


@pytest.mark.slow
def test_a_fork_while_another_thread_holds_the_locks_does_not_deadlock_the_child():
    done = _run(FORK_WHILE_LOCKED, timeout=60)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]
