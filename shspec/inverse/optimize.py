"""Optimizers of the fit energy that keep ρ a metric and can be stopped and resumed exactly.

All four work on an :class:`~shspec.inverse.energy.Objective` over the free parameters and take one iteration per
:meth:`step`.  Their whole state is a dict of arrays (:meth:`state`), so a checkpoint taken between two steps
resumes exactly (bit for bit unless a model's warm-started eigensolve was used just before the checkpoint: the
resumed run solves that point cold, equal to ~1e-15); that is why they are written here rather than taken from
``scipy.optimize``, whose internal state cannot be saved.

Positivity.  A trial point where ρ ≤ 0 somewhere (the model raises :class:`NotPositiveError`) counts as infinitely
bad: line searches halve the step, Levenberg–Marquardt rejects it and raises its damping.  Every accepted point is a
valid metric, so no fit ever crashes on it.

Levenberg–Marquardt ("lm") minimizes ½‖r‖² with the analytic Jacobian of the residuals (one quadratic form per
eigenvalue), taking the damped step (JᵀJ + μ diag(JᵀJ)) δ = −Jᵀr from an SVD, with Nielsen's update of μ and
geodesic acceleration.  Near a zero-residual solution it converges quadratically.  It follows the *sorted* eigenvalues: where two of them cross, λ_i is only Lipschitz and
the Jacobian jumps, which costs a few rejected steps; fine away from exact degeneracy (random starts are far from
the round sphere, whose multiplets are exactly degenerate).  L-BFGS ("lbfgs"), BFGS ("bfgs") and gradient descent
("gd") use the adjoint gradient only, with a backtracking Armijo line search.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from ..core.damping import nielsen_update
from ..errors import InvalidArgumentError, NotPositiveError
from .energy import Evaluation, Objective
from .options import FitOptions

__all__ = ["make_optimizer", "LevenbergMarquardt", "LBFGS", "BFGS", "GradientDescent"]

#: Consecutive accepted steps with a relative energy decrease below energy_tol before stopping.
_FLAT_STEPS = 5
#: Halvings of a line search (or rejections of LM) before giving up: 2⁻⁴⁰ is below any useful step.
_MAX_BACKTRACK = 40
_ARMIJO = 1e-4


class _Optimizer:
    """Shared iteration bookkeeping: current point, evaluation, stopping tests, state save and load."""

    name = ""
    _needs_jacobian = False

    def __init__(self, objective: Objective, x0, options: FitOptions, state: dict | None = None):
        if not isinstance(objective, Objective):
            raise InvalidArgumentError(f"objective must be an Objective, got {type(objective).__name__}")
        if not isinstance(options, FitOptions):
            raise InvalidArgumentError(f"options must be FitOptions, got {type(options).__name__}")
        self.objective = objective
        self.options = options
        self.status: str | None = None
        self.iteration = 0
        self._flat = 0
        if state is not None:
            self._load(state)
            x0 = state["x"]
        self.x = np.array(x0, dtype=float)
        if self.x.shape != (objective.nfree,):
            raise InvalidArgumentError(f"x0 must have shape ({objective.nfree},), got {self.x.shape}")
        # The start itself must be a metric: a start that is not is a caller error, not a bad trial step.
        self.ev: Evaluation = objective.evaluate(self.x, jacobian=self._needs_jacobian)
        if state is None:
            self._init()
        self._check_converged()

    # -- state ----------------------------------------------------------------------------------------------------

    def state(self) -> dict:
        """Everything needed to resume: arrays and scalars keyed by name."""
        out = {"x": self.x.copy(), "iteration": self.iteration, "flat": self._flat}
        out.update(self._extra_state())
        return out

    def _load(self, state: dict) -> None:
        self.iteration = int(state["iteration"])
        self._flat = int(state["flat"])
        self._load_extra(state)

    def _init(self) -> None:
        pass

    def _extra_state(self) -> dict:
        return {}

    def _load_extra(self, state: dict) -> None:
        pass

    # -- iteration ------------------------------------------------------------------------------------------------

    def _try(self, x, jacobian: bool = False) -> Evaluation | None:
        try:
            return self.objective.evaluate(x, jacobian=jacobian)
        except NotPositiveError:
            return None

    def _check_converged(self) -> bool:
        if self.ev.relative_residual <= self.options.residual_tol or self.ev.energy == 0.0:
            self.status = "residual_tol"
        return self.status is not None

    def _accept(self, x_new, ev_new: Evaluation) -> None:
        opt = self.options
        dx = np.linalg.norm(x_new - self.x)
        decrease = self.ev.energy - ev_new.energy
        self._flat = self._flat + 1 if decrease <= opt.energy_tol * self.ev.energy else 0
        self.x, self.ev = x_new, ev_new
        if self._check_converged():
            return
        if dx <= opt.step_tol * max(np.linalg.norm(x_new), 1e-300):
            self.status = "step_tol"
        elif self._flat >= _FLAT_STEPS:
            self.status = "energy_tol"

    def step(self) -> None:
        """One iteration; sets :attr:`status` when the optimizer stops."""
        if self.status is not None:
            return
        self.iteration += 1
        self._step()

    def _step(self) -> None:
        raise NotImplementedError

    def _line_search(self, direction, t0: float) -> tuple[np.ndarray, Evaluation, float] | None:
        """Backtracking Armijo search along a descent direction: (new x, its evaluation, step), or None."""
        slope = float(self.ev.gradient @ direction)
        if not slope < 0:
            return None
        t = t0
        for _ in range(_MAX_BACKTRACK):
            x_new = self.x + t * direction
            ev = self._try(x_new)
            if ev is not None and ev.energy <= self.ev.energy + _ARMIJO * t * slope:
                return x_new, ev, t
            t *= 0.5
        return None


class LevenbergMarquardt(_Optimizer):
    """Levenberg–Marquardt on the residuals with Marquardt's column scaling, Nielsen's damping update and, by
    default, geodesic acceleration.

    Each iteration takes one SVD of the column-scaled Jacobian J D⁻¹ = U S Vᵀ (D = the column norms) and solves
    every trial damping μ from it: the velocity v = −D⁻¹ V S(S² + μ)⁻¹ Uᵀ r.  The normal equations JᵀJ would square
    a condition number that reaches 1e9 at the study's setting (La = 15, 256 eigenvalues).

    Geodesic acceleration (``FitOptions.lm_acceleration``): the second directional derivative r_vv is taken by a
    finite difference along v (one extra solve, of the eigenvalues alone), a = −D⁻¹ V S(S² + μ)⁻¹ Uᵀ r_vv, and the
    step is v + a/2 when 2‖Da‖ ≤ α‖Dv‖ (α = 0.75), else v alone.  Near the solutions of these fits the residual
    depends on the weak directions more at second order than at first, so the linear model alone gains a few per
    cent per iteration there.  M. K. Transtrum, J. P. Sethna, "Improvements to the Levenberg–Marquardt algorithm
    for nonlinear least-squares minimization", arXiv:1201.5885 (2012).
    """

    name = "lm"
    _needs_jacobian = True
    #: Finite-difference step of r_vv, relative to the velocity (Transtrum & Sethna's choice).
    _FD_STEP = 0.1
    #: Largest accepted ratio 2‖a‖/‖v‖ of acceleration to velocity.
    _ALPHA = 0.75

    def _init(self) -> None:
        self.mu = self.options.lm_damping
        self.nu = 2.0

    def _extra_state(self) -> dict:
        return {"mu": self.mu, "nu": self.nu}

    def _load_extra(self, state: dict) -> None:
        self.mu = float(state["mu"])
        self.nu = float(state["nu"])

    def _acceleration(self, v, jv, solve, d):
        """a for velocity v (J v = jv), the damped solve of the current μ and column scale d, or None where it does not
        apply (a trial that is not a metric, or an acceleration too large for the second-order model)."""
        h = self._FD_STEP
        try:
            trial = self.objective.values(self.x + h * v)  # only its residuals are needed
        except NotPositiveError:
            return None
        rvv = (2.0 / h) * ((trial.residuals - self.ev.residuals) / h - jv)
        rvv[self.objective.pair_rows] = 0.0  # taken as linear: values() has no eigenvectors to give them
        a = solve(rvv)
        ok = 2.0 * np.linalg.norm(a * d) <= self._ALPHA * np.linalg.norm(v * d)
        return a if ok else None

    def _step(self) -> None:
        J, r = self.ev.jacobian, self.ev.residuals
        # Marquardt's scaling makes μ dimensionless; the floor keeps parameters the residuals do not see (yet) from
        # dividing by zero.
        d = np.sqrt(np.einsum("ij,ij->j", J, J))
        d = np.maximum(d, 1e-12 * max(np.max(d), 1e-300))
        try:
            U, s, Vt = scipy.linalg.svd(J / d, full_matrices=False, check_finite=False, lapack_driver="gesdd")
        except np.linalg.LinAlgError:  # pragma: no cover - gesdd's rare failure to converge
            U, s, Vt = scipy.linalg.svd(J / d, full_matrices=False, check_finite=False, lapack_driver="gesvd")
        for _ in range(_MAX_BACKTRACK):
            filt = s / (s * s + self.mu)

            def solve(rhs):
                return -(Vt.T @ (filt * (U.T @ rhs))) / d

            v = solve(r)
            jv = J @ v
            predicted = -(r @ jv) - 0.5 * (jv @ jv)
            step = v
            if self.options.lm_acceleration:
                a = self._acceleration(v, jv, solve, d)
                if a is not None:
                    step = v + 0.5 * a
            ev = self._try(self.x + step, jacobian=True)
            gain = (self.ev.energy - ev.energy) / predicted if ev is not None and predicted > 0 else float("nan")
            self.mu, self.nu = nielsen_update(self.mu, self.nu, gain)
            if gain > 0:
                self._accept(self.x + step, ev)
                return
        self.status = "stalled"


class LBFGS(_Optimizer):
    """Limited-memory BFGS (two-loop recursion) with a positivity-safeguarded Armijo line search."""

    name = "lbfgs"

    def _init(self) -> None:
        self.S = np.zeros((0, self.objective.nfree))
        self.Y = np.zeros((0, self.objective.nfree))

    def _extra_state(self) -> dict:
        return {"S": self.S.copy(), "Y": self.Y.copy()}

    def _load_extra(self, state: dict) -> None:
        self.S = np.array(state["S"], dtype=float)
        self.Y = np.array(state["Y"], dtype=float)

    def _direction(self, g) -> np.ndarray:
        q = g.copy()
        alphas = []
        for s, y in zip(self.S[::-1], self.Y[::-1]):
            a = (s @ q) / (y @ s)
            alphas.append(a)
            q -= a * y
        if len(self.S):
            q *= (self.S[-1] @ self.Y[-1]) / (self.Y[-1] @ self.Y[-1])
        else:
            # First step: a move of about 1 % of the parameters, whatever the gradient's scale.
            q *= 0.01 * max(np.linalg.norm(self.x), 1e-12) / max(np.linalg.norm(g), 1e-300)
        for (s, y), a in zip(zip(self.S, self.Y), reversed(alphas)):
            b = (y @ q) / (y @ s)
            q += (a - b) * s
        return -q

    def _step(self) -> None:
        g = self.ev.gradient
        found = self._line_search(self._direction(g), 1.0)
        if found is None and len(self.S):
            # A stale curvature model: forget it and retry along the scaled gradient.
            self._init()
            found = self._line_search(self._direction(g), 1.0)
        if found is None:
            self.status = "line_search"
            return
        x_new, ev, _ = found
        s, y = x_new - self.x, ev.gradient - g
        # Keep only pairs of positive curvature: the two-loop recursion then stays positive definite.
        if s @ y > 1e-12 * np.linalg.norm(s) * np.linalg.norm(y):
            self.S = np.vstack([self.S, s])[-self.options.lbfgs_memory:]
            self.Y = np.vstack([self.Y, y])[-self.options.lbfgs_memory:]
        self._accept(x_new, ev)


class BFGS(_Optimizer):
    """Dense BFGS on the inverse Hessian with the same safeguarded line search as :class:`LBFGS`."""

    name = "bfgs"

    def _init(self) -> None:
        self.H = np.zeros((0, 0))

    def _extra_state(self) -> dict:
        return {"H": self.H.copy()}

    def _load_extra(self, state: dict) -> None:
        self.H = np.array(state["H"], dtype=float)

    def _step(self) -> None:
        g = self.ev.gradient
        if self.H.size:
            direction = -self.H @ g
        else:
            direction = -0.01 * max(np.linalg.norm(self.x), 1e-12) / max(np.linalg.norm(g), 1e-300) * g
        found = self._line_search(direction, 1.0)
        if found is None and self.H.size:
            self._init()
            found = self._line_search(-0.01 * max(np.linalg.norm(self.x), 1e-12)
                                      / max(np.linalg.norm(g), 1e-300) * g, 1.0)
        if found is None:
            self.status = "line_search"
            return
        x_new, ev, _ = found
        s, y = x_new - self.x, ev.gradient - g
        sy = s @ y
        if sy > 1e-12 * np.linalg.norm(s) * np.linalg.norm(y):
            if not self.H.size:
                # Shanno–Phua scaling of the first inverse Hessian.
                self.H = (sy / (y @ y)) * np.eye(s.size)
            rho = 1.0 / sy
            Hy = self.H @ y
            self.H = (self.H - rho * (np.outer(s, Hy) + np.outer(Hy, s))
                      + (rho * rho * (y @ Hy) + rho) * np.outer(s, s))
        self._accept(x_new, ev)


class GradientDescent(_Optimizer):
    """Gradient descent with an Armijo line search whose first trial doubles the last accepted step."""

    name = "gd"

    def _init(self) -> None:
        g = self.ev.gradient
        self.t = 0.01 * max(np.linalg.norm(self.x), 1e-12) / max(np.linalg.norm(g), 1e-300)

    def _extra_state(self) -> dict:
        return {"t": self.t}

    def _load_extra(self, state: dict) -> None:
        self.t = float(state["t"])

    def _step(self) -> None:
        found = self._line_search(-self.ev.gradient, 2.0 * self.t)
        if found is None:
            self.status = "line_search"
            return
        x_new, ev, self.t = found
        self._accept(x_new, ev)


_CLASSES = {"lm": LevenbergMarquardt, "lbfgs": LBFGS, "bfgs": BFGS, "gd": GradientDescent}


def make_optimizer(name: str, objective: Objective, x0, options: FitOptions, state: dict | None = None):
    """The optimizer ``name`` ("lm", "lbfgs", "bfgs", "gd") started at x0 (nfree,), or resumed from ``state``.

    Raises
    ------
    InvalidArgumentError
        For an unknown name or a start of the wrong shape.
    NotPositiveError
        If the start itself is not a metric.
    """
    if name not in _CLASSES:
        raise InvalidArgumentError(f"unknown optimizer {name!r}; choose one of {tuple(_CLASSES)}")
    return _CLASSES[name](objective, x0, options, state)
