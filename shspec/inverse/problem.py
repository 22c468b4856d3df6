"""One fit problem and where a start of it is.

A :class:`FitProblem` holds a model, a target and the options, and builds the objective of each stage from what the
model says of itself (:class:`~shspec.spectral_model.SpectralModel`): the level a stage restricts it to, the free parameters,
the transform of the variables, the random start and the perturbation a stage adds when it raises the level.
A :class:`StartProgress` is where one start is: enough to checkpoint it, to resume it, or to report it after Ctrl-C.
Every random choice of start i is drawn from ``default_rng([seed, i])`` and, for the perturbation a stage adds to
its new level, ``default_rng([seed, i, stage + 1])``: a run is reproducible, and a resumed run draws the same numbers.
"""

from __future__ import annotations

import copy
import sys
from dataclasses import dataclass, field, replace

import numpy as np

from ..core.checks import finite_array
from ..errors import InvalidArgumentError, NotPositiveError
from ..core.parallel import usable_cores
from ..spectral_model import SpectralModel
from .target import Target
from .energy import Objective, eigenvalue_weights
from .options import FitOptions, fits_area
from .parametrization import Parametrization
from .results import StartResult
from .schedule import Stage, default_schedule, default_start_budget

__all__ = ["FitProblem", "StartProgress", "BudgetSpent", "BUDGET", "consistent_with_errors", "CHI2_SIGMAS",
           "SEARCH_MARGIN"]

#: A fit is consistent with a target's errors when χ²/ν ≤ 1 + CHI2_SIGMAS·√(2/ν), ν = K − 1 eigenvalues: the mean
#: of χ²/ν is 1 and its standard deviation √(2/ν) for Gaussian errors.
CHI2_SIGMAS = 3.0

#: The search stage of an exact target is done at a residual of SEARCH_MARGIN·``search_basis_tol``: its basis agrees
#: with the model's own to that tolerance at a reference ρ, not at the truth, so the truth's residual there may be a
#: few times larger (FitOptions.search_basis_tol).
SEARCH_MARGIN = 10.0


def consistent_with_errors(eigenvalues, target, errors) -> bool:
    """Whether eigenvalues (k,) match ``target`` (k,) within its one-sigma ``errors`` (k,) in the χ² sense
    (:data:`CHI2_SIGMAS`; λ₀ excluded)."""
    r = (np.asarray(eigenvalues)[1:] - np.asarray(target)[1:]) / np.asarray(errors)[1:]
    nu = r.size
    return bool(np.mean(r * r) <= 1.0 + CHI2_SIGMAS * np.sqrt(2.0 / nu))


