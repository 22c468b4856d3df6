"""Weyl's law N(λ) ≈ Aλ/(4π) + c: the area from the counting function, and how far the spectrum strays from it.

The counting function of the first K eigenvalues is a staircase; at λ_n it is n + ½ (the midpoint of the jump, n
counted from 0).  A least-squares line through those points gives the area (slope·4π): :func:`weyl_fit`.  On a
mesh that line is bent by the discretization (cotan eigenvalues fall below the smooth ones, more so the higher
they are), so what continues the spectrum above λ_K is read locally instead: :func:`top_density` fits a parabola
to the top quarter of the staircase, whose slope and curvature at λ_K feed
:func:`~shspec.spectral.heat.spectral_tail`, and whose largest distance D from the staircase there bounds that
tail's error by about 2D·e^{−λ_K t}.  On the round sphere D grows like √λ (multiplicities 2l + 1), on generic
surfaces it stays of order one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgumentError
from .heat import as_eigenvalues

__all__ = ["WeylFit", "weyl_fit", "weyl_area", "TopDensity", "top_density"]


@dataclass(frozen=True)
class WeylFit:
    """Least-squares fit of N(λ_n) = n + ½ ≈ Aλ_n/(4π) + c.

    Attributes
    ----------
    area : float
        A (area units).
    offset : float
        c (dimensionless).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import weyl_fit
    >>> l = np.repeat(np.arange(20), 2 * np.arange(20) + 1)
    >>> type(weyl_fit(l * (l + 1.0))).__name__
    'WeylFit'
    """

    area: float
    offset: float


def weyl_fit(eigenvalues) -> WeylFit:
    """Fit Weyl's law to a spectrum (k,), λ₀ = 0 first, k ≥ 4 (module notes).

    Raises
    ------
    InvalidArgumentError
        If the spectrum is too short or does not grow (slope ≤ 0).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import weyl_fit
    >>> l = np.repeat(np.arange(20), 2 * np.arange(20) + 1)
    >>> fit = weyl_fit(l * (l + 1.0))             # N(lambda) ~ A lambda / (4 pi) + c
    >>> round(fit.area / (4 * np.pi), 3), round(fit.offset, 3)
    (1.0, 0.5)
    """
    lam = as_eigenvalues(eigenvalues, minimum=4)
    n = np.arange(lam.size) + 0.5
    design = np.stack([lam[1:] / (4 * np.pi), np.ones(lam.size - 1)], 1)
    (area, offset), *_ = np.linalg.lstsq(design, n[1:], rcond=None)
    if not area > 0:
        raise InvalidArgumentError("the spectrum does not grow like Weyl's law; cannot estimate the area")
    return WeylFit(float(area), float(offset))


def weyl_area(eigenvalues) -> float:
    """Area A from Weyl's law fitted to the counting function of a spectrum (see :func:`weyl_fit`).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import weyl_area
    >>> l = np.repeat(np.arange(20), 2 * np.arange(20) + 1)
    >>> round(weyl_area(l * (l + 1.0)) / (4 * np.pi), 3)
    1.0
    """
    return weyl_fit(eigenvalues).area


@dataclass(frozen=True)
class TopDensity:
    """The counting function near the largest known eigenvalue λ_K (module notes).

    Attributes
    ----------
    lam_max : float
        λ_K.
    density, density_slope : float
        dN/dλ and d²N/dλ² at λ_K (area units and their square).
    fluctuation : float
        D, the largest distance of the staircase from the parabola over the top quarter (a count, ≥ ½).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import top_density
    >>> l = np.repeat(np.arange(20), 2 * np.arange(20) + 1)
    >>> sorted(top_density(l * (l + 1.0)).__dataclass_fields__)
    ['density', 'density_slope', 'fluctuation', 'lam_max']
    """

    lam_max: float
    density: float
    density_slope: float
    fluctuation: float


def top_density(eigenvalues, fraction: float = 0.25) -> TopDensity:
    """Fit N(λ_n) = n + ½ by a parabola in λ − λ_K over the top ``fraction`` (at least 8 eigenvalues).

    The range grows (doubling) until it holds at least four distinct eigenvalues, which highly degenerate spectra
    (the round sphere's multiplets) need; if the parabola still does not grow at λ_K, Weyl's line over the whole
    spectrum (:func:`weyl_fit`) is used, with no curvature.

    Raises
    ------
    InvalidArgumentError
        If fewer than 8 eigenvalues are given, ``fraction`` is not in (0, 1], or the spectrum does not grow.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import top_density
    >>> l = np.repeat(np.arange(20), 2 * np.arange(20) + 1)
    >>> top = top_density(l * (l + 1.0))          # eigenvalues per unit of lambda near the top: A / (4 pi) = 1
    >>> top.lam_max, round(top.density, 2)
    (380.0, 1.02)
    """
    lam = as_eigenvalues(eigenvalues, minimum=8)
    if not 0 < fraction <= 1:
        raise InvalidArgumentError(f"fraction must be in (0, 1], got {fraction}")
    m = max(8, int(fraction * lam.size))
    while m < lam.size and np.unique(np.round(lam[-m:] / lam[-1], 12)).size < 4:
        m = min(lam.size, 2 * m)
    x = (lam[-m:] - lam[-1]) / lam[-1]
    n = np.arange(lam.size - m, lam.size) + 0.5
    design = np.stack([np.ones_like(x), x, x * x], axis=1)
    coef = np.linalg.lstsq(design, n, rcond=1e-10)[0]
    slope, curvature = coef[1] / lam[-1], coef[2] / lam[-1] ** 2
    resid = n - design @ coef
    if not slope > 0:
        weyl = weyl_fit(lam)
        slope, curvature = weyl.area / (4 * np.pi), 0.0
        resid = np.arange(lam.size) + 0.5 - (slope * lam + weyl.offset)
    return TopDensity(float(lam[-1]), float(slope), float(2 * curvature), float(max(0.5, np.abs(resid[-m:]).max())))
