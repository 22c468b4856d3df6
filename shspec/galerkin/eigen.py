"""The dense eigensolves of the reduced standard problem H u = μ u (largest eigenvalues wanted), cold and warm.

Cold: LAPACK through :func:`scipy.linalg.eigh` on the upper triangle.  Which driver is faster depends on the share of
the spectrum wanted: the MRRR subset driver ('evr') for few eigenpairs, the full divide and conquer ('evd') from
about 0.28 of them (one thread, OpenBLAS 0.3.30; measured, :doc:`/benchmarks`: N = 528 crosses over at k ≈ 0.27·N,
N = 960 at 0.28·N, N = 1680 at 0.3·N; at (Lb, k) = (24, 300) 'evd' takes 0.45× the time of 'evr', at (60, 500)
1.5×).

Warm: a fit moves ρ a little between evaluations, so the previous eigenvectors (plus a few *guard* vectors beyond the
wanted ones) nearly span the new invariant subspace.  Rayleigh–Ritz on them costs one symmetric matrix product and an
eigensolve of the small projected matrix.  It is accepted only when the residuals certify the eigenvalues: with
X the Ritz vectors of the wanted block, R = H X − X Θ and η the gap between the wanted Ritz values and the rest of
the spectrum, the quadratic residual bound |θ_i − μ_i| ≤ ‖R‖₂²/η (Li & Li 2005) must be below
:data:`WARM_TOLERANCE` · θ_min.  ‖R‖₂² is bounded above by the largest absolute row sum of RᵀR; η is estimated as
θ_wanted,min − (θ_guard,max + ‖R_guard‖₂), the guard block standing in for the spectrum beyond.  The eigenvalue error
of Rayleigh–Ritz is second order in the change of H; measured at (30, 15, 256), it is about 250·δ² for a relative
coefficient change δ, so the bound holds for steps δ ≲ 1e-9 only: the last steps of a converging fit, repeated
points, line searches that return to a point.  Otherwise the caller falls back to the cold solve; further subspace
iterations gain only a factor 2-3 each there (the wanted and the guard eigenvalues are close), less than a cold
solve costs.  An accepted warm start costs 0.3× a cold solve at (30, 15, 256); but in the LM run of the benchmark
(a start 1e-4 from the truth, 18 iterations to a residual of 6e-14) every step changed ρ by 1e-7 … 1e-4, so none
was warm: with k/N ≈ 1/4 dense LAPACK is hard to beat by an iterative method that must certify 1e-14.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from scipy.linalg.blas import dsymm

__all__ = ["EVD_SHARE", "WARM_TOLERANCE", "SOLVE_OVERHEAD_SIZE", "guard_count", "cold_eigh", "warm_eigh", "solve_cost"]

#: Above this share of wanted eigenpairs (count / size) the full divide and conquer beats the MRRR subset driver.
EVD_SHARE = 0.28
#: The certified relative eigenvalue error a warm start must reach (the cold solve is exact to ~1e-14 relative).
WARM_TOLERANCE = 1e-14

#: The basis size N whose dense solve costs as much as the fixed overhead of a fit iteration: one iteration of a
#: degree-8 fit (202 eigenvalues, one thread) took 2.2 ms at N = 64, 4.1 ms at 225, 30 ms at 676 and 123 ms at
#: 1296, about (1 + (N / 150)²) · 1.5 ms.
SOLVE_OVERHEAD_SIZE = 150


def solve_cost(size: int) -> float:
    """The relative cost of one spectrum and its derivatives on a basis of ``size`` functions: 1 + (N/150)²
    (:data:`SOLVE_OVERHEAD_SIZE`), the unit of a fit's work (:mod:`shspec.inverse.race`)."""
    return 1.0 + (size / SOLVE_OVERHEAD_SIZE) ** 2


def guard_count(nwanted: int, size: int) -> int:
    """Guard vectors kept beyond ``nwanted`` wanted eigenpairs of a problem of ``size`` (for the next warm start)."""
    return int(min(max(8, nwanted // 16), size - nwanted))


def cold_eigh(h_upper: np.ndarray, count: int, vectors: bool = True,
              ) -> tuple[np.ndarray, np.ndarray | None, str]:
    """The ``count`` largest eigenpairs of the symmetric H given by its upper triangle (overwritten).

    Returns
    -------
    mu : (count,) float array, descending
    u : (n, count) float array, orthonormal eigenvectors (None unless ``vectors``)
    driver : str, the LAPACK driver used ('evr' or 'evd')
    """
    n = h_upper.shape[0]
    keep = slice(n - 1, n - count - 1 if count < n else None, -1)
    if count >= EVD_SHARE * n:
        out = scipy.linalg.eigh(h_upper, lower=False, driver="evd", overwrite_a=True, check_finite=False,
                                eigvals_only=not vectors)
        driver = "evd"
    else:
        out = scipy.linalg.eigh(h_upper, lower=False, subset_by_index=[n - count, n - 1], driver="evr",
                                overwrite_a=True, check_finite=False, eigvals_only=not vectors)
        keep = slice(None, None, -1)
        driver = "evr"
    if not vectors:
        return out[keep], None, driver
    return out[0][keep], out[1][:, keep], driver


def warm_eigh(h_upper: np.ndarray, basis: np.ndarray, nwanted: int, tol: float = WARM_TOLERANCE,
              ) -> tuple[np.ndarray, np.ndarray] | None:
    """Rayleigh–Ritz of H (upper triangle) on an orthonormal ``basis`` (n, p), p > nwanted, certified.

    Returns
    -------
    (mu, u) with mu (p,) descending and u (n, p) the Ritz vectors, or None when the bound of the module docstring
    does not certify the ``nwanted`` largest to ``tol`` relative (the caller then solves cold).
    """
    hx = dsymm(1.0, h_upper, basis, side=0, lower=0)
    a = basis.T @ hx
    theta, c = scipy.linalg.eigh(0.5 * (a + a.T), check_finite=False)
    theta, c = theta[::-1], c[:, ::-1]
    if not theta[-1] > 0:
        return None
    x = basis @ c
    r = hx @ c - x * theta[None, :]
    wanted, guard = r[:, :nwanted], r[:, nwanted:]
    bound_w = np.abs(wanted.T @ wanted).sum(axis=1).max()  # ≥ ‖R_w‖₂²
    bound_g = np.sqrt(np.abs(guard.T @ guard).sum(axis=1).max())  # ≥ ‖R_g‖₂
    gap = theta[nwanted - 1] - theta[nwanted] - bound_g
    if not (gap > 0 and bound_w / gap <= tol * theta[nwanted - 1]):
        return None
    return theta, x