#: Size of the perturbation given to the parameters a stage adds, relative to the one of a random start: enough to
#: leave the parity saddle, small enough not to undo what the earlier stages found.
_NEW_DEGREE_SCALE = 0.05


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
    executor : concurrent.futures.Executor, optional
        Choose the stages' bases on it (the fit's process pool), split over the usable cores; None: here.

    Raises
    ------
    InvalidArgumentError
        If a stage asks for more eigenvalues than the target has or for a level the model does not have, or the
        area is to be fixed but is unknown.
    BandLimitError
        If a stage's degree exceeds the model's.
    """

    def __init__(self, model: SpectralModel, target: Target, options: FitOptions, *, init=None, executor=None):
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
        default = options.schedule is None and init is None
        if default:
            schedule = default_schedule(model, target.numeig, target.errors is None)
        elif options.schedule is not None:
            schedule = options.schedule
        else:
            # a given start already holds the coarse shape: one stage at full resolution, not a ramp that would
            # truncate it to the first level
            schedule = (Stage(),)
        self.stages = schedule or (Stage(),)
        for st in self.stages:
            if st.numeig is not None and st.numeig > target.numeig:
                raise InvalidArgumentError(f"a stage matches {st.numeig} eigenvalues; the target has {target.numeig}")
            model.restrict(st.lmax_factor)  # raises for a level the model does not have
            if st.even and model.odd_parameters() is None:
                raise InvalidArgumentError(f"an even stage holds the odd parameters at 0; {model.describe()} has "
                                           "no parity")
        if options.area == "fixed" and target.area is None and target.numeig < 4:
            raise InvalidArgumentError("a fixed area needs a known area or a spectrum to estimate it from")
        self._set_target(target)
        # chosen here, once, at a reference: a start's path may then not depend on where the fit runs
        tol = options.stage_basis_tol
        last = self.stages[-1]
        # a stage that hops tests success at success_tol: on a basis only good to 1e-5 the truth itself would fail
        # it (the blob's 6:64 stage on Lb' = 14 ends every start at 1.5e-6, and its hops go on)
        requests = [None if tol is None or s == len(self.stages) - 1
                    else (st.lmax_factor, st.numeig or target.numeig,
                          min(tol, options.success_tol) if st.hops else tol)
                    for s, st in enumerate(self.stages)]
        if options.search_basis_tol is not None and not last.hops:
            requests.append((last.lmax_factor, last.numeig or target.numeig, options.search_basis_tol))
        bases = _stage_bases(model, requests, executor)
        self.bases = bases[:len(self.stages)]
        #: index of the search stage (None: none): the last stage of the schedule and its basin hops run on the
        #: coarsest basis good to ``search_basis_tol``, and a copy of it on the model's own basis polishes the result
        self.search = None
        if len(bases) > len(self.stages) and bases[-1] is not None:
            self.stages = (*self.stages[:-1], replace(last, hops=True), last)
            self.bases = [*self.bases[:-1], bases[-1], None]
            self.search = len(self.stages) - 2
        #: the work after which a start that has not succeeded ends (FitOptions.start_budget; None: no limit), in
        #: the race's units: the budget's iterations times the search stage's solve cost
        budget = options.start_budget
        if budget is None:
            budget = default_start_budget(model, target.errors is None) if default else 0
        self.work_budget = self._work_budget(budget)
        if options.progress and any(b is not None for b in self.bases):
            print("stage bases (degree:eigenvalues -> basis degree): " + ", ".join(
                f"{st.lmax_factor}:{st.numeig or target.numeig} -> {b}" for st, b in zip(self.stages, self.bases)
                if b is not None), file=sys.stderr, flush=True)

    def _work_budget(self, budget: int) -> float | None:
        if not budget:
            return None
        s = len(self.stages) - 1 if self.search is None else self.search
        st = self.stages[s]
        return budget * self.model.restrict(self.level(s), self.bases[s]).solve_cost(st.numeig or self.target.numeig)

    def with_target(self, target: Target) -> "FitProblem":
        """This problem with ``target`` instead, of as many eigenvalues (a checkpoint's own copy of the target,
        round-off apart): the stages and their bases depend on the target's size only, and are kept."""
        if not isinstance(target, Target) or target.numeig != self.target.numeig:
            raise InvalidArgumentError(f"the target must be a Target of {self.target.numeig} eigenvalues")
        new = copy.copy(self)
        new._set_target(target)
        return new

    def _set_target(self, target: Target) -> None:
        self.target, self.fit_area, self.area = target, fits_area(self.options, target), target.area_estimate()

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
        """Parameters at the start of stage s: what its level adds gets a small random perturbation, and so do the
        odd parameters after an even stage (:attr:`Stage.even`)."""
        if s == 0:
            return params
        amplitude = _NEW_DEGREE_SCALE * self.options.start_amplitude
        params = self.model.enter_level(params, self.level(s - 1), self.level(s), rng, amplitude)
        if self.stages[s - 1].even and not self.stages[s].even:
            params = self.model.release_odd(params, self.level(s), rng, amplitude)
        return params

    def objective(self, s: int, params: np.ndarray) -> Objective:
        """The energy of stage s with the fixed parameters taken from ``params`` (nparams,)."""
        st = self.stages[s]
        k = self.target.numeig if st.numeig is None else st.numeig
        lam = self.target.eigenvalues[:k]
        sub = self.model.restrict(self.level(s), self.bases[s])
        base, free = self.model.to_level(params, self.level(s)), sub.free_parameters(self.fit_area)
        if st.even:
            odd = sub.odd_parameters()
            base = base.copy()
            base[odd] = 0.0
            free = np.setdiff1d(free, odd)
        par = Parametrization.at(base, free, sub.transform)
        errors = None if self.target.errors is None else self.target.errors[:k]
        return Objective(sub, lam, eigenvalue_weights(lam, self.options.weights, errors), par, self.options.reg)

    def stage_moves(self, s: int, params: np.ndarray, moves: list) -> list:
        """The escape moves (parameter vectors, nparams each) that change what stage s fits: on an even stage
        (:attr:`Stage.even`) a move of odd parameters only is no move, as the stage holds them at 0."""
        if not self.stages[s].even:
            return moves
        even = np.ones(np.size(params), dtype=bool)
        even[self.model.restrict(self.level(s)).odd_parameters()] = False
        return [q for q in moves if np.any(q[even] != params[even])]

    def search_basis_holds(self, params: np.ndarray) -> bool:
        """Whether the search stage's basis holds at ``params`` (nparams,), not only at the reference it was chosen
        at: its eigenvalues agree with those on the model's own basis to :data:`SEARCH_MARGIN` times
        ``search_basis_tol`` (two eigenvalue solves).  A ρ far from the starts' law (a log factor of large
        amplitude, say) may need more of the basis than the reference did; its search then runs on the model's
        own basis."""
        s = self.search
        try:
            coarse, fine = self.objective(s, params), self.objective(s + 1, params)
            lam, ref = coarse.values(coarse.initial()).eigenvalues, fine.values(fine.initial()).eigenvalues
        except NotPositiveError:
            return False
        return bool(np.max(np.abs(lam[1:] / ref[1:] - 1.0)) <= SEARCH_MARGIN * self.options.search_basis_tol)

    def succeeded(self, eigenvalues, relative_residual: float, stage: int | None = None) -> bool:
        """Whether matched eigenvalues (k,) fit the target: to ``success_tol`` (relative) for an exact target; for a
        target with errors, residuals consistent with them (:func:`consistent_with_errors`).  On the search stage
        (``stage`` = :attr:`search`) an exact target is met at what its basis allows: :data:`SEARCH_MARGIN` times
        ``search_basis_tol``."""
        if self.target.errors is None:
            tol = self.options.success_tol
            if stage is not None and stage == self.search:
                tol = max(tol, SEARCH_MARGIN * self.options.search_basis_tol)
            return bool(relative_residual <= tol)
        k = np.size(eigenvalues)
        return consistent_with_errors(eigenvalues, self.target.eigenvalues[:k], self.target.errors[:k])

    def merge(self, s: int, params: np.ndarray, objective: Objective, x) -> np.ndarray:
        """Full parameters after stage s: the stage's parameters written back into ``params``."""
        return self.model.from_level(objective.params(x), params, self.level(s))


