"""Results of the inverse solver, as small frozen dataclasses: one start (:class:`StartResult`) and a whole fit
(:class:`FitResult`: every start and the distinct local solutions among them).

They hold data and what is derived from it (the best start, its factor, identifiability and alignment);
:func:`~shspec.inverse.output.write_result` writes them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..errors import NotPositiveError
from .align import align
from .identifiability import identifiability
from .options import FitOptions, fits_area

__all__ = ["StartResult", "FitResult"]


@dataclass(frozen=True)
class StartResult:
    """The outcome of one start.

    Attributes
    ----------
    index : int
        Start number i (its random start is drawn from ``default_rng([seed, i])``).
    params : (nparams,) array
        Final parameters: harmonic coefficients a of ρ (flat, l*l + l + m) or per-vertex factors c.
    energy : float
        Final energy (with the regularizer).
    relative_residual : float
        max_i |λ_i − λ*_i| / λ*_i over the matched eigenvalues, i ≥ 1.
    iterations : int
        Iterations over all stages.
    seconds : float
        Wall time of this start.
    status : str
        Why the last stage stopped ("residual_tol", "step_tol", "energy_tol", "max_iter", "interrupted", ...), or
        "abandoned" (:mod:`~shspec.inverse.race`; such starts are not part of a :class:`FitResult`).
    history : (iterations + 1, 3) array
        Columns: stage index, energy, relative residual, after each iteration (row 0: the start).
    eigenvalues : (k,) array
        Final matched eigenvalues.
    success : bool
        relative_residual ≤ :attr:`FitOptions.success_tol`.
    work : float
        The start's work (:mod:`~shspec.inverse.race`): iterations and move solves weighted by their stage's cost,
        the same on any machine; it decides which success a fit reports.

    Examples
    --------
    >>> from shspec import HarmonicModel
    >>> from shspec.fitting import blob_factor, harmonic_target
    >>> from shspec.inverse import FitOptions, fit
    >>> result = fit(harmonic_target(blob_factor().truncated(2), 10, 16), HarmonicModel(10, 2),
    ...              FitOptions(starts=1, max_iter=20, basin_hops=0, progress=False))
    >>> start = result.starts[0]
    >>> start.index, start.status, start.success, start.relative_residual < 1e-10
    (0, 'residual_tol', True, True)
    """

    index: int
    params: np.ndarray
    energy: float
    relative_residual: float
    iterations: int
    seconds: float
    status: str
    history: np.ndarray = field(repr=False)
    eigenvalues: np.ndarray = field(repr=False)
    success: bool = False
    work: float = 0.0


@dataclass(frozen=True)
class FitResult:
    """Result of :func:`~shspec.inverse.fit`.

    Attributes
    ----------
    starts : list of StartResult
        Every start, in order of their index.
    solutions : list of int
        Indices into ``starts`` of the distinct local solutions, best (lowest energy) first.
    target : Target
        What was fitted.
    options : FitOptions
    model : SpectralModel
        The discretization whose parameters ``params`` are.
    seconds : float
        Time spent in the starts, summed over them and over every process of a resumed fit.
    interrupted : bool
        The fit was stopped by Ctrl-C; ``starts`` holds what was done, the best state included.
    plan : dict
        What the fit's plan chose and why, JSON-ready (:meth:`shspec.fitting.FitPlan.record`); part of the
        summary.  Empty for a fit that was not planned.

    Examples
    --------
    >>> from shspec import HarmonicModel
    >>> from shspec.fitting import blob_factor, harmonic_target
    >>> from shspec.inverse import FitOptions, fit
    >>> target = harmonic_target(blob_factor().truncated(2), 10, 16)
    >>> result = fit(target, HarmonicModel(10, 2), FitOptions(starts=1, max_iter=20, basin_hops=0, progress=False))
    >>> result.success_count, result.best.index, result.factor().lmax
    (1, 0, 2)
    >>> result.alignment().relative_error < 1e-8        # against the target's truth, after Moebius and O(3)
    True
    """

    starts: list
    solutions: list
    target: object
    options: FitOptions
    model: object
    seconds: float
    interrupted: bool = False
    plan: dict = field(default_factory=dict, repr=False)

    @property
    def best(self) -> StartResult:
        """The start of lowest energy."""
        return self.starts[self.solutions[0]]

    @property
    def success_count(self) -> int:
        """Number of starts with a final relative residual ≤ success_tol."""
        return sum(s.success for s in self.starts)

    def factor(self):
        """The best solution as a harmonic :class:`~shspec.sphere.factor.ConformalFactor` (a mesh fit's factors
        expanded in harmonics, :meth:`~shspec.spectral_model.SpectralModel.to_factor`)."""
        return self.model.to_factor(self.best.params)

    def identifiability(self):
        """What the matched eigenvalues determine at the best solution
        (:func:`~shspec.inverse.identifiability.identifiability`, with its final residuals), and whether that
        solution converged: where it did not, its error is reported as unknown.  Computed once."""
        if "_identifiability" not in self.__dict__:
            best = self.best
            k = best.eigenvalues.size
            ref = self.target.eigenvalues[:k]
            rel = np.zeros(k)
            rel[1:] = (best.eigenvalues[1:] - ref[1:]) / ref[1:]
            # frozen: the memo goes straight into the instance dict (it is derived, not state)
            errors = self.target.errors
            ident = identifiability(self.model, best.params, k, fit_area=fits_area(self.options, self.target),
                                    residuals=rel, noise=None if errors is None else np.r_[1.0, errors[1:k] / ref[1:]])
            object.__setattr__(self, "_identifiability", dataclasses.replace(ident, converged=bool(best.success)))
        return self.__dict__["_identifiability"]

    def alignment(self):
        """The best solution, as harmonic ρ, aligned with the target's truth up to Möbius and O(3)
        (:func:`~shspec.inverse.align.align`); None when the target knows no truth.  Computed once (an alignment
        takes seconds).

        Raises
        ------
        NotPositiveError
            The solution's harmonic expansion or the truth is not positive, so it cannot be Möbius-centred (a
            low-degree expansion of extreme per-vertex factors can dip below 0).
        """
        if "_alignment" not in self.__dict__:
            try:
                value = None if self.target.truth is None else align(self.factor(), self.target.truth)
            except NotPositiveError as exc:
                value = exc
            object.__setattr__(self, "_alignment", value)
        value = self.__dict__["_alignment"]
        if isinstance(value, NotPositiveError):
            raise value
        return value
