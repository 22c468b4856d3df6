"""Helpers of the inverse-fit experiments: BLAS threads, quiet eigensolver warnings, factor errors, progress, HDF5.

Threads.  On a shared machine OpenBLAS's worker threads spin against other processes: a dense 162 × 162
generalized eigenproblem measured 0.64 s with the default threads and 5 ms with one thread (load average 10 on 2
cores).  The fits call thousands of small dense kernels, so :func:`single_threaded` keeps BLAS on one thread
(:func:`shspec.core.threads.reproducible`, which also makes the results independent of the thread count).
"""

from __future__ import annotations

import sys
import time
import warnings
from contextlib import contextmanager

import numpy as np
from tqdm import tqdm

from ..core.atomic import write_hdf5
from ..inverse import align
from ..mesh.bridge import fit_harmonic, mesh_band_limit
from ..sphere.rotate import power_spectrum
from ..core.threads import reproducible

__all__ = ["single_threaded", "Progress", "vertex_factor_errors", "spectral_residuals", "harmonic_errors",
           "write_h5", "spearman"]


@contextmanager
def single_threaded():
    """Run the block with BLAS/OpenMP limited to one thread, and the eigensolver's cut-multiplet warning silenced.

    A PL target of k eigenvalues may cut a near-degenerate group of the star surfaces (their symmetry makes exact
    pairs); the fit only uses the eigenvalues, so the warning about arbitrary eigenvectors inside the cut group is
    noise here.
    """
    with warnings.catch_warnings(), reproducible():
        warnings.filterwarnings("ignore", message=".*form one degenerate group.*")
        yield


class Progress:
    """An experiment's progress on stderr when enabled: a tqdm bar over its ``total`` steps on a terminal (with the
    elapsed and the estimated remaining time), and a ``[i/n] message (elapsed s)`` line per finished step."""

    def __init__(self, enabled: bool, total: int, name: str):
        self.enabled, self.total, self.name = enabled, total, name
        self.done = 0
        self.start = time.perf_counter()
        self.bar = tqdm(total=total, desc=name, unit="step", file=sys.stderr, leave=False,
                        disable=not (enabled and sys.stderr.isatty()))

    def step(self, message: str) -> None:
        self.done += 1
        self.bar.update(1)
        if self.enabled:
            self.bar.write(f"  {self.name} [{self.done}/{self.total}] {message} "
                           f"({time.perf_counter() - self.start:.0f} s)", file=sys.stderr)
        if self.done >= self.total:
            self.bar.close()


def vertex_factor_errors(areas, fitted, truth) -> dict:
    """Errors of per-vertex factors (n,) on one sphere mesh with vertex areas (n,).

    Returns ``relative_l2`` = ‖c − c*‖/‖c*‖ and ``baseline_l2`` (the same for the constant factor of equal area,
    i.e. how far the truth is from round), both area weighted; ``log_rms``, the area-weighted RMS of
    log(c/c*), robust to the extreme factors of coarse cMCF spheres; and ``log_correlation``, the area-weighted
    correlation of log c and log c*.
    """
    w = np.asarray(areas, dtype=float) / np.sum(areas)
    c, t = np.asarray(fitted, dtype=float), np.asarray(truth, dtype=float)
    norm = np.sqrt(np.sum(w * t * t))
    const = np.sum(w * t)
    lc, lt = np.log(c), np.log(t)
    dc, dt = lc - np.sum(w * lc), lt - np.sum(w * lt)
    corr = float(np.sum(w * dc * dt) / max(np.sqrt(np.sum(w * dc * dc) * np.sum(w * dt * dt)), 1e-300))
    return {"relative_l2": float(np.sqrt(np.sum(w * (c - t) ** 2)) / norm),
            "baseline_l2": float(np.sqrt(np.sum(w * (const - t) ** 2)) / norm),
            "log_rms": float(np.sqrt(np.sum(w * (lc - lt) ** 2))), "log_correlation": corr}


def spectral_residuals(eigenvalues, target) -> tuple[float, float]:
    """Largest and mean |λ_i − λ*_i| / λ*_i over i ≥ 1 of two (k,) arrays."""
    lam, ref = np.asarray(eigenvalues, dtype=float), np.asarray(target, dtype=float)
    rel = np.abs(lam[1:] - ref[1:]) / ref[1:]
    return float(rel.max()), float(rel.mean())


def harmonic_errors(sphere, fitted, truth, lmax_factor: int, *, aligned: bool = False) -> dict:
    """Errors of two per-vertex factors on a sphere mesh after expanding both in harmonics of degree ≤ La.

    ``power_error``: relative error of the per-degree power Σ_m a_lm² (invariant under O(3), cheap).
    ``aligned_error`` (only if ``aligned``): relative L2 error after Möbius centering and the best element of O(3)
    (:func:`shspec.inverse.align`; measured 15-20 s per call on this loaded machine at La = 6, hence optional).
    """
    la = mesh_band_limit(sphere.nvertices, lmax_factor)
    a = fit_harmonic(sphere, fitted, la).coefficients
    b = fit_harmonic(sphere, truth, la).coefficients
    pa, pb = power_spectrum(a), power_spectrum(b)
    out = {"power_error": float(np.linalg.norm(pa - pb) / np.linalg.norm(pb)), "aligned_error": float("nan")}
    if aligned:
        out["aligned_error"] = align(a, b).relative_error
    return out


def write_h5(path, groups: dict) -> None:
    """HDF5 file with one group per key, one dataset per array (scalars and strings as attributes), written
    atomically (:func:`shspec.core.atomic.write_hdf5`: a full disk is one OutputError, never a crash inside HDF5)."""
    def fill(f):
        for name, items in groups.items():
            g = f.create_group(str(name))
            for key, value in items.items():
                if isinstance(value, (str, int, float, bool, np.integer, np.floating)):
                    g.attrs[key] = value
                else:
                    g.create_dataset(key, data=np.asarray(value))

    write_hdf5(path, fill)


def spearman(x, y) -> float:
    """Spearman rank correlation of two sequences (no ties expected)."""
    rx = np.argsort(np.argsort(np.asarray(x, dtype=float)))
    ry = np.argsort(np.argsort(np.asarray(y, dtype=float)))
    if rx.size < 2:
        return float("nan")
    return float(np.corrcoef(rx, ry)[0, 1])