def _choose_bases(model: SpectralModel, requests: list) -> list:
    """``model.stage_basis(*r)`` for each request r (a job sent to an executor's worker)."""
    return [model.stage_basis(*r) for r in requests]


def _stage_bases(model: SpectralModel, requests: list, executor) -> list:
    """The stage bases of ``requests`` ((level, numeig, tol) or None each), here or split over the usable cores on
    ``executor``: each is independent and deterministic, and threads would not help (two LAPACK solves on two
    threads of one process took as long as one after the other).  The largest requests are dealt out first."""
    jobs = sorted((i for i, r in enumerate(requests) if r is not None), key=lambda i: -requests[i][1])
    out = [None] * len(requests)
    parts = 1 if executor is None else min(len(jobs), usable_cores())
    if parts < 2:
        for i, basis in zip(jobs, _choose_bases(model, [requests[i] for i in jobs])):
            out[i] = basis
        return out
    chunks = [jobs[c::parts] for c in range(parts)]
    futures = [executor.submit(_choose_bases, model, [requests[i] for i in chunk]) for chunk in chunks]
    try:
        for chunk, future in zip(chunks, futures):
            for i, basis in zip(chunk, future.result()):
                out[i] = basis
    except BaseException:
        for future in futures:
            future.cancel()
        raise
    return out


#: Status of a start ended by its budget (:attr:`FitOptions.start_budget`).
BUDGET = "budget"


