"""Fit schedules: the stages a start runs through, from coarse to fine.

A :class:`Stage` fixes the factor's degree (harmonic fits), the number of matched eigenvalues, its iterations and
whether basin hops run at its end; each stage starts from where the previous one stopped.  :func:`degree_ramp`,
:func:`numeig_ramp` and :func:`default_schedule` build the usual ones; :func:`parse_schedule` reads the command
line's syntax.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..core.checks import check_int
from ..errors import InvalidArgumentError
from ..spectral_model import SpectralModel

__all__ = ["Stage", "parse_schedule", "numeig_ramp", "degree_ramp", "parity_ramp", "default_schedule",
           "default_hop_degree", "DEFAULT_STAGE_MAX_ITER", "DEFAULT_HOP_DEGREE", "HOP_FIT_DEGREE",
           "PARITY_FIT_DEGREE", "DEFAULT_START_BUDGET", "default_start_budget"]


@dataclass(frozen=True)
class Stage:
    """One stage of a fit schedule.

    Attributes
    ----------
    lmax_factor : int or None
        Degree La of ρ fitted in this stage (harmonic fits only); None: the model's full La.  Coefficients of
        higher degree stay 0; the ones this stage adds receive a small seeded random perturbation, because at an
        even ρ the gradient along odd degrees is exactly 0 (the parity saddle, :doc:`/theory`).
    numeig : int or None
        Number of eigenvalues matched (λ₀ = 0 included); None: all of the target's.
    max_iter : int or None
        Iterations of this stage; None: :attr:`FitOptions.max_iter`.
    hops : bool
        Run the basin hops (:attr:`FitOptions.basin_hops`) at the end of this stage too, not only after the last
        one: a global search while the problem is small and its moves are cheap (see :func:`degree_ramp`).
    even : bool
        Hold the odd parameters at 0 (harmonic models: the odd degrees of ρ, or of log ρ), so that ρ is even under
        the antipodal map; the first stage after an even one gives them a small seeded random perturbation.  The
        odd degrees move the spectrum only at second order, so the even part of ρ is fitted first with little bias
        from them (see :func:`parity_ramp`).

    Examples
    --------
    >>> from shspec.inverse import Stage
    >>> Stage(lmax_factor=6, numeig=64, hops=True)
    Stage(lmax_factor=6, numeig=64, max_iter=None, hops=True, even=False)
    """

    lmax_factor: int | None = None
    numeig: int | None = None
    max_iter: int | None = None
    hops: bool = False
    even: bool = False

    def __post_init__(self):
        check_int(self.lmax_factor, "Stage.lmax_factor", allow_none=True, minimum=0)
        check_int(self.numeig, "Stage.numeig", allow_none=True, minimum=2)
        check_int(self.max_iter, "Stage.max_iter", allow_none=True, minimum=1)
        for name in ("hops", "even"):
            if not isinstance(getattr(self, name), bool):
                raise InvalidArgumentError(f"Stage.{name} must be True or False, got {getattr(self, name)!r}")


def parse_schedule(text: str) -> tuple[Stage, ...]:
    """Stages from the command-line syntax ``"2,4,8,15"`` (degrees) or ``"2:40,4:80,8"`` (degree:numeig); an
    entry ending in ``h`` (``"6:64h"``) runs the basin hops at the end of its stage (:attr:`Stage.hops`), one ending
    in ``e`` (``"8:64e"``) holds the odd degrees at 0 (:attr:`Stage.even`), ``eh`` both.

    Raises
    ------
    InvalidArgumentError
        If an entry is not ``L`` or ``L:K`` with integers, optionally followed by ``e``, ``h`` or ``eh``.

    Examples
    --------
    >>> from shspec.inverse import parse_schedule
    >>> [(s.lmax_factor, s.numeig, s.hops) for s in parse_schedule("2,4,6")]
    [(2, None, False), (4, None, False), (6, None, False)]
    >>> [(s.lmax_factor, s.numeig, s.hops) for s in parse_schedule("6:16,6:64h")]   # L:K, h: hop there
    [(6, 16, False), (6, 64, True)]
    >>> [(s.numeig, s.even) for s in parse_schedule("8:64e,8:100")]   # e: odd degrees held at 0
    [(64, True), (100, False)]
    """
    if not isinstance(text, str) or not text.strip():
        raise InvalidArgumentError(f"a schedule is a comma-separated list like '2,4,8,15', got {text!r}")
    stages = []
    for item in text.split(","):
        entry = item.strip()
        hops = entry.endswith("h")
        even = entry.removesuffix("h").endswith("e")
        parts = entry.removesuffix("h").removesuffix("e").split(":")
        try:
            nums = [int(p) for p in parts]
        except ValueError:
            raise InvalidArgumentError(f"schedule entry {item!r} is not 'L' or 'L:K' with integers "
                                       "(optionally followed by 'e', 'h' or 'eh')") from None
        if len(nums) not in (1, 2):
            raise InvalidArgumentError(f"schedule entry {item!r} is not 'L' or 'L:K'")
        stages.append(Stage(lmax_factor=nums[0], numeig=nums[1] if len(nums) == 2 else None, hops=hops, even=even))
    return tuple(stages)



#: Iterations of every stage but the last in the default degree ramp (see :func:`degree_ramp`).
DEFAULT_STAGE_MAX_ITER = 40

#: The degree whose stage of the default degree ramp hops (see :func:`degree_ramp`) in fits of degree
#: :data:`HOP_FIT_DEGREE` or more: there the hops succeed on their own and a round of moves is cheap (the design
#: notes have the numbers).
DEFAULT_HOP_DEGREE = 6

#: The smallest fit degree whose default degree ramp hops at :data:`DEFAULT_HOP_DEGREE`.  At degree 8 the hops of
#: the degree-6 stage cannot reach a zero residual and only cost time (measured: :doc:`/notes`).
HOP_FIT_DEGREE = 10

#: The smallest fit degree whose default schedule of an exact spectrum is the :func:`parity_ramp` (up to
#: :data:`HOP_FIT_DEGREE`, where the degree ramp with its degree-6 hops stays, as the parity ramp was not measured
#: there).  At degree 8 the degree ramp's truncated stages pull ρ of slowly falling degree powers (l⁻¹, l⁻¹·⁵) out
#: of their basin (:doc:`/notes`).
PARITY_FIT_DEGREE = 8


def numeig_ramp(numeig: int, lmax_factor: int | None = None, first: int = 16) -> tuple[Stage, ...]:
    """A schedule that matches more and more eigenvalues: k = 16, 36, 64, ... ((2j)² up to ``numeig``), then all.

    Raising the number of matched eigenvalues in steps that end at whole sphere clusters ((l+1)² eigenvalues)
    escapes the local minima of a direct fit more often (measured: :doc:`/notes`): the low eigenvalues fix
    the coarse shape first.

    Parameters
    ----------
    numeig : int
        Eigenvalues of the last stage (≥ 2).
    lmax_factor : int, optional
        Degree of every stage (harmonic fits); None: the model's.
    first : int
        Eigenvalues of the first stage.

    Examples
    --------
    >>> from shspec.inverse import numeig_ramp
    >>> [s.numeig for s in numeig_ramp(40)]
    [16, 36, 40]
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
        them buys little.
    hop_degree : int, optional
        The stage that raises the degree to this one runs to convergence (``FitOptions.max_iter``) and then the
        basin hops (:attr:`Stage.hops`): the global search on the low degrees while their stage is small, before
        the higher degrees are added.  None: hops after the last stage only.  No stage hops if that stage would
        match ``numeig`` eigenvalues or more.  Fits of degree 10 or more hop at degree 6 by default
        (:data:`DEFAULT_HOP_DEGREE`, :data:`HOP_FIT_DEGREE`).  The hops cost time where the stage cannot reach a
        zero residual (a regularized fit, a ρ of higher degree).

    Examples
    --------
    >>> from shspec.inverse import degree_ramp
    >>> [(s.lmax_factor, s.numeig) for s in degree_ramp(40, 6)]   # (L + 1)^2 eigenvalues per degree, then all
    [(2, 16), (3, 25), (4, 36), (6, 40)]
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


