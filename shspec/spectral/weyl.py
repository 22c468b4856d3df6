"""Weyl's law N(λ) ≈ Aλ/(4π) + c: the area from the counting function, and how far the spectrum strays from it.

The counting function of the first K eigenvalues is a staircase; at λ_n it is n + ½ (the midpoint of the jump, n
counted from 0).  A least-squares line through those points gives the area (slope·4π).  The largest distance of
the staircase from the line near λ_K, D, bounds what Weyl's density gets wrong about the spectrum above λ_K:
the error of :func:`~shspec.spectral.heat.weyl_tail` is at most about 2D·e^{−λ_K t}.  On the round sphere D grows
like √λ (multiplicities 2l + 1), on generic surfaces it stays of order one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgumentError
from .heat import as_eigenvalues

__all__ = ["WeylFit", "weyl_fit", "weyl_area"]


@dataclass(frozen=True)
class WeylFit:
    """Least-squares fit of N(λ_n) = n + ½ ≈ Aλ_n/(4π) + c.

    Attributes
    ----------
    area : float
        A (area units).
    offset : float
        c (dimensionless).
    fluctuation : float
        D = max |N(λ_n) − Aλ_n/(4π) − c| over the upper half of the spectrum (a count, ≥ ½).
    """

    area: float
    offset: float
    fluctuation: float


def weyl_fit(eigenvalues) -> WeylFit:
    """Fit Weyl's law to a spectrum (k,), λ₀ = 0 first, k ≥ 4 (module notes).

    Raises
    ------
    InvalidArgumentError
        If the spectrum is too short or does not grow (slope ≤ 0).
    """
    lam = as_eigenvalues(eigenvalues, minimum=4)
    n = np.arange(lam.size) + 0.5
    design = np.stack([lam[1:] / (4 * np.pi), np.ones(lam.size - 1)], 1)
    (area, offset), *_ = np.linalg.lstsq(design, n[1:], rcond=None)
    if not area > 0:
        raise InvalidArgumentError("the spectrum does not grow like Weyl's law; cannot estimate the area")
    resid = n - (area * lam / (4 * np.pi) + offset)
    return WeylFit(float(area), float(offset), float(max(0.5, np.abs(resid[lam.size // 2:]).max())))


def weyl_area(eigenvalues) -> float:
    """Area A from Weyl's law fitted to the counting function of a spectrum (see :func:`weyl_fit`)."""
    return weyl_fit(eigenvalues).area
