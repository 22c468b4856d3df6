"""Basin hops: leaving a local minimum of a stage by the model's escape moves, each screened by a short refit.

The moves keep the model's invariant (harmonic models: the per-degree power of ρ): half-turns and sign flips of
single degree blocks, and every block through the octahedral group (the grid moves).  Everything here is
deterministic, so that a resumed fit repeats the hops exactly.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import NotPositiveError
from ..spectral_model import SpectralModel
from .optimize import make_optimizer
from .problem import FitProblem, StartProgress

__all__ = ["hop_once", "orient_new_block", "basin_hop", "grid_moves"]

#: A hop's screening refit goes on past ``hop_iter`` while its energy fell by this share over the last
#: _FALLING_SPAN iterations: in failed degree-10 states the moves that fall back into the state's own minimum slow
#: down just above its energy, while the moves that leave it were still falling steeply at 15 iterations and,
#: continued, crossed it at 18-20 (FitOptions.hop_extend; measured: the benchmarks page of the docs).
_FALLING = 0.1


_FALLING_SPAN = 3


def hop_once(problem: FitProblem, progress: StartProgress, s: int, moves: list, status: str) -> tuple[bool, str]:
    """Try ``moves`` (parameter vectors) from the state in ``progress`` with the objective of stage s: the
    ``hop_tries`` of lowest energy before any refit (one eigensolve each), in that order, each refitted for
    ``hop_iter`` iterations (LM without the geodesic acceleration), and on while it is still above the current
    energy but falling fast (by :data:`_FALLING` over the last :data:`_FALLING_SPAN` iterations), up to
    ``hop_extend`` iterations in all; the first that ends below the current energy is refitted to convergence with
    the options as given and accepted into ``progress``.  Deterministic.

    Returns (accepted, status of the last refit or ``status``)."""
    opt = problem.options
    # the short screening refits gain nothing measurable from the acceleration's extra solve (FitOptions.hop_iter)
    screening = replace(opt, lm_acceleration=False)

    def run(params, iters, options, extend=0):
        try:
            obj = problem.objective(s, params)
            optimizer = make_optimizer(problem.optimizer, obj, obj.initial(), options)
        except NotPositiveError:  # a move that leaves ρ non-positive
            return None
        energies, hist = [optimizer.ev.energy], []
        while optimizer.status is None and (optimizer.iteration < iters or (
                optimizer.iteration < extend and progress.energy <= energies[-1]
                <= (1.0 - _FALLING) * energies[-1 - min(_FALLING_SPAN, len(energies) - 1)])):
            optimizer.step()
            progress.add_work(obj.cost)
            energies.append(optimizer.ev.energy)
            hist.append((s, optimizer.ev.energy, optimizer.ev.relative_residual))
        return optimizer, obj, hist

    def energy(q):
        try:
            obj = problem.objective(s, q)
            progress.add_work(obj.cost)
            return obj.values(obj.initial()).energy
        except NotPositiveError:
            return np.inf

    energies = [energy(q) for q in moves]
    for k in np.argsort(energies, kind="stable")[:opt.hop_tries]:
        if not np.isfinite(energies[k]):
            break
        out = run(moves[k], opt.hop_iter, screening, opt.hop_extend)
        if out is None or out[0].ev.energy >= progress.energy:
            continue
        optimizer, obj, hist = out
        q = problem.merge(s, moves[k], obj, optimizer.x)
        full = run(q, problem.stages[s].max_iter or opt.max_iter, opt)
        optimizer, obj, hist2 = full
        progress.history.extend(hist + hist2)
        progress.params = problem.merge(s, q, obj, optimizer.x)
        progress.energy, progress.relative_residual = optimizer.ev.energy, optimizer.ev.relative_residual
        progress.eigenvalues = optimizer.ev.eigenvalues
        return True, optimizer.status or "max_iter"
    return False, status


def orient_new_block(problem: FitProblem, progress: StartProgress, s: int) -> None:
    """After stage s raised the level: try the orientations of the newest block (the model's moves with
    ``newest=True``: rotations of an octahedral grid and, for odd degrees, their negatives) relative to the blocks
    fitted before, keeping the best that lowers the energy (see :attr:`FitOptions.orient_blocks`)."""
    moves = problem.stage_moves(s, progress.params,
                                problem.model.escape_moves(progress.params, problem.level(s), newest=True))
    accepted, status = hop_once(problem, progress, s, moves, progress.status)
    if accepted:
        progress.status = status
    progress.say(problem.options, f"  start {progress.index} stage {s}: {len(moves)} orientations of the new block, "
                 + (f"one accepted, max rel. residual {progress.relative_residual:.3e}" if accepted
                    else "none lowers the energy"))


def basin_hop(problem: FitProblem, progress: StartProgress, status: str, s: int) -> str:
    """Leave a local minimum of stage s by the model's escape moves (see :attr:`FitOptions.basin_hops`).

    The moves keep the model's invariant (harmonic models: the per-degree power).  Each hop is :func:`hop_once` on
    stage s with the cheap moves (half-turns and sign flips of single degree blocks), and, when none of them
    lowers the energy and ``hop_grid`` is set, with the grid moves (every block through the octahedral group).
    The hops stop at success, after ``basin_hops`` accepted moves, or when no move lowers the energy.
    Deterministic.  Models without moves make this a no-op.
    """
    opt = problem.options
    level = problem.level(s)
    where = "" if s == len(problem.stages) - 1 else f"stage {s} "
    for hop in range(opt.basin_hops):
        moves = problem.stage_moves(s, progress.params, problem.model.escape_moves(progress.params, level))
        accepted, status = hop_once(problem, progress, s, moves, status)
        tried = f"{len(moves)} moves"
        if not accepted and opt.hop_grid:
            grid = problem.stage_moves(s, progress.params, grid_moves(problem.model, progress.params, level))
            if grid:
                accepted, status = hop_once(problem, progress, s, grid, status)
                tried += f", then {min(len(grid), opt.hop_tries)} of {len(grid)} grid moves"
        progress.say(opt, f"  start {progress.index} {where}basin hop {hop + 1}: "
                     + (f"a move was accepted, {status}, max rel. residual {progress.relative_residual:.3e}"
                        if accepted else f"none of {tried} lowers the energy"))
        if not accepted or progress.succeeded(problem):
            break
    return status


def grid_moves(model: SpectralModel, params: np.ndarray, level: int | None) -> list:
    """The moves of every level up to ``level`` taken alone (``escape_moves(..., newest=True)`` per level)."""
    levels = model.levels()
    top = levels[-1] if level is None and levels else level
    return [q for lv in levels if lv <= top for q in model.escape_moves(params, lv, newest=True)]

