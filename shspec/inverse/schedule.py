"""Running one start through the stages of a schedule, with checkpoints and a clean Ctrl-C.

A :class:`FitProblem` is the model-specific glue: how a random start looks, which parameters a stage frees, which
model a stage uses (a harmonic stage of degree L uses the Gauss table restricted to L, which is cheaper).  Every
random choice of start i is drawn from ``default_rng([seed, i])`` and, for the perturbation a stage adds to its
new degrees, ``default_rng([seed, i, stage + 1])``: a run is reproducible, and a resumed run draws the same numbers.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import BandLimitError, InvalidArgumentError, NotPositiveError
from ..sphere.harmonics import degrees, ncoeffs
from ..model import SpectralModel
from .energy import Objective, eigenvalue_weights, harmonic_free_indices
from .optimize import make_optimizer
from .options import FitOptions, Stage, StartResult
from .targets import Target

__all__ = ["FitProblem", "run_start", "StartProgress", "numeig_ramp", "degree_ramp"]

#: Size of the perturbation given to the degrees a stage adds, relative to the one of a random start: enough to
#: leave the parity saddle, small enough not to undo what the earlier stages found.
_NEW_DEGREE_SCALE = 0.05


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
    if isinstance(numeig, bool) or not isinstance(numeig, (int, np.integer)) or numeig < 2:
        raise InvalidArgumentError(f"numeig must be an integer >= 2, got {numeig!r}")
    if isinstance(first, bool) or not isinstance(first, (int, np.integer)) or first < 2:
        raise InvalidArgumentError(f"first must be an integer >= 2, got {first!r}")
    ks, j = [], int(np.ceil(np.sqrt(first)))
    while j * j < numeig:
        ks.append(j * j)
        j += 2
    return tuple(Stage(lmax_factor=lmax_factor, numeig=k) for k in [*ks, int(numeig)])


def degree_ramp(numeig: int, lmax_factor: int) -> tuple[Stage, ...]:
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
    """
    if isinstance(numeig, bool) or not isinstance(numeig, (int, np.integer)) or numeig < 2:
        raise InvalidArgumentError(f"numeig must be an integer >= 2, got {numeig!r}")
    if isinstance(lmax_factor, bool) or not isinstance(lmax_factor, (int, np.integer)) or lmax_factor < 2:
        raise InvalidArgumentError(f"lmax_factor must be an integer >= 2, got {lmax_factor!r}")
    stages = [Stage(lmax_factor=l, numeig=(l + 2) ** 2) for l in range(2, int(lmax_factor) + 1)
              if (l + 2) ** 2 < numeig]
    j = int(lmax_factor) + 3
    j += j % 2
    while j * j < numeig:
        stages.append(Stage(lmax_factor=int(lmax_factor), numeig=j * j))
        j += 2
    stages.append(Stage(lmax_factor=int(lmax_factor), numeig=int(numeig)))
    return tuple(stages)


