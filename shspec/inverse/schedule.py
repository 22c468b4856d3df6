"""Running one start through the stages of a schedule, with checkpoints and a clean Ctrl-C.

A :class:`FitProblem` holds a model, a target and the options, and builds the objective of each stage from what the
model says of itself (:class:`~shspec.model.SpectralModel`): the level a stage restricts it to, the free parameters,
the transform of the variables, the random start and the perturbation a stage adds when it raises the level.
Every random choice of start i is drawn from ``default_rng([seed, i])`` and, for the perturbation a stage adds to
its new level, ``default_rng([seed, i, stage + 1])``: a run is reproducible, and a resumed run draws the same numbers.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..checks import check_int, finite_array
from ..errors import InvalidArgumentError, NotPositiveError
from ..model import SpectralModel
from .energy import Objective, eigenvalue_weights
from .optimize import make_optimizer
from .options import FitOptions, Stage, StartResult, fits_area
from .parametrization import Parametrization
from ..targets import Target

__all__ = ["FitProblem", "run_start", "StartProgress", "numeig_ramp", "degree_ramp", "default_schedule",
           "default_hop_degree", "DEFAULT_STAGE_MAX_ITER", "DEFAULT_HOP_DEGREE"]

#: Iterations of every stage but the last in the default degree ramp (see :func:`degree_ramp`).
DEFAULT_STAGE_MAX_ITER = 40

#: The degree whose stage of the default degree ramp hops (see :func:`degree_ramp`), in fits of higher degree.
#: Degree 6 is where the hops were measured to succeed on their own (the blob at La 6: 8 of 8 starts), and its
#: stage (64 eigenvalues) is small: with it the blob at La 15 (K 704) and a random ρ of degree 10 (K 300) were
#: recovered from 4 of 4 starts each, where without it a blob start ended 3.6 % off and the degree-10 fit recovered
#: 1 to 3 of the same four (benchmarks/results/bench_inverse.json, ``goal_blob`` and ``goal_degree10``).
DEFAULT_HOP_DEGREE = 6

#: Size of the perturbation given to the parameters a stage adds, relative to the one of a random start: enough to
#: leave the parity saddle, small enough not to undo what the earlier stages found.
_NEW_DEGREE_SCALE = 0.05

#: A hop's screening refit goes on past ``hop_iter`` while its energy fell by this share over the last
#: _FALLING_SPAN iterations: in failed degree-10 states the moves that fall back into the state's own minimum slow
#: down just above its energy, while the moves that leave it were still falling steeply at 15 iterations
#: (benchmarks/bench_hop_screening.py) and, continued in a probe, crossed it at 18-20 (FitOptions.hop_extend).
_FALLING = 0.1
_FALLING_SPAN = 3


def numeig_ramp(numeig: int, lmax_factor: int | None = None, first: int = 16) -> tuple[Stage, ...]:
    """A schedule that matches more and more eigenvalues: k = 16, 36, 64, ... ((2j)² up to ``numeig``), then all.

    Raising the number of matched eigenvalues in steps that end at whole sphere clusters ((l+1)² eigenvalues)
    was measured to escape the local minima of a direct fit far more often (benchmarks/bench_inverse.py): the low
    eigenvalues fix the coarse shape first.

    Parameters
    ----------
    numeig : int
        Eigenvalues of the last stage (≥ 2).
    lmax_factor : int, optional
        Degree of every stage (harmonic fits); None: the model's.
    first : int
        Eigenvalues of the first stage.
    """
    numeig, first = check_int(numeig, "numeig", minimum=2), check_int(first, "first", minimum=2)
    ks, j = [], int(np.ceil(np.sqrt(first)))
    while j * j < numeig:
        ks.append(j * j)
        j += 2
    return tuple(Stage(lmax_factor=lmax_factor, numeig=k) for k in [*ks, int(numeig)])


def degree_ramp(numeig: int, lmax_factor: int, stage_max_iter: int | None = None,
                hop_degree: int | None = None) -> tuple[Stage, ...]:
    """A schedule that raises the factor's degree and the eigenvalue count together, then matches more eigenvalues.

    Stage l = 2, ..., La fits degree l to (l + 2)² eigenvalues (16, 25, 36, ...), each stage overdetermined; then
    La is kept and the count rises through the even squares (2j)² above (La + 2)², then to ``numeig``.  For
    La = 6 and 120 eigenvalues: 2:16, 3:25, 4:36, 5:49, 6:64, 6:100, 6:120.  On the blob (Lb = 20, La = 6, 120
    eigenvalues, 8 starts of seed 0, LM, max_iter 150, one BLAS thread) it succeeded as often as :func:`numeig_ramp`
    (2 of 8) at about 40 % of its CPU time per start (median 16 s against 37–41 s for the ramp's failed starts);
    with ``basin_hops=4`` it succeeded on 7 of 8 (median 34 s CPU per start).  Its failed starts mostly share one
    local minimum (6 of 8 without hops), which the block moves of the basin hops leave.

    Parameters
    ----------
    numeig : int
        Eigenvalues of the last stage.
    lmax_factor : int
        Degree La of the last stages (≥ 2).
    stage_max_iter : int, optional
        Iterations of every stage but the last (None: :attr:`FitOptions.max_iter`).  Their optima are not the truth
        cut to their degree or eigenvalue count (the higher degrees move the low eigenvalues too), so converging
        them buys little.  At degree 10 (Lb 24, K = 300) with 4 basin hops, capping them at 40 iterations gave 2
        of 12 successes at a median 116 s per start (benchmarks/results/bench_global_search.json), where the
        uncapped ramp had given 0 of 4 at a median 163 s (``goal_degree10`` in bench_inverse.json of commit
        c0e95a5); on the blob (La 6, K 120) 7 of 8 either way.
    hop_degree : int, optional
        The stage that raises the degree to this one runs to convergence (``FitOptions.max_iter``) and then the
        basin hops (:attr:`Stage.hops`): the global search on the low degrees while their stage is small, before
        the higher degrees are added.  None: hops after the last stage only.  No stage hops if that stage would
        match ``numeig`` eigenvalues or more.  With ``hop_degree=6``, the default of fits above degree 6
        (:data:`DEFAULT_HOP_DEGREE`), the blob at La 15 with K = 704 found the truth at its degree-6 stage in every
        start and went on to ρ within 2e-9; without it a start ended at an error of 3.6 %.  The hops cost time
        where the stage cannot reach a zero residual: with R = 1e-6 in the study's setting (K = 256) a start took
        570-895 s instead of 126 s, for the same result.
    """
    numeig, lmax_factor = check_int(numeig, "numeig", minimum=2), check_int(lmax_factor, "lmax_factor", minimum=2)
    stage_max_iter = check_int(stage_max_iter, "stage_max_iter", allow_none=True, minimum=1)
    hop_degree = check_int(hop_degree, "hop_degree", allow_none=True, minimum=2)
    stages = [Stage(lmax_factor=l, numeig=(l + 2) ** 2, max_iter=None if l == hop_degree else stage_max_iter,
                    hops=l == hop_degree)
              for l in range(2, int(lmax_factor) + 1) if (l + 2) ** 2 < numeig]
    j = int(lmax_factor) + 3
    j += j % 2
    while j * j < numeig:
        stages.append(Stage(lmax_factor=int(lmax_factor), numeig=j * j, max_iter=stage_max_iter))
        j += 2
    stages.append(Stage(lmax_factor=int(lmax_factor), numeig=int(numeig)))
    return tuple(stages)


def default_schedule(model: SpectralModel, numeig: int) -> tuple[Stage, ...]:
    """The schedule a fit runs when its options name none: :func:`degree_ramp` over the model's levels (harmonic
    models: the factor's degree), :func:`numeig_ramp` for models without levels (meshes).

    The degree ramp with 4 basin hops made 7 of 8 blob starts succeed, the numeig ramp 2 of 8 and one stage none
    (benchmarks/results/bench_inverse.json).  Its stages but the last are capped at
    :data:`DEFAULT_STAGE_MAX_ITER` iterations: the same 7 of 8 on the blob in 155 s against 171 s for the 8 starts,
    and at degree 10 (K = 300) 2 of 12 with 4 hops; with the default hops (12, and the grid moves) 8 of 8 on the
    blob and 6 of 8 at degree 10 with every stage on the model's basis, 8 of 8 and 4 of 8 with the stages' own
    bases (:attr:`FitOptions.stage_basis_tol`; benchmarks/results/bench_global_search.json).
    """
    levels = model.levels()
    if not levels:
        return numeig_ramp(numeig)
    return degree_ramp(numeig, levels[-1], stage_max_iter=DEFAULT_STAGE_MAX_ITER,
                       hop_degree=default_hop_degree(levels[-1]))


def default_hop_degree(lmax_factor: int) -> int | None:
    """The degree whose stage hops in the default degree ramp of a fit of degree ``lmax_factor``
    (:data:`DEFAULT_HOP_DEGREE`, or None when the fit's own degree is not above it: its last stage hops anyway)."""
    lmax_factor = check_int(lmax_factor, "lmax_factor", minimum=0)
    return DEFAULT_HOP_DEGREE if lmax_factor > DEFAULT_HOP_DEGREE else None


class FitProblem:
    """A model, a target and the options, and the objective of each stage.

    Parameters
    ----------
    model : SpectralModel
    target : Target
    options : FitOptions
    init : (nparams,) array, optional
        Starting point of start 0 (the other starts stay random); with ``options.schedule`` None the fit is then one
        stage at full resolution.

    Raises
    ------
    InvalidArgumentError
        If a stage asks for more eigenvalues than the target has or for a level the model does not have, or the
        area is to be fixed but is unknown.
    BandLimitError
        If a stage's degree exceeds the model's.
    """

    def __init__(self, model: SpectralModel, target: Target, options: FitOptions, *, init=None):
        if not isinstance(model, SpectralModel):
            raise InvalidArgumentError(f"model must be a SpectralModel, got {type(model).__name__}")
        if not isinstance(target, Target):
            raise InvalidArgumentError(f"target must be a Target, got {type(target).__name__}")
        if not isinstance(options, FitOptions):
            raise InvalidArgumentError(f"options must be FitOptions, got {type(options).__name__}")
        self.model, self.target, self.options = model, target, options
        self.optimizer = options.optimizer or model.default_optimizer
        if init is not None:
            init = finite_array(init, f"a starting point ({model.nparams} parameters of {model.describe()})",
                                (model.nparams,)).copy()
        self.init = init
        if options.schedule is not None:
            schedule = options.schedule
        else:
            # a given start already holds the coarse shape: one stage at full resolution, not a ramp that would
            # truncate it to the first level
            schedule = (Stage(),) if init is not None else default_schedule(model, target.numeig)
        self.stages = schedule or (Stage(),)
        for st in self.stages:
            if st.numeig is not None and st.numeig > target.numeig:
                raise InvalidArgumentError(f"a stage matches {st.numeig} eigenvalues; the target has {target.numeig}")
            model.restrict(st.lmax_factor)  # raises for a level the model does not have
        if options.area == "fixed" and target.area is None and target.numeig < 4:
            raise InvalidArgumentError("a fixed area needs a known area or a spectrum to estimate it from")
        self.fit_area = fits_area(options, target)
        self.area = target.area_estimate()
        # chosen here, once, at a reference: a start's path may then not depend on where the fit runs
        tol = options.stage_basis_tol
        # a stage that hops tests success at success_tol: on a basis only good to 1e-5 the truth itself would fail
        # it (the blob's 6:64 stage on Lb' = 14 ends every start at 1.5e-6, and its hops go on)
        self.bases = [None if tol is None or s == len(self.stages) - 1
                      else model.stage_basis(st.lmax_factor, st.numeig or target.numeig,
                                             min(tol, options.success_tol) if st.hops else tol)
                      for s, st in enumerate(self.stages)]
        if options.progress and any(b is not None for b in self.bases):
            print("stage bases (degree:eigenvalues -> basis degree): " + ", ".join(
                f"{st.lmax_factor}:{st.numeig or target.numeig} -> {b}" for st, b in zip(self.stages, self.bases)
                if b is not None), file=sys.stderr, flush=True)

    def level(self, s: int) -> int | None:
        """The level (harmonic models: the factor's degree) of stage s, None for the model's own."""
        return self.stages[s].lmax_factor

    def initial(self, rng: np.random.Generator, index: int = 0) -> np.ndarray:
        """Start ``index``: the given starting point for start 0 if there is one, otherwise a random
        symmetry-broken start (nparams,) of the model at the first stage's level, with the area."""
        if index == 0 and self.init is not None:
            return self.init.copy()
        return self.model.random_start(rng, self.options.start_amplitude, self.area, self.level(0))

    def enter_stage(self, s: int, params: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Parameters at the start of stage s: what its level adds gets a small random perturbation."""
        if s == 0:
            return params
        return self.model.enter_level(params, self.level(s - 1), self.level(s), rng,
                                      _NEW_DEGREE_SCALE * self.options.start_amplitude)

    def objective(self, s: int, params: np.ndarray) -> Objective:
        """The energy of stage s with the fixed parameters taken from ``params`` (nparams,)."""
        st = self.stages[s]
        k = self.target.numeig if st.numeig is None else st.numeig
        lam = self.target.eigenvalues[:k]
        sub = self.model.restrict(self.level(s), self.bases[s])
        par = Parametrization.at(self.model.to_level(params, self.level(s)), sub.free_parameters(self.fit_area),
                                 sub.transform)
        return Objective(sub, lam, eigenvalue_weights(lam, self.options.weights), par, self.options.reg)

    def merge(self, s: int, params: np.ndarray, objective: Objective, x) -> np.ndarray:
        """Full parameters after stage s: the stage's parameters written back into ``params``."""
        return self.model.from_level(objective.params(x), params, self.level(s))


@dataclass
class StartProgress:
    """Where a start is: enough to checkpoint it or to report it after Ctrl-C.

    Attributes
    ----------
    index, stage : int
        Start and stage; ``stage`` = the number of stages once they are all done and the basin hops run.
    base : (nparams,) array
        Full parameters at the stage's start (after its perturbation).
    state : dict or None
        The optimizer's state after its last completed iteration.
    history : list of (stage, energy, relative residual)
    seconds : float
        Time spent in this start before the current run (resumed starts).
    """

    index: int
    stage: int
    base: np.ndarray
    state: dict | None
    history: list = field(default_factory=list)
    seconds: float = 0.0
    params: np.ndarray | None = None
    energy: float = np.inf
    relative_residual: float = np.inf
    eigenvalues: np.ndarray | None = None
    status: str = "max_iter"

    def result(self, status: str, seconds: float, success_tol: float) -> StartResult:
        """The start's outcome so far (its best state: the optimizers only accept descent)."""
        return StartResult(index=self.index, params=self.params.copy(), energy=float(self.energy),
                           relative_residual=float(self.relative_residual),
                           iterations=max(len(self.history) - 1, 0), seconds=seconds, status=status,
                           history=np.array(self.history, dtype=float).reshape(-1, 3),
                           eigenvalues=np.array(self.eigenvalues), success=bool(self.relative_residual <= success_tol))


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
    """
    opt = problem.options
    t0 = time.perf_counter() - progress.seconds
    rng_seed = (opt.seed, progress.index)
    params = progress.base
    last = len(problem.stages) - 1
    if progress.stage > last:  # resumed during the basin hops: restore the state the stages ended in
        obj = problem.objective(last, progress.base)
        ev = obj.evaluate(obj.initial())
        progress.params, progress.eigenvalues = progress.base, ev.eigenvalues
        progress.energy, progress.relative_residual = ev.energy, ev.relative_residual
    for s in range(progress.stage, len(problem.stages)):
        resumed = progress.state is not None and s == progress.stage
        if not resumed and s == progress.stage and progress.history:
            # stopped before the stage's first iteration or in the hops after its last: run it again from its
            # start, which already holds its perturbation, and forget what it had recorded
            params = progress.base
            progress.history = [row for row in progress.history if row[0] < s]
        elif not resumed:
            params = problem.enter_stage(s, params, np.random.default_rng([*rng_seed, s + 1]))
            progress.stage, progress.base = s, params
        obj = problem.objective(s, progress.base)
        optimizer = make_optimizer(problem.optimizer, obj, obj.initial(), opt, progress.state if resumed else None)
        max_iter = problem.stages[s].max_iter or opt.max_iter

        def record():
            progress.seconds = time.perf_counter() - t0
            progress.params = problem.merge(s, progress.base, obj, optimizer.x)
            progress.energy, progress.relative_residual = optimizer.ev.energy, optimizer.ev.relative_residual
            progress.eigenvalues = optimizer.ev.eigenvalues

        if not resumed:
            progress.history.append((s, optimizer.ev.energy, optimizer.ev.relative_residual))
        record()
        while optimizer.status is None and optimizer.iteration < max_iter:
            optimizer.step()
            progress.state = optimizer.state()
            progress.history.append((s, optimizer.ev.energy, optimizer.ev.relative_residual))
            record()
            if opt.progress and sys.stderr.isatty():
                print(f"\r  start {progress.index} stage {s} it {optimizer.iteration:4d}  E = {optimizer.ev.energy:.3e}"
                      f"  max rel. residual = {optimizer.ev.relative_residual:.3e}   ", end="", file=sys.stderr,
                      flush=True)
            if checkpoint is not None and opt.checkpoint_every and (len(progress.history) - 1) % opt.checkpoint_every == 0:
                checkpoint(progress)
        progress.status = optimizer.status or "max_iter"
        progress.state = None
        if opt.orient_blocks and _raises_level(problem, s) and progress.relative_residual > opt.success_tol:
            _orient_new_block(problem, progress, s)
        if opt.progress:
            basis = "" if problem.bases[s] is None else f", basis degree {problem.bases[s]}"
            print(f"\r  start {progress.index} stage {s} ({_level_text(obj.model, problem.level(s))}{obj.target.size} "
                  f"eigenvalues{basis}): "
                  f"{progress.status} after {optimizer.iteration} iterations, max rel. residual "
                  f"{optimizer.ev.relative_residual:.3e}", file=sys.stderr, flush=True)
        if (s < last and problem.stages[s].hops and opt.basin_hops
                and progress.relative_residual > opt.success_tol):
            # not checkpointed apart: a resume inside these hops runs stage s again, which repeats them exactly
            progress.status = _basin_hop(problem, progress, progress.status, s)
        params = progress.params
    if opt.basin_hops and progress.relative_residual > opt.success_tol:
        if progress.stage <= last:
            # checkpoint the end of the stages, so that a resume repeats only the (deterministic) hops
            progress.stage, progress.base = last + 1, progress.params
            if checkpoint is not None and opt.checkpoint_every:
                checkpoint(progress)
        progress.status = _basin_hop(problem, progress, progress.status, last)
    return progress.result(progress.status, time.perf_counter() - t0, opt.success_tol)


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


def _hop_once(problem: FitProblem, progress: StartProgress, s: int, moves: list, status: str) -> tuple[bool, str]:
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
            energies.append(optimizer.ev.energy)
            hist.append((s, optimizer.ev.energy, optimizer.ev.relative_residual))
        return optimizer, obj, hist

    def energy(q):
        try:
            obj = problem.objective(s, q)
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


def _orient_new_block(problem: FitProblem, progress: StartProgress, s: int) -> None:
    """After stage s raised the level: try the orientations of the newest block (the model's moves with
    ``newest=True``: rotations of an octahedral grid and, for odd degrees, their negatives) relative to the blocks
    fitted before, keeping the best that lowers the energy (see :attr:`FitOptions.orient_blocks`)."""
    moves = problem.model.escape_moves(progress.params, problem.level(s), newest=True)
    accepted, status = _hop_once(problem, progress, s, moves, progress.status)
    if accepted:
        progress.status = status
    if problem.options.progress:
        print(f"  start {progress.index} stage {s}: {len(moves)} orientations of the new block, "
              + (f"one accepted, max rel. residual {progress.relative_residual:.3e}" if accepted
                 else "none lowers the energy"), file=sys.stderr, flush=True)


def _basin_hop(problem: FitProblem, progress: StartProgress, status: str, s: int) -> str:
    """Leave a local minimum of stage s by the model's escape moves (see :attr:`FitOptions.basin_hops`).

    The moves keep the model's invariant (harmonic models: the per-degree power).  Each hop is :func:`_hop_once` on
    stage s with the cheap moves (half-turns and sign flips of single degree blocks), and, when none of them
    lowers the energy and ``hop_grid`` is set, with the grid moves (every block through the octahedral group).
    The hops stop at success, after ``basin_hops`` accepted moves, or when no move lowers the energy.
    Deterministic.  Models without moves make this a no-op.
    """
    opt = problem.options
    level = problem.level(s)
    where = "" if s == len(problem.stages) - 1 else f"stage {s} "
    for hop in range(opt.basin_hops):
        moves = problem.model.escape_moves(progress.params, level)
        accepted, status = _hop_once(problem, progress, s, moves, status)
        tried = f"{len(moves)} moves"
        if not accepted and opt.hop_grid:
            grid = _grid_moves(problem.model, progress.params, level)
            if grid:
                accepted, status = _hop_once(problem, progress, s, grid, status)
                tried += f", then {min(len(grid), opt.hop_tries)} of {len(grid)} grid moves"
        if opt.progress:
            print(f"  start {progress.index} {where}basin hop {hop + 1}: "
                  + (f"a move was accepted, {status}, max rel. residual {progress.relative_residual:.3e}" if accepted
                     else f"none of {tried} lowers the energy"), file=sys.stderr, flush=True)
        if not accepted or progress.relative_residual <= opt.success_tol:
            break
    return status


def _grid_moves(model: SpectralModel, params: np.ndarray, level: int | None) -> list:
    """The moves of every level up to ``level`` taken alone (``escape_moves(..., newest=True)`` per level)."""
    levels = model.levels()
    top = levels[-1] if level is None and levels else level
    return [q for lv in levels if lv <= top for q in model.escape_moves(params, lv, newest=True)]