def parity_ramp(numeig: int, lmax_factor: int | None = None, first: int = 36) -> tuple[Stage, ...]:
    """A schedule that fits the even part of ρ first: the even degrees up to La on a ramp of eigenvalues (the
    squares of even numbers from ``first`` up, then ``numeig``; odd degrees held at 0, :attr:`Stage.even`), then
    every degree to all ``numeig`` eigenvalues.

    A ramp of degrees biases every stage but the last: the degrees it leaves out move the low eigenvalues at first
    order.  An odd degree moves them only at second order (:doc:`/theory`), so the even stages see every degree
    that acts at first order, and the odd ones then start from small random values (the parity saddle) beside an
    even part already near the truth's.

    Parameters
    ----------
    numeig : int
        Eigenvalues of the last even stage and of the final one.
    lmax_factor : int, optional
        Degree of every stage; None: the model's.
    first : int
        Eigenvalues of the first stage.

    Examples
    --------
    >>> from shspec.inverse import parity_ramp
    >>> [(s.numeig, s.even) for s in parity_ramp(120, 8)]
    [(36, True), (64, True), (100, True), (120, True), (120, False)]
    """
    even = numeig_ramp(numeig, lmax_factor, first)
    return (*(replace(st, even=True) for st in even), Stage(lmax_factor=lmax_factor, numeig=int(numeig)))


