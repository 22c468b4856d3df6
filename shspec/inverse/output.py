"""What a finished fit writes: a JSON-ready summary, result.h5 and the figures, in one directory.

The summary holds everything needed to judge the fit without opening the HDF5 file: the model, the target, the
options, every start (energy, residual, iterations, time, work, why it stopped, whether it succeeded), the best
solution as a pyshtools cilm array and, when the target knows its truth, the errors after Möbius + O(3) alignment
(and the model's own comparison, e.g. per-vertex factor errors on a mesh), and what the matched eigenvalues
determine at the solution (``identifiability``: free parameters, rank, condition, estimated error, noise gain; see
:mod:`shspec.inverse.identifiability`).  A start *succeeds* when its largest relative
eigenvalue residual max_i |λ_i − λ*_i|/λ*_i (i ≥ 1) is at most ``FitOptions.success_tol``; the summary says so.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
from pathlib import Path

import filelock
import numpy as np

from ..core.atomic import atomic_outputs, save_figure, write_text
from ..errors import InvalidArgumentError, NotPositiveError, OutputError
from ..core.outputs import ensure_directory
from ..sphere.evaluate import sample_harmonic
from . import plots
from .checkpoint import claim_checkpoint, options_dict, save_result
from .problem import CHI2_SIGMAS
from .results import FitResult

__all__ = ["summary", "write_result", "success_definition", "alignment_record", "surface_record", "rho_error",
           "claim_output", "OUTPUT_LOCK"]

#: The lock file of a fit's output folder (held by :func:`claim_output` for the whole fit), and the file beside it
#: that says who holds it.
OUTPUT_LOCK = ".shspec-fit.lock"
_OWNER = ".shspec-fit.owner"


def alignment_record(result: FitResult) -> dict | None:
    """Errors of the best solution against the target's harmonic truth after alignment, or why there are none."""
    try:
        aligned = result.alignment()
    except NotPositiveError as exc:  # the model's harmonic expansion dips below 0: report it, keep the rest
        return {"skipped": f"no alignment: {exc}"}
    if aligned is None:
        return None
    return {"relative_error": aligned.relative_error, "power_error": aligned.power_error,
            "mirrored": aligned.mirrored, "angles": aligned.angles.tolist()}


def surface_record(result: FitResult) -> dict | None:
    """For a fit of a mesh target by a model that can express the target's cMCF factors c
    (:meth:`~shspec.spectral_model.SpectralModel.approximation`): the best solution, aligned with the truth, at the
    vertices of the cMCF sphere against c — area-weighted relative L2 error, Pearson correlation and RMS of the
    logarithms — beside the model's floor, the error of its best approximation of c, and the error bar against c,
    √(floor² + bar²) with the bar of the target's errors (:class:`~shspec.inverse.identifiability.Identifiability`),
    the floor raised to the surface plan's bias where it has one (its reference polished against the spectrum,
    :class:`~shspec.fitting.surface_plan.SurfacePlan`).  None otherwise."""
    samples = result.target.factor_samples()
    if samples is None:
        return None
    points, weights, c = samples
    best = result.model.approximation(points, weights, c)
    if best is None:
        return None
    out = {"floor": best[1], "truth_range": [float(c.min()), float(c.max())]}
    bias = (result.plan.get("surface_plan") or {}).get("bias")
    if bias is not None:
        out["bias"] = bias
    bar = result.identifiability().noise_error
    if bar is not None and np.isfinite(bar):
        # the floor (or the bias of a fit of the spectrum), which no spectrum can lower, and the spread the errors
        # leave about it
        out["error_bar"] = float(np.hypot(max(best[1], bias or 0.0), bar))
    try:
        aligned = result.alignment()
    except NotPositiveError as exc:
        return {**out, "skipped": f"no alignment: {exc}"}
    fitted = sample_harmonic(aligned.aligned, points)
    out["fitted_range"] = [float(fitted.min()), float(fitted.max())]
    out["factor_error"] = float(np.sqrt(weights @ (fitted - c) ** 2 / (weights @ c ** 2)))
    if np.all(fitted > 0):
        lf, lc = np.log(fitted), np.log(c)
        out["log_correlation"] = float(np.corrcoef(lf, lc)[0, 1])
        out["log_rms"] = float(np.sqrt(weights @ (lf - lc) ** 2 / weights.sum()))
    return out


def success_definition(result: FitResult) -> str:
    """When a start of this fit succeeds, in words."""
    if result.target.errors is None:
        return f"max_i |lambda_i - lambda*_i| / lambda*_i <= {result.options.success_tol:g}"
    return (f"residuals consistent with the target's errors sigma_i: chi^2 / (K - 1) <= 1 + {CHI2_SIGMAS:g} "
            "sqrt(2 / (K - 1)), chi^2 = sum_i ((lambda_i - lambda*_i) / sigma_i)^2")


