"""Figures of a fit of per-vertex factors: Hammer maps of truth, fit and difference, and the study's validation of
spectra (Section 2.4).  Every function returns a matplotlib Figure; the caller saves or closes it."""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError
from .eigen import mesh_spectrum
from .plot import area_percentiles, plot_hammer
from .triangle_mesh import TriangleMesh

__all__ = ["plot_vertex_factors", "plot_spectra_validation"]


def plot_vertex_factors(sphere: TriangleMesh, fitted, truth=None):
    """Hammer maps of the fitted per-vertex factors (n,) on ``sphere``, and with a truth (n,) also of the truth and of
    log10(fit/truth); factors are shown on a log colour scale with one shared range for truth and fit."""
    import matplotlib.pyplot as plt

    fitted = np.asarray(fitted, dtype=float)
    if fitted.shape != (sphere.nvertices,):
        raise InvalidArgumentError(f"fitted factors must have shape ({sphere.nvertices},), got {fitted.shape}")
    if truth is None:
        fig = plt.figure(figsize=(6.5, 4.2))
        plot_hammer(sphere, fitted, ax=fig.add_subplot(1, 1, 1, projection="hammer"), title="fitted factors",
                    log=True, label="factor")
        return fig
    truth = np.asarray(truth, dtype=float)
    if truth.shape != fitted.shape:
        raise InvalidArgumentError(f"truth must have shape {fitted.shape}, got {truth.shape}")
    fig = plt.figure(figsize=(17, 4.2))
    axes = [fig.add_subplot(1, 3, i + 1, projection="hammer") for i in range(3)]
    # one colour range for target and fit (area percentiles of both), so that equal colours mean equal factors
    lo = min(area_percentiles(sphere, truth, [1.0])[0], area_percentiles(sphere, fitted, [1.0])[0])
    hi = max(area_percentiles(sphere, truth, [99.0])[0], area_percentiles(sphere, fitted, [99.0])[0])
    plot_hammer(sphere, truth, ax=axes[0], title="target (cMCF factors)", log=True, label="factor", vmin=lo, vmax=hi)
    plot_hammer(sphere, fitted, ax=axes[1], title="fit", log=True, label="factor", vmin=lo, vmax=hi)
    ratio = np.log10(fitted / truth)
    bound = float(np.max(np.abs(area_percentiles(sphere, ratio, [1.0, 99.0])))) or 1.0
    plot_hammer(sphere, ratio, ax=axes[2], cmap="RdBu_r", title="log10(fit / target)", label="log10 ratio",
                vmin=-bound, vmax=bound)
    return fig


def plot_spectra_validation(model, params, mesh: TriangleMesh, factors, k: int):
    """The study's validation: spectra of the target mesh, of its cMCF sphere carrying the cMCF factors, and of that
    sphere carrying the fitted factors, side by side (right: relative to the target's).

    Parameters
    ----------
    model : MeshModel
        The model of the cMCF sphere.
    params : (n,) array
        Fitted factors.
    mesh : TriangleMesh
        The target surface.
    factors : (n,) array
        Its cMCF factors.
    k : int
        Number of eigenvalues.

    Returns
    -------
    (Figure, dict)
        The figure and the three spectra (arrays (k,)) under "target", "cmcf", "fit".
    """
    import matplotlib.pyplot as plt

    spectra = {"target": mesh_spectrum(mesh, k, whole_multiplets=False).eigenvalues[:k],
               "cmcf": model.spectrum(factors, k).eigenvalues, "fit": model.spectrum(params, k).eigenvalues}
    labels = {"target": "target mesh (cotan)", "cmcf": "sphere with cMCF factors", "fit": "sphere with fitted factors"}
    colours = {"target": "k", "cmcf": "tab:blue", "fit": "tab:orange"}
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    i = np.arange(k)
    for name, lam in spectra.items():
        axes[0].plot(i, lam, ".", label=labels[name], ms=4, color=colours[name])
        if name != "target":
            axes[1].semilogy(i[1:], np.maximum(np.abs(lam[1:] / spectra["target"][1:] - 1), 1e-300), ".",
                             label=labels[name], ms=4, color=colours[name])
    axes[0].set_ylabel("λ_i")
    axes[1].set_ylabel("|λ_i / λ_i(target) − 1|")
    for ax in axes:
        ax.set_xlabel("eigenvalue index i")
        ax.legend()
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig, spectra
