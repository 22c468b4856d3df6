"""O(3) acting on coefficient vectors: rotations (Wigner-D, through pyshtools), the mirror z ↦ −z, and the
per-degree power that neither changes.

Rotations act on each degree by the Wigner-D matrices (``pyshtools.rotate.SHRotateRealCoef``), and a reflection is
a rotation composed with the mirror z ↦ −z, which multiplies a_lm by (−1)^(l+m) (P_l^m(−x) = (−1)^(l+m) P_l^m(x)).
The per-degree power Σ_m a_lm² is invariant under O(3).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pyshtools

from ..errors import InvalidArgumentError
from ..core.threads import PYSHTOOLS_LOCK
from .harmonics import as_coefficients, degree_order, lmax_of_size

__all__ = ["power_spectrum", "rotate_coefficients", "rotator", "mirror_coefficients"]


def power_spectrum(coeffs) -> np.ndarray:
    """Per-degree power P_l = Σ_m a_lm², shape (La+1,), of a flat vector, cilm array or SHCoeffs."""
    a = as_coefficients(coeffs)
    l, _ = degree_order(lmax_of_size(a.size))
    return np.bincount(l, weights=a * a)


def rotate_coefficients(coeffs, angles) -> np.ndarray:
    """Coefficients (N,) of ρ rotated by the z-y-z Euler angles (α, β, γ) in radians, as ``SHRotateRealCoef``.

    The rotation is linear and the same for the 'ortho' and '4pi' normalizations (they differ by one constant), so
    shspec's coefficients go straight to pyshtools.
    """
    a = as_coefficients(coeffs)
    angles = np.asarray(angles, dtype=float)
    if angles.shape != (3,) or not np.all(np.isfinite(angles)):
        raise InvalidArgumentError(f"angles must be three finite Euler angles, got {angles!r}")
    return rotator(lmax_of_size(a.size))(a, angles)


@lru_cache(maxsize=8)
def rotator(lmax: int):
    """A fast rotation of validated flat vectors of band limit lmax (the alignment calls it thousands of times)."""
    l, m = degree_order(lmax)
    sheet, col = (m < 0).astype(int), np.abs(m)
    with PYSHTOOLS_LOCK:
        dj = pyshtools.rotate.djpi2(max(lmax, 1))

    def rotate(a: np.ndarray, angles: np.ndarray) -> np.ndarray:
        if lmax == 0:
            return a.copy()
        cilm = np.zeros((2, lmax + 1, lmax + 1))
        cilm[sheet, l, col] = a
        with PYSHTOOLS_LOCK:
            return pyshtools.rotate.SHRotateRealCoef(cilm, angles, dj)[sheet, l, col]

    return rotate


def mirror_coefficients(coeffs) -> np.ndarray:
    """Coefficients (N,) of ρ∘σ with σ the mirror z ↦ −z: a_lm (−1)^(l+m)."""
    a = as_coefficients(coeffs)
    l, m = degree_order(lmax_of_size(a.size))
    return a * np.where((l + m) % 2 == 0, 1.0, -1.0)
