"""The Galerkin forward solver in the spherical-harmonic basis: :class:`HarmonicModel` (ρ's coefficients,
:mod:`~shspec.galerkin.model`), :class:`LogHarmonicModel` (log ρ's, positive by construction,
:mod:`~shspec.galerkin.log_model`), :func:`spectrum` (:mod:`~shspec.galerkin.solver`), and convergence studies in
the band limits (:mod:`~shspec.galerkin.convergence`)."""

from .convergence import convergence, convergence_in_factor
from .log_model import LogHarmonicModel, LogSpectrumResult
from .model import HarmonicModel, SpectrumResult
from .solver import spectrum

__all__ = ["HarmonicModel", "SpectrumResult", "LogHarmonicModel", "LogSpectrumResult", "spectrum", "convergence",
           "convergence_in_factor"]
