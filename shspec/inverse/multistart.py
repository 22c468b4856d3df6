"""The inverse solver's entry point: several symmetry-broken starts through a schedule, every local solution kept.

A round start never leaves the even subspace (at an even ρ the gradient along odd degrees is exactly 0,
:doc:`/theory`), so every start is random, with odd degrees.  Starts run one after the other, or on an executor,
with the same bits either way (:func:`shspec.core.threads.reproducible`); each writes checkpoints if asked, and Ctrl-C
ends the fit cleanly with the best state so far.  By default the fit stops at a success
(:attr:`FitOptions.stop_at_success`): the starts race in rounds of :attr:`FitOptions.race`, and the answer is the
success of the first round that has one that took the least work (:mod:`~shspec.inverse.race`), whatever order
the starts ended in.

On an executor.  Each start is independent and seeded by its index, so the results are those of a serial run, with
:attr:`FitOptions.stop_at_success` too: when a start of race round r succeeds, the other starts of round r go on
only while they have done less work, the pending starts of later rounds are cancelled, and the fit waits for the
running starts of earlier rounds (one of them may succeed, and then it is the answer); starts that ended anyway but
lost the race are left out of the result.  A start of a later round already running in a process pool cannot be
cancelled: the fit returns without its result, and it ends in its worker at its next look at the race (within
:data:`~shspec.inverse.race.POLL_SECONDS` and one iteration); :func:`shspec.core.parallel.stop_executor` ends it at
once (``shspec fit`` does).  On Ctrl-C the running starts of a :class:`~shspec.core.parallel.WorkerPool`
(``make_executor(workers=N)``) are interrupted and their best states, status "interrupted", are part of the result
(waited for up to :data:`INTERRUPT_GRACE` seconds).  Finished starts are checkpointed as they arrive; a start still
running when the fit stops is run again from its beginning on resume (or from the state a serial run's checkpoint
holds), as the checkpoints are written between starts only.  Run at most one start per process at a time
(processes, or Dask workers with one thread each): threads are safe (:mod:`shspec.core.threads`), but they take
turns in pyshtools' grid routines and numba's parallel kernels.
"""

from __future__ import annotations

import dataclasses
import math
import time
from concurrent.futures import FIRST_COMPLETED, Executor, wait
from pathlib import Path

import numpy as np

from ..core.checks import check_options
from ..errors import InvalidArgumentError
from ..core.parallel import SerialExecutor, interruptible
from ..spectral_model import SpectralModel
from .checkpoint import fingerprint, load_checkpoint, save_checkpoint
from .driver import run_start
from .options import FitOptions
from .problem import FitProblem, StartProgress
from .progress import FitDisplay
from .race import ABANDONED, RaceBoard, RaceBound, best_success, race_outcome, race_round, won_round
from .results import FitResult, StartResult
from .prepared import PreparedFit
from .target import Target
from ..core.threads import reproducible_call

__all__ = ["fit", "distinct_solutions", "spectral_scale", "SAFE_EIGENVALUES"]

#: The eigenvalues a fit runs on as they are.  Its arithmetic squares eigenvalues and ρ's coefficients (weights
#: 1/λ², the Jacobian's λ·v²): λ·1e-100 of the blob raised "A has a NaN entry" inside SciPy, λ·1e300 ended at a
#: residual of 4.4e-2 where λ ended at 1.5e-2.
SAFE_EIGENVALUES = (2.0 ** -64, 2.0 ** 64)


def spectral_scale(eigenvalues) -> float:
    """The factor :func:`fit` divides a spectrum (k,) by before it fits it: 1 when λ₁ … λ_k are within
    :data:`SAFE_EIGENVALUES`, else the power of 2 nearest λ₁ (exact in floating point, so that λ₁ becomes about 1).
    λ₀ ≈ 0 does not count (a target's may be an ulp off 0).

    The problem is scale-free: the surface scaled by √s in length has the eigenvalues λ/s and the metric s·ρ.
    """
    lam = np.asarray(eigenvalues, dtype=float)[1:]
    if lam.size == 0 or not lam.min() > 0 or (SAFE_EIGENVALUES[0] <= lam.min() and lam.max() <= SAFE_EIGENVALUES[1]):
        return 1.0
    return float(2.0 ** round(math.log2(lam.min())))


