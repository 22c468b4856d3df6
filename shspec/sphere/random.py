"""Random smooth functions on the sphere, in one law: degree l carries an RMS amplitude ∝ 1/l.

Per coefficient the standard deviation is σ_l = rms / (√(2l+1) · l), so the 2l+1 coefficients of degree l together
have an expected power rms²/l²: smooth (the power falls like 1/l²) yet with every degree present.  Degree 1 is left
out (a_1m = 0 is the Möbius-centred gauge, :doc:`/theory`), and so is everything below ``low``.  Fits draw their
starts, targets and experiments their random truths from here.
"""

from __future__ import annotations

import numpy as np

from ..core.checks import check_int
from ..errors import InvalidArgumentError
from .harmonics import check_degree, degrees

__all__ = ["random_coefficients", "random_centred_coefficients"]


def random_coefficients(rng: np.random.Generator, lmax: int, rms: float, *, low: int = 2) -> np.ndarray:
    """Random coefficients ((lmax+1)**2,) of degrees ``low`` … ``lmax`` (degree 1 and below ``low`` are 0).

    Parameters
    ----------
    rng : numpy.random.Generator
        One standard normal is drawn per coefficient of degree ≤ lmax (also for those left at 0), so that the draws
        of a given degree do not depend on ``low``.
    lmax : int
        Band limit.
    rms : float
        Scale: degree l has expected RMS amplitude ``rms / l`` over the sphere's unit-norm harmonics.
    low : int
        Lowest degree drawn (at least 2).
    """
    if not isinstance(rng, np.random.Generator):
        raise InvalidArgumentError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    l = degrees(check_degree(lmax, "lmax")).astype(float)
    rms = float(rms)
    if not np.isfinite(rms) or rms < 0:
        raise InvalidArgumentError(f"rms must be finite and >= 0, got {rms}")
    draw = rng.standard_normal(l.size)
    sigma = rms / (np.sqrt(2 * l + 1) * np.maximum(l, 1.0))
    return np.where(l >= max(int(low), 2), sigma * draw, 0.0)


def random_centred_coefficients(seed: int, lmax_factor: int, amplitude: float) -> np.ndarray:
    """Coefficients (ncoeffs(La),) of a random band-limited ρ with mean 1 and a_1m = 0 (the Möbius-centred gauge).

    Degree l ≥ 2 has RMS amplitude ``amplitude / l`` relative to the mean (:func:`random_coefficients`),
    reproducible from ``seed``.  Positivity is not checked: keep ``amplitude`` modest.
    """
    seed = check_int(seed, "seed", minimum=0)
    a = random_coefficients(np.random.default_rng([99, seed]), lmax_factor, amplitude * np.sqrt(4 * np.pi))
    a[0] = np.sqrt(4 * np.pi)
    return a