def default_schedule(model: SpectralModel, numeig: int, exact: bool = True) -> tuple[Stage, ...]:
    """The schedule a fit runs when its options name none: :func:`degree_ramp` over the model's levels (harmonic
    models: the factor's degree); for an ``exact`` target (no errors) :func:`parity_ramp` at degrees
    :data:`PARITY_FIT_DEGREE` up to :data:`HOP_FIT_DEGREE` (excluded), where it was measured; :func:`numeig_ramp` for
    models without levels (meshes).

    The stages of the degree ramp but the last are capped at :data:`DEFAULT_STAGE_MAX_ITER` iterations; how often
    each schedule succeeds, measured, is in the design notes (:doc:`/notes`).

    Examples
    --------
    >>> from shspec import HarmonicModel
    >>> from shspec.inverse import default_schedule
    >>> [(s.lmax_factor, s.numeig) for s in default_schedule(HarmonicModel(12, 6), 40)][:2]   # the degree ramp
    [(2, 16), (3, 25)]
    >>> [(s.numeig, s.even) for s in default_schedule(HarmonicModel(12, 8), 100)]   # degree 8: the parity ramp
    [(36, True), (64, True), (100, True), (100, False)]
    """
    levels = model.levels()
    if not levels:
        return numeig_ramp(numeig)
    if _parity_default(model, exact):
        return parity_ramp(numeig, levels[-1])
    return degree_ramp(numeig, levels[-1], stage_max_iter=DEFAULT_STAGE_MAX_ITER,
                       hop_degree=default_hop_degree(levels[-1]))


#: The work (iterations of the search stage, :attr:`FitOptions.start_budget`) after which a start of the default
#: parity ramp that has not succeeded ends, so that the next start runs: its successes on the many-law benchmark
#: took at most 1224, the failures ran on in their hops up to the goal's time (:doc:`/notes`).
DEFAULT_START_BUDGET = 1500


def default_start_budget(model: SpectralModel, exact: bool = True) -> int:
    """The start budget of a fit that runs its :func:`default_schedule` and whose options name none:
    :data:`DEFAULT_START_BUDGET` where that is the :func:`parity_ramp` (``exact``: a target without errors), 0 (none)
    elsewhere, where no budget was measured.

    Examples
    --------
    >>> from shspec import HarmonicModel
    >>> from shspec.inverse.schedule import default_start_budget
    >>> default_start_budget(HarmonicModel(12, 8)), default_start_budget(HarmonicModel(12, 6))
    (1500, 0)
    """
    return DEFAULT_START_BUDGET if _parity_default(model, exact) else 0


def _parity_default(model: SpectralModel, exact: bool) -> bool:
    """Whether the default schedule of ``model`` is the parity ramp: an exact target (the many-law benchmark's
    spectra; a mesh's or a noisy spectrum's fit keeps the degree ramp it was measured with), a model with parity,
    of a degree from PARITY_FIT_DEGREE up to HOP_FIT_DEGREE (excluded)."""
    levels = model.levels()
    return (bool(exact) and bool(levels) and PARITY_FIT_DEGREE <= levels[-1] < HOP_FIT_DEGREE
            and model.odd_parameters() is not None)


def default_hop_degree(lmax_factor: int) -> int | None:
    """The degree whose stage hops in the default degree ramp of a fit of degree ``lmax_factor``:
    :data:`DEFAULT_HOP_DEGREE` from :data:`HOP_FIT_DEGREE` on, else None (only the last stage hops)."""
    lmax_factor = check_int(lmax_factor, "lmax_factor", minimum=0)
    return DEFAULT_HOP_DEGREE if lmax_factor >= HOP_FIT_DEGREE else None


