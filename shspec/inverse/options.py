"""Options of the inverse solver, as one frozen dataclass (:class:`FitOptions`).

A fit runs a *schedule* of :class:`~shspec.inverse.schedule.Stage` s from each of several starts; its results are
in :mod:`shspec.inverse.results`.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..core.checks import check_choice, check_float, check_int
from ..errors import InvalidArgumentError
from .schedule import Stage

__all__ = ["OPTIMIZERS", "WEIGHTINGS", "AREA_MODES", "FitOptions", "fits_area"]

#: Optimizers: Levenberg–Marquardt on the residuals, limited-memory BFGS, dense BFGS, gradient descent.
OPTIMIZERS = ("lm", "lbfgs", "bfgs", "gd")
#: Eigenvalue weights w_i: 1 ("absolute") or 1/λ*_i² ("relative", every eigenvalue counts by its relative error).
WEIGHTINGS = ("relative", "absolute")
#: How a_00 (the area) is treated in a harmonic fit: "auto" fixes it to the target's true area when known and
#: fits it (started from the Weyl estimate) otherwise; "fixed" requires a known or estimated area; "fit" frees it.
AREA_MODES = ("auto", "fixed", "fit")


@dataclass(frozen=True)
class FitOptions:
    """Options of :func:`~shspec.inverse.fit`.  The defaults are the command line's; the user guide's inverse page
    (:doc:`/guide/inverse`) says what to expect of them, and the design notes (:doc:`/notes`) what was measured for
    each search option.

    Attributes
    ----------
    optimizer : {"lm", "lbfgs", "bfgs", "gd"} or None
        None (default): the model's :attr:`~shspec.spectral_model.SpectralModel.default_optimizer`, Levenberg–
        Marquardt for harmonic models, L-BFGS for mesh models.
    weights : {"relative", "absolute"}
        Eigenvalue weights, see :data:`WEIGHTINGS` (default "relative").
    reg : float
        Regularization weight R ≥ 0, dimensionless (harmonic: E += R‖Δρ‖²; meshes: the model's penalty).
    area : {"auto", "fixed", "fit"}
        Treatment of a_00, see :data:`AREA_MODES` (harmonic fits).
    schedule : tuple of Stage or None
        Stages run in order from each start; empty: one stage at full degree with every eigenvalue; None
        (default): the model's :func:`~shspec.inverse.default_schedule` (for harmonic models the degree ramp, at
        degrees 8 and 9 the parity ramp; the numeig ramp for meshes).
    stage_basis_tol : float or None
        Every stage but the last runs on the coarsest discretization on which its eigenvalues agree with the
        model's own to this relative tolerance (:meth:`~shspec.spectral_model.SpectralModel.stage_basis`, chosen
        once per fit at a reference ρ); a stage with :attr:`Stage.hops` uses ``success_tol`` if smaller.  None:
        every stage on the model's own.  Default 1e-5.
    search_basis_tol : float or None
        The last stage of the schedule and its basin hops (the search) run on the coarsest basis on which its
        eigenvalues agree with the model's own to this relative tolerance (chosen like the stage bases), and count as
        done at a residual of :data:`~shspec.inverse.problem.SEARCH_MARGIN` times it; the same stage then runs
        again on the model's own basis, which polishes the result to ``success_tol`` (no hops there).  The model's
        basis may then be chosen for the success tolerance (``shspec fit`` plans it so) while every search
        iteration costs what the search needs.  None, or when only the model's basis agrees: the last stage on the
        model's own basis.  Default 1e-6.
    starts : int
        Number of random symmetry-broken starts (default 4).
    start_budget : int or None
        A start that has not succeeded after this much work ends there, failed, with status "budget" and its best
        state, and the next start runs.  The work is the race's (:mod:`~shspec.inverse.race`, the same on every
        machine), counted here in iterations of the search stage (the last stage of the schedule, on its search
        basis): a budget of 1500 is 1500 such iterations, or more iterations of the cheaper stages before it.
        None (default): with the default schedule :func:`~shspec.inverse.schedule.default_start_budget`, a budget
        where one was measured
        (fits of degree 8 and 9 with the default schedule), else none; 0: none.
    stop_at_success : bool
        Stop at a success (default): the starts race in rounds of ``race``, and the fit keeps the first round with
        a success, up to its success of least work (:mod:`~shspec.inverse.race`), the same starts and numbers
        whether they ran one after the other or on an executor (:func:`~shspec.inverse.fit`).  False: run every
        start, e.g. to count the local solutions.
    race : int
        Starts per round of the race (default 2, the cores of the machine the goals were measured on): on a pool
        of as many workers a round ends about when its first success comes in; one after the other, a start after
        a success of its round runs up to the success's work.  1: the first successful start by index wins.
    seed : int
        Seed of every random choice: start i uses ``numpy.random.default_rng([seed, i])``.
    start_amplitude : float
        RMS size of a random start relative to the mean of ρ (degree l ≥ 2 gets a share ∝ 1/l).
    max_iter : int
        Iterations per stage unless the stage says otherwise.
    residual_tol : float
        Stop a stage when max_i |λ_i − λ*_i| / λ*_i ≤ residual_tol (i ≥ 1).
    step_tol : float
        Stop when a step changes the parameters by less than step_tol relative.
    energy_tol : float
        Stop when an accepted step lowers the energy by less than energy_tol relative, 5 times in a row.
    lbfgs_memory : int
        Number of correction pairs kept by L-BFGS.
    lm_damping : float
        Initial Levenberg–Marquardt damping μ (relative to diag(JᵀJ)).
    lm_acceleration : bool
        Levenberg–Marquardt adds the geodesic acceleration of each step (Transtrum & Sethna): one extra solve of
        the eigenvalues alone per trial, to follow curved valleys.
    basin_hops : int
        After the last stage, and after every stage with :attr:`Stage.hops`, while the relative residual is above
        ``success_tol``: up to this many accepted escape moves (0: none).  A hop tries the model's cheap moves
        (:meth:`~shspec.spectral_model.SpectralModel.escape_moves`), then the grid moves of ``hop_grid``; each is
        screened by a short refit, and the first below the current energy is refitted to convergence.  The hops
        stop at success, after ``basin_hops`` accepted moves, or when no move lowers the energy.
    hop_iter : int
        Iterations of each move's screening refit (plain LM, without ``lm_acceleration``).
    hop_extend : int
        A screening refit still above the current energy at ``hop_iter`` iterations goes on, up to this many
        iterations in all, while its energy falls by 10 % over its last 3 iterations (``hop_iter``: never).
    hop_grid : bool
        When no cheap move lowers the energy, also try every degree block turned through the octahedral group
        (and reflected, for odd blocks).
    hop_tries : int
        At most this many moves of a hop are refitted, those of lowest energy before any refit; it bounds the
        cost of a hop that finds nothing.
    orient_blocks : bool
        After each stage that first fits a new degree block, try its orientations relative to the blocks fitted
        before (default off).
    distinct_tol : float
        Two converged starts are the same local solution when their energies agree to this relative tolerance
        and their per-degree powers (rotation invariant) agree to it relative to the total power.
    success_tol : float
        A start succeeds when its final relative spectral residual is ≤ success_tol.
    checkpoint_every : int
        Write a checkpoint every N iterations (0: never); needs ``checkpoint_path``.
    checkpoint_path : str or None
        HDF5 file of the checkpoint.
    progress : bool
        Show the fit's progress on stderr (:class:`~shspec.inverse.progress.FitDisplay`): a bar on a terminal with
        the stage, the starts done, the successes, the elapsed and the estimated remaining time, and one line per
        finished stage, hop and start.  On by default, in Python as on the command line: a fit takes seconds to
        minutes, and silence for that long reads as a hang.

    Examples
    --------
    >>> from shspec.inverse import FitOptions
    >>> options = FitOptions(starts=2, seed=7)
    >>> options.starts, options.stop_at_success, options.success_tol
    (2, True, 1e-10)
    """

    optimizer: str | None = None
    weights: str = "relative"
    reg: float = 0.0
    area: str = "auto"
    schedule: tuple | None = None
    stage_basis_tol: float | None = 1e-5
    search_basis_tol: float | None = 1e-6
    starts: int = 4
    start_budget: int | None = None
    stop_at_success: bool = True
    race: int = 2
    seed: int = 0
    start_amplitude: float = 0.2
    max_iter: int = 200
    residual_tol: float = 1e-13
    step_tol: float = 1e-15
    energy_tol: float = 1e-6
    lbfgs_memory: int = 20
    lm_damping: float = 1e-3
    lm_acceleration: bool = True
    basin_hops: int = 12
    hop_iter: int = 15
    hop_extend: int = 45
    hop_grid: bool = True
    hop_tries: int = 144
    orient_blocks: bool = False
    distinct_tol: float = 1e-4
    success_tol: float = 1e-10
    checkpoint_every: int = 0
    checkpoint_path: str | None = None
    progress: bool = True

    def __post_init__(self):
        if self.optimizer is not None:
            check_choice(self.optimizer, "optimizer", OPTIMIZERS)
        check_choice(self.weights, "weights", WEIGHTINGS)
        check_choice(self.area, "area", AREA_MODES)
        if self.schedule is not None and (not isinstance(self.schedule, tuple)
                                          or not all(isinstance(s, Stage) for s in self.schedule)):
            raise InvalidArgumentError("schedule must be None (the model's default) or a tuple of Stage")
        degrees = [s.lmax_factor for s in self.schedule or () if s.lmax_factor is not None]
        if any(b < a for a, b in zip(degrees, degrees[1:])):
            raise InvalidArgumentError(f"the stages' degrees must not decrease, got {degrees}")
        check_float(self.reg, "reg", minimum=0.0)
        if self.stage_basis_tol is not None:
            check_float(self.stage_basis_tol, "stage_basis_tol", positive=True)
        if self.search_basis_tol is not None:
            check_float(self.search_basis_tol, "search_basis_tol", positive=True)
        check_int(self.starts, "starts", minimum=1)
        check_int(self.start_budget, "start_budget", allow_none=True, minimum=0)
        check_int(self.race, "race", minimum=1)
        check_int(self.seed, "seed", minimum=0)
        check_float(self.start_amplitude, "start_amplitude", positive=True)
        check_int(self.max_iter, "max_iter", minimum=1)
        for name in ("residual_tol", "step_tol", "energy_tol", "distinct_tol", "success_tol"):
            check_float(getattr(self, name), name, positive=True)
        check_int(self.lbfgs_memory, "lbfgs_memory", minimum=1)
        check_float(self.lm_damping, "lm_damping", positive=True)
        if not isinstance(self.lm_acceleration, bool):
            raise InvalidArgumentError(f"lm_acceleration must be a bool, got {self.lm_acceleration!r}")
        check_int(self.basin_hops, "basin_hops", minimum=0)
        check_int(self.hop_iter, "hop_iter", minimum=1)
        check_int(self.hop_tries, "hop_tries", minimum=1)
        check_int(self.hop_extend, "hop_extend", minimum=self.hop_iter)
        for name in ("stop_at_success", "hop_grid", "orient_blocks"):
            if not isinstance(getattr(self, name), bool):
                raise InvalidArgumentError(f"{name} must be a bool, got {getattr(self, name)!r}")
        check_int(self.checkpoint_every, "checkpoint_every", minimum=0)
        if self.checkpoint_every and not self.checkpoint_path:
            raise InvalidArgumentError("checkpoint_every > 0 needs a checkpoint_path")


def fits_area(options: FitOptions, target) -> bool:
    """Whether a fit frees the area: ``area="fit"``, or ``"auto"`` with a target whose area is unknown."""
    return options.area == "fit" or (options.area == "auto" and target.area is None)


