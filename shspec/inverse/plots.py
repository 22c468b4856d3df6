"""Figures of a fit: Hammer maps of target, fit and difference, the energy history, the eigenvalue residuals, and
the study's validation (Section 2.4) of a mesh fit.  Every function returns a matplotlib Figure; the caller saves
or closes it (use a non-interactive backend such as Agg on servers)."""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError
from .options import FitResult

__all__ = ["plot_factors", "plot_history", "plot_residuals", "plot_validation"]


def _check(result) -> FitResult:
    if not isinstance(result, FitResult):
        raise InvalidArgumentError(f"expected a FitResult, got {type(result).__name__}")
    return result


def plot_factors(result: FitResult, aligned=None):
    """Hammer projections of the target ρ, the fitted ρ and their difference (harmonic fits; mesh fits: the cMCF
    factors, the fitted factors and the difference on the reference sphere).

    Parameters
    ----------
    result : FitResult
    aligned : Alignment, optional
        For harmonic fits with a known truth: plot the fit after this alignment (default: computed).
    """
    import matplotlib.pyplot as plt

    from ..sphere.factor import ConformalFactor

    result = _check(result)
    target = result.target
    fig = plt.figure(figsize=(15, 4.5))
    axes = [fig.add_subplot(1, 3, i + 1, projection="hammer") for i in range(3)]
    if result.kind == "mesh":
        from ..mesh.plot import plot_hammer

        sphere = target.sphere
        fitted = result.best.params
        if sphere is None or target.factors is None or sphere.nvertices != fitted.size:
            raise InvalidArgumentError("a mesh fit figure needs the target's cMCF sphere and factors")
        plot_hammer(sphere, target.factors, ax=axes[0], title="target (cMCF factors)")
        plot_hammer(sphere, fitted, ax=axes[1], title="fit")
        plot_hammer(sphere, fitted - target.factors, ax=axes[2], cmap="RdBu_r", title="fit - target")
        return fig
    fit = result.factor()
    if target.truth is None:
        fit.plot(ax=axes[1], title="fit")
        for ax in (axes[0], axes[2]):
            ax.set_title("(no truth known)")
        return fig
    if aligned is None:
        from .align import align

        aligned = align(fit, target.truth)
    ConformalFactor(aligned.reference, name="target").plot(ax=axes[0], title="target (centred)")
    ConformalFactor(aligned.aligned, name="fit").plot(ax=axes[1], title="fit (centred, aligned)")
    ConformalFactor(aligned.aligned - aligned.reference, name="difference").plot(
        ax=axes[2], cmap="RdBu_r", title=f"fit - target (rel. L2 {aligned.relative_error:.2e})")
    return fig


def plot_history(result: FitResult):
    """Energy and max relative residual against iteration, one line per start (stage changes marked)."""
    import matplotlib.pyplot as plt

    result = _check(result)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for r in result.starts:
        h = r.history
        for ax, col in zip(axes, (1, 2)):
            ax.semilogy(np.arange(h.shape[0]), np.maximum(h[:, col], 1e-300), label=f"start {r.index}")
    axes[0].set_ylabel("energy")
    axes[1].set_ylabel("max |λ−λ*|/λ*")
    for ax in axes:
        ax.set_xlabel("iteration (all stages)")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize="small")
    fig.tight_layout()
    return fig


def plot_residuals(result: FitResult):
    """Relative eigenvalue residuals (λ_i − λ*_i)/λ*_i of the best start against i."""
    import matplotlib.pyplot as plt

    result = _check(result)
    lam = result.best.eigenvalues
    ref = result.target.eigenvalues[:lam.size]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    i = np.arange(1, lam.size)
    ax.semilogy(i, np.maximum(np.abs(lam[1:] - ref[1:]) / ref[1:], 1e-300), ".")
    ax.set_xlabel("eigenvalue index i")
    ax.set_ylabel("|λ_i − λ*_i| / λ*_i")
    ax.set_title(f"best start {result.best.index}: max {result.best.relative_residual:.2e}")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def plot_validation(result: FitResult, numeig: int | None = None):
    """The study's validation of a mesh fit: spectra of the target mesh, of its cMCF sphere carrying the cMCF
    factors, and of that sphere carrying the fitted factors, side by side (relative to the target's).

    Returns
    -------
    (Figure, dict)
        The figure and the three spectra (arrays (k,)) under "target", "cmcf", "fit".
    """
    import matplotlib.pyplot as plt

    from ..mesh.eigen import mesh_spectrum
    from ..mesh.model import MeshModel

    result = _check(result)
    t = result.target
    if result.kind != "mesh" or t.mesh is None or t.factors is None:
        raise InvalidArgumentError("validation plots need a mesh fit of a mesh target")
    k = result.best.eigenvalues.size if numeig is None else int(numeig)
    model = MeshModel(t.sphere)
    spectra = {"target": mesh_spectrum(t.mesh, k, whole_multiplets=False).eigenvalues[:k],
               "cmcf": model.spectrum(t.factors, k).eigenvalues, "fit": model.spectrum(result.best.params, k).eigenvalues}
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    i = np.arange(k)
    for name, lam in spectra.items():
        axes[0].plot(i, lam, ".", label=name, ms=4)
        if name != "target":
            axes[1].semilogy(i[1:], np.abs(lam[1:] / spectra["target"][1:] - 1), ".", label=name, ms=4)
    axes[0].set_ylabel("λ_i")
    axes[1].set_ylabel("|λ_i/λ_i(target) − 1|")
    for ax in axes:
        ax.set_xlabel("i")
        ax.legend()
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig, spectra
