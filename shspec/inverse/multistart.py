"""The inverse solver's entry point: several symmetry-broken starts through a schedule, every local solution kept.

A round start never leaves the even subspace (at an even ρ the gradient along odd degrees is exactly 0,
:doc:`/theory`), so every start is random, with odd degrees.  Starts run one after the other (each already uses the machine's
BLAS threads); each writes checkpoints if asked, and Ctrl-C ends the fit cleanly with the best state so far.
"""

from __future__ import annotations

import dataclasses
import hashlib
from concurrent.futures import Executor, as_completed
from pathlib import Path

import numpy as np

from ..checks import check_options
from ..errors import InvalidArgumentError
from ..spectral_model import SpectralModel
from .checkpoint import fingerprint, load_checkpoint, save_checkpoint
from .driver import run_start
from .options import FitOptions
from .problem import FitProblem, StartProgress
from .progress import FitDisplay
from .results import FitResult, StartResult
from ..targets import Target

__all__ = ["fit", "distinct_solutions"]


def distinct_solutions(starts: list, model: SpectralModel, tol: float) -> list:
    """Indices (into ``starts``) of the distinct local solutions, lowest energy first.

    Two starts are the same solution when their energies agree to ``tol`` relative (or both are below 1e-20) and
    their invariants (:meth:`~shspec.spectral_model.SpectralModel.invariant`: per-degree power for harmonic fits, the
    factors for meshes) agree to ``tol`` relative.
    """
    if not starts:
        raise InvalidArgumentError("no starts to compare")
    order = sorted(range(len(starts)), key=lambda i: starts[i].energy)
    reps: list[int] = []
    for i in order:
        ei, pi = starts[i].energy, model.invariant(starts[i].params)
        same = False
        for j in reps:
            ej, pj = starts[j].energy, model.invariant(starts[j].params)
            close_e = max(ei, ej) < 1e-20 or abs(ei - ej) <= tol * max(ei, ej)
            if close_e and np.linalg.norm(pi - pj) <= tol * np.linalg.norm(pj):
                same = True
                break
        if not same:
            reps.append(i)
    return reps


def _run_fresh_start(problem: FitProblem, index: int) -> StartResult:
    """One start from scratch (the task sent to an executor's worker): no checkpoints inside it."""
    rng = np.random.default_rng([problem.options.seed, index])
    return run_start(problem, StartProgress(index, 0, problem.initial(rng, index), None))


def _run_parallel(problem: FitProblem, pending: list, executor: Executor, finished: list, checkpoint,
                  display: FitDisplay) -> bool:
    """Run the pending starts on ``executor``; finished starts are appended (and checkpointed) as they complete.
    Returns True if Ctrl-C stopped it (the running starts are cancelled where the executor can)."""
    futures = {executor.submit(_run_fresh_start, problem, i): i for i in pending}
    try:
        for future in as_completed(futures):
            finished.append(future.result())
            if checkpoint is not None:
                checkpoint(None)
            display.start_done(finished[-1])
    except KeyboardInterrupt:
        for future in futures:
            future.cancel()
        return True
    return False


