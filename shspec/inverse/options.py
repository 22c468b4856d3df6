"""Options of the inverse solver, as one frozen dataclass (:class:`FitOptions`).

A fit runs a *schedule* of :class:`~shspec.inverse.schedule.Stage` s from each of several starts; its results are
in :mod:`shspec.inverse.results`.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..checks import check_choice, check_float, check_int
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
    """Options of :func:`~shspec.inverse.fit`.

    Attributes
    ----------
    optimizer : {"lm", "lbfgs", "bfgs", "gd"} or None
        None (the default, also the command line's): the model's :attr:`~shspec.spectral_model.SpectralModel.default_optimizer`.
        Harmonic models use "lm" (Levenberg–Marquardt): it reached the same minimum as L-BFGS and BFGS in 4–5× less
        time and converges quadratically near a zero-residual solution; gradient descent had not converged after
        1000 iterations.  Mesh models use "lbfgs": at 600 vertices and 599 eigenvalues it reached LM's point in 11 s
        against 16 s, and at 1200 vertices LM diverged (benchmarks/results/bench_inverse.json).
    weights : {"relative", "absolute"}
        Eigenvalue weights, see :data:`WEIGHTINGS`.
    reg : float
        Bi-Laplacian regularization weight R ≥ 0 (E += R‖Δρ‖²).
    area : {"auto", "fixed", "fit"}
        Treatment of a_00, see :data:`AREA_MODES` (harmonic fits).
    schedule : tuple of Stage or None
        Stages run in order from each start; empty means one stage at full degree with every eigenvalue; None (the
        default, also the command line's) the model's default, :func:`~shspec.inverse.default_schedule`: the degree
        ramp for harmonic models (with 4 basin hops 7 of 8 blob starts succeeded, against 2 of 8 with
        :func:`~shspec.inverse.numeig_ramp` and none with one stage; benchmarks/results/bench_inverse.json), the
        numeig ramp for meshes.
    stage_basis_tol : float or None
        Every stage but the last runs on the coarsest discretization of the model on which its eigenvalues agree
        with the model's own to this relative tolerance (:meth:`~shspec.spectral_model.SpectralModel.stage_basis`; harmonic
        models: a smaller basis degree, chosen once per fit at a reference ρ); the last stage and the basin hops use
        the model itself; a stage with :attr:`Stage.hops` gets the tolerance ``success_tol`` (if smaller), so that
        its hops can tell success.  None: every stage on the model's own.  The stages' optima are not the truth's
        truncations anyway (at degree 10 they end at residuals of 1e-4 … 1e-3).  For the blob at La = 15 with
        K = 704 (Lb 42) the bases run from degree 7 (16 eigenvalues) to 40 (576), and the stages up to 400
        eigenvalues were done 2.6 min after launch (choosing the bases, 18 s, included) against 16.5 min on Lb
        (one start each, one core each, side by side; benchmarks/results/bench_stage_bases.json).  On small
        bases the gain is small: the blob at Lb 20, La 6, K 120, 8 of 8 starts at a median 19 s against 23 s;
        degree 10 at Lb 24, K 300, 4 of 8 at 244 s against 6 of 8 at 241 s, measured again 5 of 8 at 262 s
        against 5 of 8 at 270 s (the stages themselves 29 s against 46 s; the paths differ, and which starts
        succeed is fragile; benchmarks/results/bench_global_search.json, bench_hop_anatomy.json of commit
        ecb52d3, before the hops screened with plain LM).
    starts : int
        Number of random symmetry-broken starts.
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
        Initial Levenberg–Marquardt damping μ (relative to diag(JᵀJ)); large values make the first steps short
        gradient-like steps.
    lm_acceleration : bool
        Levenberg–Marquardt adds the geodesic acceleration of each step (Transtrum & Sethna): one extra solve per
        trial, of the eigenvalues alone, and the fit follows curved valleys where the linear model alone crawls.
        On the blob at La = 15 from 1e-3 off the truth (benchmarks/results/bench_convergence.json) it took the
        relative residual to 3e-15 in 28 iterations at K = 600 (Lb 40), where plain LM was at 3e-9 after 60.
    basin_hops : int
        After the last stage, and after every stage with :attr:`Stage.hops` (in the default degree ramp of a fit
        above degree 6, the stage of degree 6), while the relative residual is above success_tol, up to this many
        basin hops (0: none).  A hop first tries the model's cheap moves (power-preserving moves of one degree
        block: half-turns about the axes, signs of odd blocks), and when none of them lowers the energy, the grid
        moves of ``hop_grid``.  Each move tried gets ``hop_iter`` iterations, and the first that lowers the energy
        is refitted to convergence.  The hops stop at success, after ``basin_hops`` accepted moves, or when no move
        lowers the energy, so a larger budget costs only the starts that are still improving.  Not checkpointed (a
        run resumed after the last stage repeats it).  On the blob with :func:`~shspec.inverse.degree_ramp`, 4 hops
        (hop_iter 15) raised the successes from 2 to 7 of 8 starts.  At degree 10 (Lb 24, K = 300, the capped
        degree ramp) the hops made every success: 0 of 12 starts without them, 2 of 12 with 4 and 5 of 8 with 12
        (cheap moves only; the successes took 1 to 10 accepted hops), 6 of 8 with 12 and ``hop_grid``, at a median
        241 s per start (benchmarks/results/bench_global_search.json).  On the blob (Lb 20, La 6, K = 120) the
        defaults made 8 of 8 succeed (7 of 8 with 4 cheap hops).
    hop_iter : int
        Iterations given to each move of a basin hop.  These short refits run plain LM (without
        ``lm_acceleration``), which reaches the same energy in them: on 12 moves from a degree-10 local minimum
        (Lb 24, K = 300) the energies after 15 iterations agreed to 2-3 % (most to all printed digits) at 0.7× the
        time; the accepted move's refit to convergence uses ``lm_acceleration``.
    hop_extend : int
        A screening refit still above the current energy at ``hop_iter`` iterations goes on, up to this many
        iterations in all, while its energy keeps falling fast (by 10 % over the last 3 iterations); set it to
        ``hop_iter`` for none.  In failed degree-10 states (benchmarks/bench_hop_screening.py) the moves that fall
        back into the state's own minimum reach its energy within a few iterations and stop there, while the moves
        that leave it were still falling at 15 iterations (a probe: 3 of 12 continued crossed it at 18 to 20).  At
        degree 10 (Lb 24, K = 300, 8 starts on an AMD EPYC; bench_hop_anatomy.json) 45 made 7 succeed and 3 of
        the first four, 15 made 6 and 2, at a median 246 s per start either way.
    hop_grid : bool
        When no cheap move lowers the energy, try every degree block turned by the 23 rotations of the octahedral
        group (and, for odd blocks, by the 24 improper ones): :meth:`~shspec.spectral_model.SpectralModel.escape_moves`
        with ``newest=True`` at each level, 303 moves at degree 10.  In the degree-10 setting above it rescued one
        of the 3 starts whose cheap moves were exhausted with ``hop_tries`` 48, two of them when every grid move
        could be refitted (a probe; the failing one then spent 8 minutes in one hop).
    hop_tries : int
        At most this many moves of a hop are refitted, those of lowest energy before any refit (one eigensolve
        each); it bounds the cost of a hop that finds nothing.  A larger value only adds successes: the moves are
        tried in the same order and the first that lowers the energy is taken, so a start follows the same path
        until a smaller cap would have given up.  At degree 10 (Lb 24, K = 300, 16 starts of seed 0;
        benchmarks/results/bench_hop_anatomy.json of commit c851d30) 144 made 12 of 16 starts succeed at a median
        135 s per start (the failures 230–342 s), 48 made 10 of 16 at 106 s (the failures 105–154 s).
    orient_blocks : bool
        After each stage that first fits a new level (a new degree block), try the model's orientations of that
        block relative to the ones fitted before (:meth:`~shspec.spectral_model.SpectralModel.escape_moves` with
        ``newest=True``: an octahedral grid of rotations, and reflections of odd blocks), each with ``hop_iter``
        iterations, and go on from the best that lowers the energy.  Default off (see the benchmark).
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
        Print one line per stage and a progress line per iteration on stderr.
    """

    optimizer: str | None = None
    weights: str = "relative"
    reg: float = 0.0
    area: str = "auto"
    schedule: tuple | None = None
    stage_basis_tol: float | None = 1e-5
    starts: int = 4
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
    progress: bool = False

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
        check_int(self.starts, "starts", minimum=1)
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
        for name in ("hop_grid", "orient_blocks"):
            if not isinstance(getattr(self, name), bool):
                raise InvalidArgumentError(f"{name} must be a bool, got {getattr(self, name)!r}")
        check_int(self.checkpoint_every, "checkpoint_every", minimum=0)
        if self.checkpoint_every and not self.checkpoint_path:
            raise InvalidArgumentError("checkpoint_every > 0 needs a checkpoint_path")


def fits_area(options: FitOptions, target) -> bool:
    """Whether a fit frees the area: ``area="fit"``, or ``"auto"`` with a target whose area is unknown."""
    return options.area == "fit" or (options.area == "auto" and target.area is None)