class BudgetSpent(Exception):
    """Raised in a start whose work reached its budget (:attr:`FitOptions.start_budget`) without success."""


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
        Time spent in this start: before the current run (resumed starts) while it runs, up to date after each
        iteration and whenever :func:`~shspec.inverse.driver.run_start` returns or is interrupted.
    work : float
        The start's work so far (:mod:`~shspec.inverse.race`): its optimizer iterations and its hops' move solves,
        each weighted by its stage's :attr:`~shspec.inverse.energy.Objective.cost`.
    stage_work : float
        ``work`` when the start entered its current stage (or its final hops): where a resume that runs the stage
        again restarts the count.

    A checkpoint holds :meth:`resume_point`, the state at the last :meth:`mark`, never the live fields: an
    interrupt (Ctrl-C, SIGTERM) lands anywhere, between an optimizer's step and its history row, or inside the hops
    whose rows a resume runs again, and a checkpoint of that moment would resume into another history.
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
    work: float = 0.0
    stage_work: float = 0.0
    #: what the start knows of its round's best success (:class:`~shspec.inverse.race.RaceBound`; None: no race);
    #: not part of a checkpoint
    bound: object = field(default=None, repr=False, compare=False)
    #: the work after which the start ends (:attr:`FitProblem.work_budget`, set when it runs); not part of a
    #: checkpoint, as it follows from the options
    budget: float | None = field(default=None, repr=False, compare=False)
    #: the fit's :class:`~shspec.inverse.progress.FitDisplay` while it runs here (None in an executor's worker,
    #: whose lines go to its own stderr); not part of a checkpoint
    display: object = field(default=None, repr=False, compare=False)
    #: (stage, base, state, history rows, work, stage_work, status) at the last :meth:`mark`; None: none yet
    _mark: tuple | None = field(default=None, repr=False, compare=False)

    def mark(self) -> None:
        """Note the present as where a resume may continue from: a completed iteration (``state`` that of its
        optimizer), or the entry of a stage or of the final hops (``state`` None: the resume runs it from there)."""
        self._mark = (self.stage, self.base, self.state, len(self.history), self.work, self.stage_work, self.status)

    def resume_point(self) -> "StartProgress":
        """The start as of its last :meth:`mark` (itself before any), what a checkpoint holds: resumed, it runs on
        as this run did from there."""
        if self._mark is None:
            return self
        stage, base, state, rows, work, stage_work, status = self._mark
        return StartProgress(self.index, stage, base, state, self.history[:rows], seconds=self.seconds,
                             status=status, work=work, stage_work=stage_work)

    def add_work(self, cost: float) -> None:
        """Count ``cost`` more work; raises :class:`~shspec.inverse.race.RaceLost` once the start can no longer win
        its round, :class:`BudgetSpent` once it has spent ``budget``."""
        self.work += cost
        if self.bound is not None:
            self.bound.check(self.work)
        if self.budget is not None and self.work >= self.budget:
            raise BudgetSpent(f"its work reached the start budget ({self.budget:.6g})")

    def say(self, options, text: str) -> None:
        """Report a line of this start: through the fit's display, else (a worker) on stderr if ``progress``."""
        if self.display is not None:
            self.display.message(text)
        elif options.progress:
            print(text, file=sys.stderr, flush=True)

    def result(self, status: str, seconds: float, success: bool) -> StartResult:
        """The start's outcome so far (its best state: the optimizers only accept descent); ``success`` from
        :meth:`FitProblem.succeeded`."""
        return StartResult(index=self.index, params=self.params.copy(), energy=float(self.energy),
                           relative_residual=float(self.relative_residual),
                           iterations=max(len(self.history) - 1, 0), seconds=seconds, status=status,
                           history=np.array(self.history, dtype=float).reshape(-1, 3),
                           eigenvalues=np.array(self.eigenvalues), success=bool(success), work=float(self.work))

    def succeeded(self, problem: FitProblem, final: bool = False) -> bool:
        """Whether the start's state so far fits the target (:meth:`FitProblem.succeeded`): as its current stage
        asks, or, ``final``, as a result must (the search stage's allowance does not count)."""
        return self.eigenvalues is not None and problem.succeeded(self.eigenvalues, self.relative_residual,
                                                                  None if final else self.stage)

