"""Running one start through the stages of a schedule, with checkpoints, the hops and a clean Ctrl-C."""

from __future__ import annotations

import time

import numpy as np

from ..errors import NotPositiveError
from ..spectral_model import SpectralModel
from .hops import basin_hop, orient_new_block
from .optimize import make_optimizer
from .problem import BUDGET, BudgetSpent, FitProblem, StartProgress
from .race import ABANDONED, RaceLost
from .results import StartResult

__all__ = ["run_start"]


def run_start(problem: FitProblem, progress: StartProgress, checkpoint=None) -> StartResult:
    """Run (or continue) one start through the remaining stages.

    Parameters
    ----------
    problem : FitProblem
    progress : StartProgress
        A fresh start (``state`` None, ``stage`` 0, ``base`` the random start) or one loaded from a checkpoint.
        It is updated after every iteration, so that a caller catching ``KeyboardInterrupt`` holds the best state.
    checkpoint : callable, optional
        ``checkpoint(progress)``, called every ``options.checkpoint_every`` iterations.

    Returns
    -------
    StartResult
        Status "abandoned" when ``progress.bound`` says that a start of its round succeeded after less work
        (:mod:`~shspec.inverse.race`).
    """
    t0 = time.perf_counter() - progress.seconds
    progress.budget = problem.work_budget
    try:
        return _run(problem, progress, checkpoint, t0)
    except RaceLost as lost:
        progress.say(problem.options, f"  start {progress.index} abandoned: {lost}")
        return progress.result(ABANDONED, time.perf_counter() - t0, False)
    except BudgetSpent as spent:
        progress.say(problem.options, f"  start {progress.index} ended: {spent}, max rel. residual "
                                      f"{progress.relative_residual:.3e}")
        # a state of an earlier stage matches fewer eigenvalues than the target has: no success
        last = progress.stage >= len(problem.stages) - 1
        return progress.result(BUDGET, time.perf_counter() - t0, last and progress.succeeded(problem, final=True))
    finally:
        # one clock per start: an interrupt anywhere, in the hops too, leaves its time up to date for the result
        progress.seconds = time.perf_counter() - t0


def _run(problem: FitProblem, progress: StartProgress, checkpoint, t0: float) -> StartResult:
    """The body of :func:`run_start`, its clock started at ``t0`` (:func:`time.perf_counter`)."""
    params = progress.base
    last = len(problem.stages) - 1
    # the hops after the last stage; after a search stage (FitProblem.search) only where its basis did not hold
    hop_at_end = problem.search is None or progress.stage > last
    if progress.stage > last:
        _restore_end_of_stages(problem, progress, last)
    for s in range(progress.stage, len(problem.stages)):
        resumed = progress.state is not None and s == progress.stage
        if not resumed:
            _enter_stage(problem, progress, s, params)
        if problem.search is not None and s == problem.search + 1:  # decided from the stage's start alone: the
            hop_at_end = not problem.search_basis_holds(progress.base)  # same in a resumed run
        stage = _stage_optimizer(problem, progress, s, resumed)
        if stage is None:
            return _outcome(problem, progress, t0)
        obj, optimizer = stage
        _iterate(problem, progress, s, obj, optimizer, resumed, checkpoint, t0)
        _end_stage(problem, progress, s, obj, optimizer)
        params = progress.params
    if problem.options.basin_hops and hop_at_end and not progress.succeeded(problem):
        _final_hops(problem, progress, checkpoint, last)
    return _outcome(problem, progress, t0)


def _outcome(problem: FitProblem, progress: StartProgress, t0: float) -> StartResult:
    """The start's result as it stands, its time counted from ``t0``."""
    seconds = time.perf_counter() - t0
    return progress.result(progress.status, seconds, progress.succeeded(problem, final=True))


def _restore_end_of_stages(problem: FitProblem, progress: StartProgress, last: int) -> None:
    """Resumed during the final basin hops: restore the state the stages ended in."""
    obj = problem.objective(last, progress.base)
    ev = obj.evaluate(obj.initial())
    progress.params, progress.eigenvalues = progress.base, ev.eigenvalues
    progress.energy, progress.relative_residual = ev.energy, ev.relative_residual
    progress.work = progress.stage_work
    progress.mark()


def _enter_stage(problem: FitProblem, progress: StartProgress, s: int, params: np.ndarray) -> None:
    """Start stage s from ``params`` (the state the previous stage ended in), or, where a resume stopped, again."""
    if s == progress.stage and progress.history:
        # stopped before the stage's first iteration or in the hops after its last: run it again from its
        # start, which already holds its perturbation, and forget what it had recorded
        progress.history = [row for row in progress.history if row[0] < s]
        progress.work = progress.stage_work
    else:
        rng = np.random.default_rng([problem.options.seed, progress.index, s + 1])
        progress.stage, progress.base, progress.stage_work = s, problem.enter_stage(s, params, rng), progress.work