class FitProblem:
    """A model, a target and the options, with the stage logic of the model's kind.

    Parameters
    ----------
    model : HarmonicModel or MeshModel
    target : Target
    options : FitOptions

    Raises
    ------
    InvalidArgumentError
        If a stage asks for more eigenvalues than the target has, a mesh fit has stages with a degree, or the area
        is to be fixed but is unknown.
    BandLimitError
        If a stage's degree exceeds the model's La.
    """

    def __init__(self, model: SpectralModel, target: Target, options: FitOptions):
        from ..galerkin.solver import HarmonicModel
        from ..mesh.model import MeshModel

        if not isinstance(target, Target):
            raise InvalidArgumentError(f"target must be a Target, got {type(target).__name__}")
        if not isinstance(options, FitOptions):
            raise InvalidArgumentError(f"options must be FitOptions, got {type(options).__name__}")
        if isinstance(model, HarmonicModel):
            self.kind = "harmonic"
        elif isinstance(model, MeshModel):
            self.kind = "mesh"
        else:
            raise InvalidArgumentError(f"model must be a HarmonicModel or a MeshModel, got {type(model).__name__}")
        self.model, self.target, self.options = model, target, options
        self.stages = options.schedule or (Stage(),)
        for st in self.stages:
            if st.numeig is not None and st.numeig > target.numeig:
                raise InvalidArgumentError(f"a stage matches {st.numeig} eigenvalues; the target has {target.numeig}")
            if st.lmax_factor is not None:
                if self.kind == "mesh":
                    raise InvalidArgumentError("stages of a mesh fit change numeig only (lmax_factor must be None)")
                if st.lmax_factor > model.lmax_factor:
                    raise BandLimitError(f"stage degree {st.lmax_factor} > the model's lmax_factor "
                                         f"{model.lmax_factor}")
        if options.area == "fixed" and target.area is None and target.numeig < 4:
            raise InvalidArgumentError("a fixed area needs a known area or a spectrum to estimate it from")
        self.fit_area = options.area == "fit" or (options.area == "auto" and target.area is None)
        self.area = target.area_estimate()
        self._models: dict[int, SpectralModel] = {}

    # -- per-kind logic -------------------------------------------------------------------------------------------

    def stage_degree(self, s: int) -> int | None:
        """Factor degree of stage s (harmonic fits), None for meshes."""
        if self.kind == "mesh":
            return None
        la = self.stages[s].lmax_factor
        return self.model.lmax_factor if la is None else la

    def stage_model(self, s: int) -> SpectralModel:
        """The model of stage s: for harmonic stages, the Galerkin model of the stage's degree."""
        from ..galerkin.solver import HarmonicModel

        la = self.stage_degree(s)
        if la is None or la == self.model.lmax_factor:
            return self.model
        if la not in self._models:
            self._models[la] = HarmonicModel(self.model.lmax, la, table=self.model.table)
        return self._models[la]

    def _harmonic_noise(self, rng: np.random.Generator, low: int, high: int, amplitude: float) -> np.ndarray:
        """Random coefficients (ncoeffs(high),) of degrees low..high (l ≠ 1), RMS ∝ amplitude/l per degree."""
        l = degrees(high).astype(float)
        draw = rng.standard_normal(l.size)
        sigma = amplitude / (np.sqrt(2 * l + 1) * np.maximum(l, 1.0))
        keep = (l >= max(low, 2))
        return np.where(keep, sigma * draw, 0.0)

    def initial(self, rng: np.random.Generator) -> np.ndarray:
        """A random symmetry-broken start (nparams,) of the model, positive, with the target's area.

        Harmonic: a_00 from the area, a_1m = 0, degrees 2..La of the first stage random (odd ones included, so
        the fit is not trapped in the even subspace).  Mesh: constant factors times 1 + a random smooth field.
        The amplitude is halved until the minimum is at least a quarter of the mean.
        """
        amp = self.options.start_amplitude
        if self.kind == "harmonic":
            a00 = self.area / np.sqrt(4 * np.pi)
            la = self.stage_degree(0)
            noise = self._harmonic_noise(rng, 2, la, amp * a00)
            params = np.zeros(self.model.nparams)
            params[0] = a00
            for _ in range(30):
                params[1:ncoeffs(la)] = noise[1:]
                if self._minimum(params) >= 0.25 * a00 / np.sqrt(4 * np.pi):  # a quarter of the mean of ρ
                    return params
                noise = noise * 0.5
            raise InvalidArgumentError("could not draw a positive random start")  # pragma: no cover
        from ..sphere.evaluate import sample_harmonic

        areas = self.model.vertex_areas
        c0 = self.area / areas.sum()
        field_ = sample_harmonic(self._harmonic_noise(rng, 2, 4, amp), self.model.mesh.vertices)
        while np.min(field_) < -0.75:
            field_ = field_ * 0.5
        return c0 * (1.0 + field_)

    def _minimum(self, params) -> float:
        from ..sphere.factor import ConformalFactor

        return ConformalFactor(np.array(params)).minimum().value  # a copy: ConformalFactor freezes its array

    def enter_stage(self, s: int, params: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Parameters at the start of stage s: the degrees it adds get a small random perturbation."""
        if self.kind == "mesh" or s == 0:
            return params
        old, new = self.stage_degree(s - 1), self.stage_degree(s)
        if new <= old:
            return params
        out = params.copy()
        noise = self._harmonic_noise(rng, old + 1, new, _NEW_DEGREE_SCALE * self.options.start_amplitude * out[0])
        for _ in range(30):
            out[ncoeffs(old):ncoeffs(new)] = noise[ncoeffs(old):]
            if self._minimum(out[:ncoeffs(new)]) > 0:
                return out
            noise = noise * 0.5
        return params  # pragma: no cover - a positive ρ stays positive under a small enough change

    def objective(self, s: int, params: np.ndarray) -> Objective:
        """The energy of stage s with the fixed parameters taken from ``params`` (nparams,)."""
        st = self.stages[s]
        k = self.target.numeig if st.numeig is None else st.numeig
        lam = self.target.eigenvalues[:k]
        model = self.stage_model(s)
        w = eigenvalue_weights(lam, self.options.weights)
        if self.kind == "harmonic":
            la = self.stage_degree(s)
            base, free = params[:ncoeffs(la)], harmonic_free_indices(la, self.fit_area)
        else:
            base, free = params, np.arange(model.nparams)
        return Objective(model, lam, w, base, free, self.options.reg)

    @staticmethod
    def merge(params: np.ndarray, objective: Objective, x) -> np.ndarray:
        """Full parameters after a stage: the stage's parameters written back into ``params``."""
        out = params.copy()
        p = objective.params(x)
        out[:p.size] = p
        return out


@dataclass
class StartProgress:
    """Where a start is: enough to checkpoint it or to report it after Ctrl-C.

    Attributes
    ----------
    index, stage : int
        Start and stage.
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
    status = "max_iter"
    params = progress.base
    for s in range(progress.stage, len(problem.stages)):
        resumed = progress.state is not None and s == progress.stage
        if not resumed:
            params = problem.enter_stage(s, params, np.random.default_rng([*rng_seed, s + 1]))
            progress.stage, progress.base = s, params
        obj = problem.objective(s, progress.base)
        optimizer = make_optimizer(opt.optimizer, obj, obj.initial(), opt, progress.state if resumed else None)
        max_iter = problem.stages[s].max_iter or opt.max_iter

        def record():
            progress.params = problem.merge(progress.base, obj, optimizer.x)
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
                progress.seconds = time.perf_counter() - t0
                checkpoint(progress)
        status = optimizer.status or "max_iter"
        params = progress.params
        progress.state = None
        if opt.progress:
            print(f"\r  start {progress.index} stage {s} ({problem.stage_degree(s)}, {obj.target.size} eigenvalues): "
                  f"{status} after {optimizer.iteration} iterations, max rel. residual "
                  f"{optimizer.ev.relative_residual:.3e}", file=sys.stderr, flush=True)
    if opt.basin_hops and problem.kind == "harmonic" and progress.relative_residual > opt.success_tol:
        status = _basin_hop(problem, progress, status)
    return progress.result(status, time.perf_counter() - t0, opt.success_tol)


def _block_moves(params: np.ndarray, la: int) -> list:
    """Power-preserving moves of one degree block l ≥ 2: its half-turns about the z, y and x axes, and for odd l
    also these composed with the sign −1 and the sign alone (the point reflection of that block only).  For even l
    the mirror z ↦ −z of the block is its half-turn about z; for odd l the negated one."""
    from ..sphere.rotate import rotate_coefficients

    l_all = degrees(la)
    moves = []
    for l in range(2, la + 1):
        sel = l_all == l
        sub = np.where(sel, params[:l_all.size], 0.0)
        turns = [rotate_coefficients(sub, np.array(ang)) for ang in ((np.pi, 0, 0), (0, np.pi, 0), (np.pi, np.pi, 0))]
        if l % 2:
            turns += [-t for t in turns] + [-sub]
        for t in turns:
            q = params.copy()
            q[:l_all.size][sel] = t[sel]
            moves.append(q)
    return moves


def _basin_hop(problem: FitProblem, progress: StartProgress, status: str) -> str:
    """Leave a local minimum by power-preserving block moves (see :attr:`FitOptions.basin_hops`).

    The failed fits of the blob end in local minima whose per-degree power is already right (to ~1e-4) while the
    degree blocks are wrongly placed relative to each other.  A move turns one block by a half-turn about a
    coordinate axis (odd blocks also negated), keeping every power; the moves are tried in the order of their
    energy before any refit, with ``hop_iter`` iterations of the last stage each, the first whose energy ends below the current one is refitted to convergence, and the
    hops stop at success, after ``basin_hops`` accepted moves, or when no move lowers the energy.  Deterministic.
    """
    opt = problem.options
    s = len(problem.stages) - 1
    la = problem.stage_degree(s)

    def run(params, iters):
        obj = problem.objective(s, params)
        try:
            optimizer = make_optimizer(opt.optimizer, obj, obj.initial(), opt)
        except NotPositiveError:  # a move that leaves ρ non-positive
            return None
        hist = []
        while optimizer.status is None and optimizer.iteration < iters:
            optimizer.step()
            hist.append((s, optimizer.ev.energy, optimizer.ev.relative_residual))
        return optimizer, obj, hist

    def energy(q):
        obj = problem.objective(s, q)
        try:
            return obj.evaluate(obj.initial()).energy
        except NotPositiveError:
            return np.inf

    for _ in range(opt.basin_hops):
        accepted = False
        moves = _block_moves(progress.params, la)
        # Cheapest first: one eigensolve per move, then the short refits in order of the moved energy.
        for q in [moves[k] for k in np.argsort([energy(q) for q in moves], kind="stable")]:
            out = run(q, opt.hop_iter)
            if out is None or out[0].ev.energy >= progress.energy:
                continue
            optimizer, obj, hist = out
            full = run(problem.merge(q, obj, optimizer.x), problem.stages[s].max_iter or opt.max_iter)
            optimizer, obj, hist2 = full
            progress.history.extend(hist + hist2)
            progress.params = problem.merge(q, obj, optimizer.x)
            progress.energy, progress.relative_residual = optimizer.ev.energy, optimizer.ev.relative_residual
            progress.eigenvalues = optimizer.ev.eigenvalues
            status, accepted = optimizer.status or "max_iter", True
            break
        if not accepted or progress.relative_residual <= opt.success_tol:
            break
    return status