def _fit_scaled(target: Target, model: SpectralModel, options, *, init, **kwargs) -> FitResult:
    """:func:`fit` of ``target`` through the same surface scaled to eigenvalues of order 1 (:func:`spectral_scale`),
    its result mapped back: parameters by :meth:`~shspec.spectral_model.SpectralModel.scaled`, eigenvalues, and
    the energy when the weights are absolute (relative ones and those of the errors are scale-free)."""
    options = check_options(options, FitOptions)
    s = spectral_scale(target.eigenvalues)
    inner = dataclasses.replace(target, eigenvalues=target.eigenvalues / s,
                                errors=None if target.errors is None else target.errors / s,
                                area=None if target.area is None else target.area * s)
    result = fit(inner, model, options, init=None if init is None else model.scaled(init, s), **kwargs)
    energy = s * s if options.weights == "absolute" else 1.0
    starts = [dataclasses.replace(r, params=model.scaled(r.params, 1.0 / s), eigenvalues=r.eigenvalues * s,
                                  energy=r.energy * energy, history=r.history * np.array([1.0, energy, 1.0]))
              for r in result.starts]
    return dataclasses.replace(result, starts=starts, target=target)


def distinct_solutions(starts: list, model: SpectralModel, tol: float) -> list:
    """Indices (into ``starts``) of the distinct local solutions, lowest energy first.

    Two starts are the same solution when their energies agree to ``tol`` relative (or both are below 1e-20) and
    their invariants (:meth:`~shspec.spectral_model.SpectralModel.invariant`: per-degree power for harmonic fits, the
    factors for meshes) agree to ``tol`` relative.

    Examples
    --------
    >>> from shspec import HarmonicModel
    >>> from shspec.fitting import blob_factor, harmonic_target
    >>> from shspec.inverse import FitOptions, distinct_solutions, fit
    >>> model = HarmonicModel(10, 2)
    >>> result = fit(harmonic_target(blob_factor().truncated(2), 10, 16), model,
    ...              FitOptions(starts=2, max_iter=20, basin_hops=0, stop_at_success=False, progress=False))
    >>> distinct_solutions(result.starts, model, 1e-4)   # both starts found the same rho
    [0]
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


#: Seconds an interrupted fit waits for the running starts of its process pool to send back their best states.
INTERRUPT_GRACE = 30.0


def _run_fresh_start(problem: FitProblem, index: int, bound: RaceBound | None) -> StartResult:
    """One start from scratch (the task sent to an executor's worker), in the race with ``bound``: no checkpoints
    inside it."""
    rng = np.random.default_rng([problem.options.seed, index])
    return _continue_start(problem, StartProgress(index, 0, problem.initial(rng, index), None, bound=bound))


@reproducible_call
def _continue_start(problem: FitProblem, progress: StartProgress) -> StartResult:
    """A start a checkpoint left running, continued from its state (the task sent to an executor's worker).  When
    its pool's owner interrupts it (:meth:`~shspec.core.parallel.WorkerPool.interrupt_workers`), the start ends at its
    best state, with status "interrupted"."""
    try:
        with interruptible():
            return run_start(problem, progress)
    except KeyboardInterrupt:
        if progress.params is None:  # interrupted before its first state: nothing to send back
            raise
        return progress.result("interrupted", progress.seconds, progress.succeeded(problem, final=True))


def _run_parallel(problem: FitProblem, pending: list, executor: Executor, finished: list, checkpoint,
                  display: FitDisplay, current: StartProgress | None = None) -> bool:
    """Run the pending starts (in order of their index; ``current``, a start a checkpoint left running, from its
    state) on ``executor``; finished starts are appended (and checkpointed) as they complete.

    With ``stop_at_success``, once a start of race round r succeeded (:mod:`~shspec.inverse.race`) its work is
    posted to the other starts of round r, which stop once they pass it, the pending starts of later rounds are
    cancelled and the running ones no longer waited for; the starts of earlier rounds are, one of them may succeed
    too.  Returns True if Ctrl-C stopped it (the running starts are cancelled where the executor can)."""
    stop, width = problem.options.stop_at_success, problem.options.race
    won = won_round(finished, width)
    futures = {}
    with RaceBoard() as board:
        for i in pending:
            bound = RaceBound(i, best_success(finished, i, width), board.path(race_round(i, width))) if stop else None
            if current is not None and current.index == i:
                current.bound = bound
                futures[executor.submit(_continue_start, problem, current)] = i
            else:
                futures[executor.submit(_run_fresh_start, problem, i, bound)] = i
        waiting = set(futures)
        try:
            while waiting:
                ended, waiting = wait(waiting, return_when=FIRST_COMPLETED)
                for future in sorted(ended, key=futures.get):
                    finished.append(future.result())
                    if checkpoint is not None:
                        checkpoint(None)
                    display.start_done(finished[-1])
                    if stop and finished[-1].success:
                        won = min(won, _posted(board, finished[-1], waiting, futures, won, width, display))
                if stop and won < math.inf:
                    for future in [f for f in waiting if race_round(futures[f], width) > won]:
                        # a running start of a process pool cannot be cancelled: the board ends it
                        if not future.cancel():
                            board.close(race_round(futures[future], width))
                        waiting.discard(future)
        except KeyboardInterrupt:
            for future in futures:
                future.cancel()
            _collect_interrupted(executor, {f for f in waiting if not f.cancelled()}, finished, display)
            return True
        except BaseException:
            for future in futures:
                future.cancel()
            raise
    return False


def _posted(board: RaceBoard, result: StartResult, waiting: set, futures: dict, won: float, width: int,
            display: FitDisplay) -> int:
    """Post the success ``result`` to the other starts of its round on ``board``, say on the console what the fit
    waits for now, and return its round."""
    rnd = race_round(result.index, width)
    board.post(rnd, result.work, result.index)
    if rnd >= won:
        return rnd
    later = [f for f in waiting if race_round(futures[f], width) > rnd]
    if later:
        display.message(f"start {result.index} succeeded: the {len(later)} start(s) of later rounds are not waited "
                        "for, and the running ones end at their next look at the race (stop_at_success)")
    rivals = sorted(futures[f] for f in waiting if race_round(futures[f], width) == rnd)
    if rivals:
        display.message(f"start {result.index} succeeded after work {result.work:.4g}; start(s) "
                        f"{', '.join(map(str, rivals))} of its round go on only while they have done less")
    before = sorted(futures[f] for f in waiting if race_round(futures[f], width) < rnd)
    if before:
        # the wait can be long (a failing start's last round of hops ran 186 s at degree 8), and the console is
        # silent meanwhile: say why, and how to take the success now
        display.message(f"start {result.index} succeeded; waiting for start(s) {', '.join(map(str, before))} of "
                        "earlier rounds, as the result is that of the first round with a success, the same as a "
                        f"serial run's. Ctrl-C takes start {result.index}'s result now (an interrupted fit keeps its "
                        "finished starts)")
    return rnd


def _collect_interrupted(executor: Executor, running: set, finished: list, display: FitDisplay) -> None:
    """After Ctrl-C: interrupt the workers of a :class:`~shspec.core.parallel.WorkerPool` and append the best states
    their running starts send back within :data:`INTERRUPT_GRACE` seconds (as many as workers were signalled: a
    start still queued may have taken a freed worker, and is not waited for)."""
    interrupt = getattr(executor, "interrupt_workers", None)
    signalled = interrupt() if running and interrupt is not None else 0
    if signalled:
        display.message(f"interrupted: waiting up to {INTERRUPT_GRACE:g} s for the best states of the running "
                        "starts (Ctrl-C again: do not wait)")
    deadline = time.monotonic() + INTERRUPT_GRACE
    try:
        while running and signalled and time.monotonic() < deadline:
            ended, running = wait(running, timeout=deadline - time.monotonic(), return_when=FIRST_COMPLETED)
            for future in ended:
                signalled -= 1
                try:
                    finished.append(future.result())
                except (KeyboardInterrupt, Exception):  # interrupted before its first state, or its worker died
                    continue
                display.start_done(finished[-1])
    except KeyboardInterrupt:
        display.message("interrupted again: the states of the starts still running are dropped")


@reproducible_call
def fit(target: Target | PreparedFit, model: SpectralModel | None = None, options: FitOptions | None = None, *,
        resume: bool = False, init=None, executor: Executor | None = None) -> FitResult:
    """Fit the parameters of ``model`` to the spectrum of ``target`` from several random starts.

    Parameters
    ----------
    target : Target or PreparedFit
        The target spectrum (k eigenvalues; stages may use fewer; one far from eigenvalues of order 1 is fitted as the
        same surface scaled to them, and the result scaled back: :func:`spectral_scale`); or a fit made ready, such as the plan of
        :func:`shspec.fitting.prepare_fit`, which brings its target, model, options and start (then give only
        ``resume`` and ``executor``).
    model : SpectralModel
        The discretization: its parameters, gauge, levels and regularizer (see :mod:`shspec.spectral_model`).
    options : FitOptions, optional
    resume : bool
        Continue from ``options.checkpoint_path`` if that file exists (it must be a checkpoint of the same fit).
    init : (nparams,) array, optional
        A starting point (e.g. a prior shape, or the previous pass of a recursive fit) for start 0; the other starts
        stay random.  With ``options.schedule`` None a fit from ``init`` is one stage at full resolution.
    executor : concurrent.futures.Executor, optional
        Run the starts on it, and choose the stages' bases there first (a process pool, or a Dask cluster's
        ``Client.get_executor()``; see :func:`shspec.core.parallel.make_executor`); None or a
        :class:`~shspec.core.parallel.SerialExecutor`: here, one after the other.  The results are those of a
        serial run; the module notes say how the race, Ctrl-C and the checkpoints go on an executor, and how many
        starts a process should run at a time.

    Returns
    -------
    FitResult
        Every start run (with ``stop_at_success``: those of the rounds up to the first with a success, without
        the starts that lost the race, :func:`~shspec.inverse.race.race_outcome`), the distinct local solutions
        (best first), and whether Ctrl-C stopped the fit.  On Ctrl-C the
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
    >>> from shspec.inverse import FitOptions, fit
    >>> from shspec.fitting import blob_factor, harmonic_target
    >>> target = harmonic_target(blob_factor(), lmax=12, numeig=40)
    >>> result = fit(target, HarmonicModel(12, 6), FitOptions(starts=1))  # doctest: +SKIP
    """
    if isinstance(target, PreparedFit):
        if model is not None or options is not None or init is not None:
            raise InvalidArgumentError("fit(plan) runs the plan's own model, options and start: give it only resume "
                                       "and executor")
        return target.run(fit, resume=resume, executor=executor)
    if model is None:
        raise InvalidArgumentError("fit(target, model, options) needs the model to fit; or plan the whole fit with "
                                   "shspec.fitting.prepare_fit and run fit(plan)")
    if isinstance(target, Target) and spectral_scale(target.eigenvalues) != 1.0:
        return _fit_scaled(target, model, options, resume=resume, init=init, executor=executor)
    options = check_options(options, FitOptions)
    if isinstance(executor, SerialExecutor):
        executor = None  # the same starts, with the checkpoints inside them that only a run here writes
    problem = FitProblem(model, target, options, init=init, executor=executor)
    fp = fingerprint(options, target, model, problem.init)
    problem, finished, current = _resumed(problem, fp) if resume else (problem, [], None)
    done = {r.index for r in finished}
    display = FitDisplay(options.starts, len(problem.stages), options.progress, done=len(done))
    try:
        interrupted = _run_starts(problem, executor, finished, current, done, fp, display)
    finally:
        display.close()
    return _fit_result(problem, finished, interrupted)


def _resumed(problem: FitProblem, fp: dict) -> tuple:
    """(problem, finished starts, running start or None) to resume from: those of ``options.checkpoint_path``
    if that file exists, else the problem and no starts."""
    path = problem.options.checkpoint_path
    if path is None or not Path(path).exists():
        return problem, [], None
    finished, current, stored = load_checkpoint(path, fp, problem.target)
    # a start the race abandoned runs again: its bound depends on the rounds, and a resumed fit may race in
    # others (FitOptions.race is not part of the fingerprint) or run every start
    finished = [r for r in finished if r.status != ABANDONED]
    # equal to round-off: go on with the checkpoint's own target, as the uninterrupted fit did
    return problem.with_target(stored), finished, current


def _fit_result(problem: FitProblem, finished: list, interrupted: bool) -> FitResult:
    """The fit's result from its finished starts (no start at all: the interrupt goes on)."""
    options = problem.options
    if options.stop_at_success:
        # what a serial run reports, wherever the starts ran and whenever the race reached them
        finished = race_outcome(finished, options.race)
    if not finished:
        raise KeyboardInterrupt
    finished.sort(key=lambda r: r.index)
    solutions = distinct_solutions(finished, problem.model, options.distinct_tol)
    return FitResult(starts=finished, solutions=solutions, target=problem.target, options=options,
                     model=problem.model, seconds=float(sum(r.seconds for r in finished)), interrupted=interrupted)


def _run_starts(problem: FitProblem, executor, finished: list, current, done: set, fp: str,
                display: FitDisplay) -> bool:
    """Run the starts not in ``done`` (on ``executor``, or here one after the other, ``current`` first when a
    checkpoint left one running), appending them to ``finished``, up to the first round with a success with
    ``stop_at_success`` (a start after a success of its round runs only while it has done less work);
    returns whether an interrupt stopped them."""
    options, target = problem.options, problem.target

    def checkpoint(progress):
        save_checkpoint(options.checkpoint_path, fp, finished, progress, target)

    def stopped(i: int) -> bool:  # a start of a round before i's succeeded, and the fit stops there
        return options.stop_at_success and won_round(finished, options.race) < race_round(i, options.race)

    interrupted = False
    if executor is not None:
        pending = [i for i in range(options.starts) if i not in done and not stopped(i)]
        interrupted = _run_parallel(problem, pending, executor, finished,
                                    checkpoint if options.checkpoint_path else None, display, current)
        if interrupted:
            display.message("interrupted: the finished starts and the best states of the running ones are kept")
    else:
        for i in range(options.starts):
            if i in done:
                continue
            if stopped(i):
                display.message("a start of an earlier round succeeded: the fit stops there (stop_at_success)")
                break
            # the whole step is guarded: an interrupt (Ctrl-C, SIGTERM) between two starts keeps the finished ones too
            try:
                if current is None or current.index != i:
                    current = StartProgress(i, 0, problem.initial(np.random.default_rng([options.seed, i]), i),
                                            None)
                current.display = display
                if options.stop_at_success:
                    current.bound = RaceBound(i, best_success(finished, i, options.race))
                finished.append(run_start(problem, current, checkpoint if options.checkpoint_path else None))
                display.start_done(finished[-1])
                current = None
                if options.checkpoint_path and options.checkpoint_every:
                    checkpoint(None)
            except KeyboardInterrupt:
                interrupted = True
                if options.checkpoint_path:
                    save_checkpoint(options.checkpoint_path, fp, finished, current, target)
                running = current is not None and current.index not in {r.index for r in finished}
                if running and current.params is not None:
                    finished.append(current.result("interrupted", current.seconds,
                                                   current.succeeded(problem, final=True)))
                display.message("interrupted: the best state so far is kept")
                break
    return interrupted
