"""The piecewise-linear spectrum of a harmonic conformal factor: the reference the study compares the harmonic
spectrum of the same metric with (its Section 3.3)."""

from __future__ import annotations

import numpy as np

from ..sphere.evaluate import sample_harmonic
from ..sphere.factor import ConformalFactor, as_factor
from .model import MeshModel
from .shapes import icosphere

__all__ = ["pl_spectrum_of_factor"]


def pl_spectrum_of_factor(rho, k: int, subdivisions: int = 4) -> np.ndarray:
    """First k eigenvalues of the cotan Laplacian of an icosphere carrying ρ (lumped mass scaled by ρ at vertices).

    The piecewise-linear counterpart of the harmonic spectrum of the same metric; it is the reference the study
    compares the harmonic one with (its Section 3.3).
    """
    factor = rho if isinstance(rho, ConformalFactor) else as_factor(rho)
    sphere = icosphere(subdivisions)
    c = sample_harmonic(factor.coefficients, sphere.vertices)
    return MeshModel(sphere).spectrum(c, k).eigenvalues