def fit(target: Target, model: SpectralModel, options: FitOptions | None = None, *, resume: bool = False,
        init=None, executor: Executor | None = None) -> FitResult:
    """Fit the parameters of ``model`` to the spectrum of ``target`` from several random starts.

    Parameters
    ----------
    target : Target
        The target spectrum (k eigenvalues; stages may use fewer).
    model : SpectralModel
        The discretization: its parameters, gauge, levels and regularizer (see :mod:`shspec.spectral_model`).
    options : FitOptions, optional
    resume : bool
        Continue from ``options.checkpoint_path`` if that file exists (it must be a checkpoint of the same fit).
    init : (nparams,) array, optional
        A starting point (e.g. a prior shape, or the previous pass of a recursive fit) for start 0; the other starts
        stay random.  With ``options.schedule`` None a fit from ``init`` is one stage at full resolution.
    executor : concurrent.futures.Executor, optional
        Run the starts on it (a process pool, or a Dask cluster's ``Client.get_executor()``; see
        :func:`shspec.parallel.make_executor`): each start is independent and seeded by its index, so the results are
        those of a serial run.  Finished starts are checkpointed as they arrive; a start still running when the
        fit stops is run again from its beginning on resume.  Run at most one start per process at a time
        (processes, or Dask workers with one thread each): threads are safe (:mod:`shspec.threads`), but they take
        turns in pyshtools' grid routines and numba's parallel kernels.

    Returns
    -------
    FitResult
        Every start, the distinct local solutions (best first), and whether Ctrl-C stopped the fit.  On Ctrl-C the
        running start is reported with status "interrupted" and its best state, and a checkpoint is written if a
        path is set.

    Raises
    ------
    InvalidArgumentError, BandLimitError
        For inconsistent options, target and model.
    CheckpointError
        If a checkpoint cannot be written, or read when resuming.

    Examples
    --------
    >>> from shspec.galerkin import HarmonicModel
    >>> from shspec.inverse import FitOptions, blob_factor, fit, harmonic_target
    >>> target = harmonic_target(blob_factor(), lmax=12, numeig=40)
    >>> result = fit(target, HarmonicModel(12, 6), FitOptions(starts=1))  # doctest: +SKIP
    """
    options = check_options(options, FitOptions)
    problem = FitProblem(model, target, options, init=init)
    fp = fingerprint(options, target.eigenvalues, model.describe()
                     + ("" if init is None else " init " + hashlib.sha256(problem.init.tobytes()).hexdigest()))
    finished: list[StartResult] = []
    current: StartProgress | None = None
    if resume and options.checkpoint_path is not None and Path(options.checkpoint_path).exists():
        finished, current, stored = load_checkpoint(options.checkpoint_path, fp, target.eigenvalues)
        if not np.array_equal(stored, target.eigenvalues):  # round-off apart: go on with the checkpoint's own
            target = dataclasses.replace(target, eigenvalues=stored)  # target, as the uninterrupted fit did
            problem = FitProblem(model, target, options, init=init)
    done = {r.index for r in finished}
    display = FitDisplay(options.starts, len(problem.stages), options.progress, done=len(done))
    try:
        interrupted = _run_starts(problem, executor, finished, current, done, fp, display)
    finally:
        display.close()
    if not finished:
        raise KeyboardInterrupt
    finished.sort(key=lambda r: r.index)
    solutions = distinct_solutions(finished, model, options.distinct_tol)
    return FitResult(starts=finished, solutions=solutions, target=problem.target, options=options, model=model,
                     seconds=float(sum(r.seconds for r in finished)), interrupted=interrupted)


def _run_starts(problem: FitProblem, executor, finished: list, current, done: set, fp: str,
                display: FitDisplay) -> bool:
    """Run the starts not in ``done`` (on ``executor``, or here one after the other, ``current`` first when a
    checkpoint left one running), appending them to ``finished``; returns whether an interrupt stopped them."""
    options, target = problem.options, problem.target

    def checkpoint(progress):
        save_checkpoint(options.checkpoint_path, fp, finished, progress, target.eigenvalues)

    interrupted = False
    if executor is not None:
        pending = [i for i in range(options.starts) if i not in done]
        interrupted = _run_parallel(problem, pending, executor, finished,
                                    checkpoint if options.checkpoint_path else None, display)
        if interrupted:
            display.message("interrupted: the finished starts are kept")
    else:
        for i in range(options.starts):
            if i in done:
                continue
            # the whole step is guarded: an interrupt (Ctrl-C, SIGTERM) between two starts keeps the finished ones too
            try:
                if current is None or current.index != i:
                    current = StartProgress(i, 0, problem.initial(np.random.default_rng([options.seed, i]), i),
                                            None)
                current.display = display
                finished.append(run_start(problem, current, checkpoint if options.checkpoint_path else None))
                display.start_done(finished[-1])
                current = None
                if options.checkpoint_path and options.checkpoint_every:
                    checkpoint(None)
            except KeyboardInterrupt:
                interrupted = True
                if options.checkpoint_path:
                    save_checkpoint(options.checkpoint_path, fp, finished, current, target.eigenvalues)
                running = current is not None and current.index not in {r.index for r in finished}
                if running and current.params is not None:
                    finished.append(current.result("interrupted", current.seconds, current.succeeded(problem)))
                display.message("interrupted: the best state so far is kept")
                break
    return interrupted
