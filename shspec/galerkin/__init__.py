"""The Galerkin forward solver in the spherical-harmonic basis: :class:`HarmonicModel` and :func:`spectrum`
(:mod:`~shspec.galerkin.solver`), and convergence studies in the band limits (:mod:`~shspec.galerkin.convergence`)."""

from .convergence import convergence, convergence_in_factor
from .model import HarmonicModel, SpectrumResult
from .solver import spectrum

__all__ = ["HarmonicModel", "SpectrumResult", "spectrum", "convergence", "convergence_in_factor"]