def summary(result: FitResult) -> dict:
    """The JSON-ready summary of a fit (module notes).

    Examples
    --------
    >>> from shspec import HarmonicModel
    >>> from shspec.fitting import blob_factor, harmonic_target
    >>> from shspec.inverse import FitOptions, fit, summary
    >>> result = fit(harmonic_target(blob_factor().truncated(2), 10, 16), HarmonicModel(10, 2),
    ...              FitOptions(starts=1, max_iter=20, basin_hops=0, progress=False))
    >>> s = summary(result)
    >>> s["successes"], s["model"], s["alignment"]["relative_error"] < 1e-8
    (1, 'harmonic Lb=10 La=2', True)
    """
    if not isinstance(result, FitResult):
        raise InvalidArgumentError(f"expected a FitResult, got {type(result).__name__}")
    best, target, opt = result.best, result.target, result.options
    out = {
        "target": target.name, "source": target.source, "model": result.model.describe(),
        "numeig": target.numeig, "options": options_dict(opt),
        "optimizer": opt.optimizer or result.model.default_optimizer,
        "energy": best.energy, "relative_residual": best.relative_residual,
        "success_definition": success_definition(result),
        "successes": result.success_count, "time_s": result.seconds, "interrupted": result.interrupted,
        "solutions": [{"start": result.starts[i].index, "energy": result.starts[i].energy} for i in result.solutions],
        "starts": [{"index": r.index, "energy": r.energy, "relative_residual": r.relative_residual,
                    "iterations": r.iterations, "time_s": r.seconds, "work": r.work, "status": r.status,
                    "success": r.success}
                   for r in result.starts],
    }
    out["cilm"] = result.factor().to_cilm().tolist()
    ident = result.identifiability()
    out["identifiability"] = ident.to_dict()
    alignment = alignment_record(result)
    if alignment is not None:
        out["alignment"] = alignment
    out.update(result.model.compare(best.params, target))
    surface = surface_record(result)
    if surface is not None:
        out["surface"] = surface
    out["rho_error"] = rho_error(ident, surface)
    out.update(result.plan)
    return out


#: A measured error beyond this multiple of its linearized bar says the bar's assumption (the truth's basin) fails.
_BAR_HOLDS = 2.0


def rho_error(ident, surface: dict | None = None) -> dict:
    """The one error of the fitted ρ to read, and what it is: ``{"value": relative L2 error or None, "meaning": ...}``.

    A fit that did not succeed has none (a residual at a local minimum says nothing of the distance to the truth).
    Otherwise: against a mesh's cMCF factors, the error measured after alignment (the surface record), which says
    whether the error bar of the basis's floor with the target's errors holds (a fit within the target's errors can
    lie in another basin, beyond the linearized bar); without an alignment, that bar; else the error bar the
    target's errors leave; else, for an exact target, the error its final residual leaves (linearized).
    ``expected_error`` of a planned fit is the same kind of bar predicted before the fit, at a random start of the
    fit's law."""
    if ident.converged is False:
        return {"value": None, "meaning": "unknown: the fit did not converge to its target, and a residual left at a "
                "local minimum says nothing about the distance to the truth"}
    if ident.underdetermined:
        return {"value": None, "meaning": "unknown: the matched eigenvalues do not determine every direction of rho"}
    if surface is not None and surface.get("factor_error") is not None:
        bar = surface.get("error_bar")
        expected = "" if bar is None else (
            f"; expected within {bar:.2g} (surface.error_bar: the basis's floor, or the plan's bias, with the "
            "target's errors)"
            + (", which assumes the fit in the factors' own basin: this one is not" if surface["factor_error"]
               > _BAR_HOLDS * bar else ""))
        return {"value": surface["factor_error"], "meaning": "relative L2 error against the mesh's cMCF factors, "
                f"measured after Moebius and O(3) alignment (surface.factor_error){expected}"}
    if surface is not None and surface.get("error_bar") is not None:
        return {"value": surface["error_bar"], "meaning": "expected relative L2 error against the mesh's cMCF "
                "factors: the floor of the basis with the target's errors (surface.error_bar)"}
    if ident.noise_error is not None and np.isfinite(ident.noise_error):
        return {"value": float(ident.noise_error), "meaning": "expected relative L2 error that the target's own "
                "errors leave (identifiability.error_bar)"}
    if ident.error_estimate is not None:
        return {"value": float(ident.error_estimate), "meaning": "relative L2 error that the final residual leaves, "
                "linearized (identifiability.estimated_error)"}
    return {"value": None, "meaning": "unknown: no residual or errors to judge by"}