def _stage_optimizer(problem: FitProblem, progress: StartProgress, s: int, resumed: bool):
    """Stage s's objective and optimizer (from ``progress.state`` if ``resumed``); None, with the start's status
    and its line, when the stage's start is no metric."""
    try:
        obj = problem.objective(s, progress.base)
        return obj, make_optimizer(problem.optimizer, obj, obj.initial(), problem.options,
                                   progress.state if resumed else None)
    except NotPositiveError as exc:
        if progress.params is None:  # the start itself is no metric: nothing to keep
            raise
        # positivity never ends a fit: the start ends at the best state it reached, and says why
        progress.status = "stopped: the start of the next stage is not a metric"
        progress.say(problem.options, f"  start {progress.index} stage {s}: {progress.status} ({exc}); keeping the "
                                      f"state of stage {s - 1}")
        return None


def _record(problem: FitProblem, progress: StartProgress, s: int, obj, optimizer, t0: float) -> None:
    """Note the optimizer's present state of stage s in ``progress``, for a Ctrl-C to keep."""
    progress.seconds = time.perf_counter() - t0
    progress.params = problem.merge(s, progress.base, obj, optimizer.x)
    progress.energy, progress.relative_residual = optimizer.ev.energy, optimizer.ev.relative_residual
    progress.eigenvalues = optimizer.ev.eigenvalues


def _iterate(problem: FitProblem, progress: StartProgress, s: int, obj, optimizer, resumed: bool, checkpoint,
             t0: float) -> None:
    """Step stage s's optimizer until it stops or reaches the stage's iteration limit, with the checkpoints."""
    opt = problem.options
    max_iter = problem.stages[s].max_iter or opt.max_iter
    if not resumed:
        progress.history.append((s, optimizer.ev.energy, optimizer.ev.relative_residual))
    _record(problem, progress, s, obj, optimizer, t0)
    progress.mark()
    while optimizer.status is None and optimizer.iteration < max_iter:
        optimizer.step()
        progress.state = optimizer.state()
        progress.history.append((s, optimizer.ev.energy, optimizer.ev.relative_residual))
        _record(problem, progress, s, obj, optimizer, t0)
        progress.add_work(obj.cost)
        if optimizer.status is None:
            # not after the step that stopped the optimizer: its state does not say it stopped, and a resume
            # from it would step on; from the state before, the resume takes that step again, and stops
            progress.mark()
        if progress.display is not None:
            progress.display.iteration(progress.index, s, optimizer.iteration, optimizer.ev.relative_residual)
        if checkpoint is not None and opt.checkpoint_every and (len(progress.history) - 1) % opt.checkpoint_every == 0:
            checkpoint(progress)


def _end_stage(problem: FitProblem, progress: StartProgress, s: int, obj, optimizer) -> None:
    """After stage s's iterations: its status, the orientation of a new block, its line, and its own hops."""
    opt = problem.options
    progress.status = optimizer.status or "max_iter"
    progress.state = None
    if opt.orient_blocks and _raises_level(problem, s) and not progress.succeeded(problem):
        orient_new_block(problem, progress, s)
    basis = "" if problem.bases[s] is None else f", basis degree {problem.bases[s]}"
    parity = "odd degrees at 0, " if problem.stages[s].even else ""
    progress.say(opt, f"  start {progress.index} stage {s} ({_level_text(obj.model, problem.level(s))}{parity}"
                      f"{obj.target.size} eigenvalues{basis}): {progress.status} after {optimizer.iteration} "
                      f"iterations, max rel. residual {optimizer.ev.relative_residual:.3e}")
    if progress.display is not None:
        progress.display.stage_done()
    if (s < len(problem.stages) - 1 and problem.stages[s].hops and opt.basin_hops
            and not progress.succeeded(problem)):
        if s == problem.search and not problem.search_basis_holds(progress.params):
            progress.say(opt, f"  start {progress.index} stage {s}: its basis does not hold at this rho; the "
                              "hops follow the polish on the model's own")
        else:
            # not checkpointed apart: a resume inside these hops runs stage s again, which repeats them exactly
            progress.status = basin_hop(problem, progress, progress.status, s)


def _final_hops(problem: FitProblem, progress: StartProgress, checkpoint, last: int) -> None:
    """The basin hops after the last stage (``progress.stage`` past it while they run)."""
    if progress.stage <= last:
        # checkpoint the end of the stages, so that a resume repeats only the (deterministic) hops
        progress.stage, progress.base, progress.stage_work = last + 1, progress.params, progress.work
        progress.mark()
        if checkpoint is not None and problem.options.checkpoint_every:
            checkpoint(progress)
    progress.status = basin_hop(problem, progress, progress.status, last)


def _raises_level(problem: FitProblem, s: int) -> bool:
    """Whether stage s raises the level of stage s − 1, i.e. fits a block no earlier stage had."""
    levels = problem.model.levels()
    if not levels or s == 0:
        return False
    top = levels[-1]
    old = top if problem.level(s - 1) is None else problem.level(s - 1)
    new = top if problem.level(s) is None else problem.level(s)
    return new > old


def _level_text(model: SpectralModel, level: int | None) -> str:
    if not model.levels():
        return ""
    return f"degree {max(model.levels()) if level is None else level}, "

