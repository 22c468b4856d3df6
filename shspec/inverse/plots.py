"""Figures of a fit: Hammer maps of target, fit and difference, the energy history and the eigenvalue residuals.
Models add their own (:meth:`~shspec.spectral_model.SpectralModel.figures`; a mesh fit: per-vertex maps and the study's
validation of spectra).  Every function returns a matplotlib Figure; the caller saves or closes it (use a
non-interactive backend such as Agg on servers)."""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError
from ..sphere.factor import ConformalFactor
from .results import FitResult

__all__ = ["plot_factors", "plot_history", "plot_residuals", "RESIDUAL_FLOOR"]

#: Relative residuals below this (a few ulps of double precision) are drawn at it, marked as rounding.
RESIDUAL_FLOOR = 1e-15


def _check(result) -> FitResult:
    if not isinstance(result, FitResult):
        raise InvalidArgumentError(f"expected a FitResult, got {type(result).__name__}")
    return result


def plot_factors(result: FitResult, aligned=None):
    """Hammer projections of the fitted ρ and, when the target knows its truth, of the truth and the difference after
    Möbius + O(3) alignment, the target and the fit on one colour range.  Mesh fits show the harmonic expansion of
    their factors (their per-vertex maps are among the model's figures).

    Parameters
    ----------
    result : FitResult
    aligned : Alignment, optional
        The fit's alignment with the truth (default: :meth:`FitResult.alignment`, computed once per result).

    Raises
    ------
    NotPositiveError
        If the fit or the truth is not positive, so that they cannot be Möbius-centred.
    """
    import matplotlib.pyplot as plt

    result = _check(result)
    target = result.target
    fit = result.factor()
    if target.truth is None:
        fig = plt.figure(figsize=(7, 4.5))
        fit.plot(ax=fig.add_subplot(1, 1, 1, projection="hammer"), title="fit (no truth known)")
        return fig
    if aligned is None:
        aligned = result.alignment()
    fig = plt.figure(figsize=(16, 4.8))
    axes = [fig.add_subplot(1, 3, i + 1, projection="hammer") for i in range(3)]
    ref, fitted = ConformalFactor(aligned.reference, name="target"), ConformalFactor(aligned.aligned, name="fit")
    lo = min(ref.minimum().value, fitted.minimum().value)
    hi = max(np.max(ref.evaluate()[0]), np.max(fitted.evaluate()[0]))
    ref.plot(ax=axes[0], title="target (centred)", vmin=lo, vmax=hi)
    fitted.plot(ax=axes[1], title="fit (centred, aligned)" + (", mirrored" if aligned.mirrored else ""),
                vmin=lo, vmax=hi)
    diff = ConformalFactor(aligned.aligned - aligned.reference, name="difference")
    bound = float(np.max(np.abs(diff.evaluate()[0]))) or 1.0
    diff.plot(ax=axes[2], cmap="RdBu_r", title=f"fit − target (rel. L2 {aligned.relative_error:.2e})",
              vmin=-bound, vmax=bound)
    fig.tight_layout()
    return fig


def plot_history(result: FitResult):
    """Energy and max relative residual against iteration, one line per start and stage: stages match different
    numbers of eigenvalues, so their energies are not joined; a dotted line, labelled with the stage, marks where a
    stage (or a basin hop's refit) begins."""
    import matplotlib.pyplot as plt

    result = _check(result)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    labelled = set()
    for n, r in enumerate(result.starts):
        h = r.history
        colour = f"C{n % 10}"
        starts = np.concatenate([[0], np.flatnonzero(np.diff(h[:, 0]) != 0) + 1, [h.shape[0]]])
        for ax, col in zip(axes, (1, 2)):
            for j, (a, b) in enumerate(zip(starts[:-1], starts[1:])):
                ax.semilogy(np.arange(a, b), np.maximum(h[a:b, col], 1e-300), color=colour,
                            label=f"start {r.index}" if j == 0 else None)
                if a > 0:
                    ax.axvline(a, color=colour, ls=":", lw=0.8, alpha=0.6)
                if (ax, a, int(h[a, 0])) not in labelled:  # starts that change stage together share one label
                    labelled.add((ax, a, int(h[a, 0])))
                    ax.annotate(_stage_label(result, int(h[a, 0])), (a, 1.0), xycoords=("data", "axes fraction"),
                                xytext=(2, -3), textcoords="offset points", fontsize=7, color="0.3", va="top")
    axes[0].set_ylabel("energy (each stage its own eigenvalues: not joined)")
    axes[1].set_ylabel("max |λ−λ*|/λ*")
    for ax in axes:
        ax.set_xlabel("iteration (all stages)")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize="small")
    fig.tight_layout()
    return fig


def _stage_label(result: FitResult, stage: int) -> str:
    """'stage 2: La 4, K 25' when the schedule is known, else 'stage 2' (an automatic schedule, or a hop's refit)."""
    schedule = result.options.schedule
    if schedule and 0 <= stage < len(schedule):
        s = schedule[stage]
        parts = [f"La {s.lmax_factor}" if s.lmax_factor is not None else "",
                 f"K {s.numeig}" if s.numeig is not None else ""]
        return f"stage {stage}: " + ", ".join(p for p in parts if p) if any(parts) else f"stage {stage}"
    return f"stage {stage}"


def plot_residuals(result: FitResult):
    """Relative eigenvalue residuals (λ_i − λ*_i)/λ*_i of the best start against i."""
    import matplotlib.pyplot as plt

    result = _check(result)
    lam = result.best.eigenvalues
    ref = result.target.eigenvalues[:lam.size]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    i = np.arange(1, lam.size)
    rel = np.abs(lam[1:] - ref[1:]) / ref[1:]
    # a residual below double precision's resolution is zero as far as the data can tell: drawn at that floor
    # (one exact eigenvalue would otherwise stretch the log axis down to 1e-300)
    exact = rel < RESIDUAL_FLOOR
    ax.semilogy(i[~exact], rel[~exact], ".", label="|λ_i − λ*_i| / λ*_i")
    if exact.any():
        ax.semilogy(i[exact], np.full(exact.sum(), RESIDUAL_FLOOR), "v", color="0.5", ms=4,
                    label=f"below {RESIDUAL_FLOOR:g} (rounding)")
        ax.legend(fontsize="small")
    ax.set_xlabel("eigenvalue index i")
    ax.set_ylabel("|λ_i − λ*_i| / λ*_i")
    ax.set_title(f"best start {result.best.index}: max {result.best.relative_residual:.2e}")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig
