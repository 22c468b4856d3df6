"""The inverse solver's entry point: several symmetry-broken starts through a schedule, every local solution kept.

A round start never leaves the even subspace (NOTES.md: at an even ρ the gradient along odd degrees is exactly 0),
so every start is random, with odd degrees.  Starts run one after the other (each already uses the machine's
BLAS threads); each writes checkpoints if asked, and Ctrl-C ends the fit cleanly with the best state so far.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ..errors import InvalidArgumentError
from ..model import SpectralModel
from .checkpoint import fingerprint, load_checkpoint, save_checkpoint
from .options import FitOptions, FitResult, StartResult
from .schedule import FitProblem, StartProgress, run_start
from ..targets import Target

__all__ = ["fit", "distinct_solutions"]


def distinct_solutions(starts: list, model: SpectralModel, tol: float) -> list:
    """Indices (into ``starts``) of the distinct local solutions, lowest energy first.

    Two starts are the same solution when their energies agree to ``tol`` relative (or both are below 1e-20) and
    their invariants (:meth:`~shspec.model.SpectralModel.invariant`: per-degree power for harmonic fits, the
    factors for meshes) agree to ``tol`` relative.
    """
    if not starts:
        raise InvalidArgumentError("no starts to compare")
    order = sorted(range(len(starts)), key=lambda i: starts[i].energy)
    reps: list[int] = []
    for i in order:
        ei, pi = starts[i].energy, model.invariant(starts[i].params)
        same = False
        for j in reps:
            ej, pj = starts[j].energy, model.invariant(starts[j].params)
            close_e = max(ei, ej) < 1e-20 or abs(ei - ej) <= tol * max(ei, ej)
            if close_e and np.linalg.norm(pi - pj) <= tol * np.linalg.norm(pj):
                same = True
                break
        if not same:
            reps.append(i)
    return reps


def fit(target: Target, model: SpectralModel, options: FitOptions | None = None, *, resume: bool = False,
        ) -> FitResult:
    """Fit the parameters of ``model`` to the spectrum of ``target`` from several random starts.

    Parameters
    ----------
    target : Target
        The target spectrum (k eigenvalues; stages may use fewer).
    model : SpectralModel
        The discretization: its parameters, gauge, levels and regularizer (see :mod:`shspec.model`).
    options : FitOptions, optional
    resume : bool
        Continue from ``options.checkpoint_path`` if that file exists (it must be a checkpoint of the same fit).

    Returns
    -------
    FitResult
        Every start, the distinct local solutions (best first), and whether Ctrl-C stopped the fit.  On Ctrl-C the
        running start is reported with status "interrupted" and its best state, and a checkpoint is written if a
        path is set.

    Raises
    ------
    InvalidArgumentError, BandLimitError
        For inconsistent options, target and model.
    CheckpointError
        If a checkpoint cannot be written, or read when resuming.

    Examples
    --------
    >>> from shspec.galerkin import HarmonicModel
    >>> from shspec.inverse import FitOptions, blob_factor, fit, harmonic_target
    >>> target = harmonic_target(blob_factor(), lmax=12, numeig=40)
    >>> result = fit(target, HarmonicModel(12, 6), FitOptions(starts=1))  # doctest: +SKIP
    """
    options = FitOptions() if options is None else options
    problem = FitProblem(model, target, options)
    fp = fingerprint(options, target.eigenvalues, model.describe())
    finished: list[StartResult] = []
    current: StartProgress | None = None
    if resume and options.checkpoint_path is not None and Path(options.checkpoint_path).exists():
        finished, current = load_checkpoint(options.checkpoint_path, fp)

    def checkpoint(progress):
        save_checkpoint(options.checkpoint_path, fp, finished, progress)

    interrupted = False
    done = {r.index for r in finished}
    for i in range(options.starts):
        if i in done:
            continue
        if current is None or current.index != i:
            current = StartProgress(i, 0, problem.initial(np.random.default_rng([options.seed, i])), None)
        try:
            finished.append(run_start(problem, current, checkpoint if options.checkpoint_path else None))
        except KeyboardInterrupt:
            interrupted = True
            if options.checkpoint_path:
                save_checkpoint(options.checkpoint_path, fp, finished, current)
            if current.params is not None:
                finished.append(current.result("interrupted", current.seconds, options.success_tol))
            if options.progress:
                print("\ninterrupted: the best state so far is kept", file=sys.stderr)
            break
        current = None
        if options.checkpoint_path and options.checkpoint_every:
            checkpoint(None)
    if not finished:
        raise KeyboardInterrupt
    finished.sort(key=lambda r: r.index)
    solutions = distinct_solutions(finished, model, options.distinct_tol)
    return FitResult(starts=finished, solutions=solutions, target=target, options=options, model=model,
                     seconds=float(sum(r.seconds for r in finished)), interrupted=interrupted)