@contextlib.contextmanager
def claim_output(directory, *, resume: bool = False, overwrite: bool = False):
    """Hold the output folder of a fit for the whole fit: a context manager around the fit and
    :func:`write_result`.

    It creates ``directory`` if needed and takes its lock (:data:`OUTPUT_LOCK`, the cache's kind of lock: released
    by the system when the process ends, however it ends); a second fit into the folder is refused at once, saying
    which process holds it.  Under the lock it checks the folder's checkpoint (:func:`claim_checkpoint`, with
    ``resume`` and ``overwrite``): a checkpoint there now is that of a fit that ended or died, never of a running
    one.

    Yields
    ------
    Path
        The directory.

    Raises
    ------
    OutputError
        If ``directory`` is a file or cannot be created, or another fit holds it.
    CheckpointError
        As :func:`claim_checkpoint`.
    """
    out = ensure_directory(directory)
    lock = filelock.FileLock(out / OUTPUT_LOCK, mode=0o644, thread_local=False)
    try:
        lock.acquire(timeout=0)
    except filelock.Timeout:
        try:
            owner = (out / _OWNER).read_text(encoding="utf-8").strip()
        except OSError:
            owner = "a process that did not say which"
        raise OutputError(f"another fit is writing into {out} ({owner}): wait for it to end, or give another "
                          "output folder") from None
    except OSError as exc:
        raise OutputError(f"cannot lock the output folder {out}: {exc.strerror or exc}") from exc
    try:
        # said after the lock is held, in a file of its own: a waiting process's attempt empties the lock file
        write_text(out / _OWNER, f"pid {os.getpid()} on {socket.gethostname()}, since "
                                 f"{time.strftime('%Y-%m-%d %H:%M:%S')}\n")
        claim_checkpoint(out / "checkpoint.h5", resume=resume, overwrite=overwrite)
        yield out
    finally:
        with contextlib.suppress(OSError):
            (out / _OWNER).unlink()
        lock.release()


#: What a fit writes into its folder but the model's own files: what a fit replaces there even when the folder's
#: list of the previous fit's outputs (:data:`shspec.core.atomic.MANIFEST`) is missing.
FIT_OUTPUTS = ("result.h5", "summary.json", "history.png", "residuals.png", "factors.png")


def write_result(result: FitResult, directory, *, figures: bool = True) -> Path:
    """Write ``result.h5`` (:func:`~shspec.inverse.checkpoint.save_result`), ``summary.json``, the model's own files
    (:meth:`~shspec.spectral_model.SpectralModel.write_files`: factors.txt and sphere.obj of a mesh fit) and, if ``figures``,
    history.png, residuals.png, factors.png and the model's own figures into ``directory`` (created).

    The files are one unit (:func:`shspec.core.atomic.atomic_outputs`): they replace every output of the fit written
    there before, those this one does not write (a figure it skips) included, or, when one cannot be written, none
    does; a checkpoint in the folder is left alone.

    Returns
    -------
    Path
        The directory.

    Raises
    ------
    OutputError
        If a file cannot be written (a full disk, a file-size limit, a read-only folder): the folder is then as it
        was.

    Examples
    --------
    >>> import os
    >>> from shspec import HarmonicModel
    >>> from shspec.fitting import blob_factor, harmonic_target
    >>> from shspec.inverse import FitOptions, fit, write_result
    >>> result = fit(harmonic_target(blob_factor().truncated(2), 10, 16), HarmonicModel(10, 2),
    ...              FitOptions(starts=1, max_iter=20, basin_hops=0, progress=False))
    >>> out = write_result(result, "fit", figures=False)
    >>> sorted(name for name in os.listdir(out) if not name.startswith("."))
    ['result.h5', 'summary.json']
    """
    out = ensure_directory(directory)
    with atomic_outputs(out, replaces=FIT_OUTPUTS) as files:
        save_result(files.path("result.h5"), result)
        write_text(files.path("summary.json"), json.dumps(summary(result), indent=2) + "\n")
        for name in result.model.write_files(result.best.params, files.staging):
            files.path(name)
        if figures:
            import matplotlib.pyplot as plt

            figs = {"history.png": plots.plot_history(result), "residuals.png": plots.plot_residuals(result)}
            try:
                figs["factors.png"] = plots.plot_factors(result)
            except NotPositiveError:
                pass  # the alignment could not be made; summary.json says why
            figs.update(result.model.figures(result.best.params, result.target))
            for name, fig in figs.items():
                try:
                    save_figure(fig, files.path(name), dpi=110)
                finally:
                    plt.close(fig)
    return out
