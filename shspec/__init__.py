"""shspec: spectral geometry of genus-0 surfaces g = ρ·g₀ in the spherical-harmonic basis and on triangle meshes."""

from .errors import *  # noqa: F401,F403
from .errors import __all__ as _errors_all
from .factor import ConformalFactor
from .galerkin import HarmonicModel, SpectrumResult, spectrum
from .gaunt import real_gaunt
from .wigner import wigner3j
from .harmonics import cilm_to_vector, degree_order, flat_index, ncoeffs, vector_to_cilm, vector_to_shcoeffs
from .inverse import FitOptions, FitResult, Stage, Target, align, fit

__version__ = "0.1.0"

__all__ = [*_errors_all, "cilm_to_vector", "degree_order", "flat_index", "ncoeffs", "vector_to_cilm",
           "vector_to_shcoeffs", "real_gaunt", "wigner3j", "ConformalFactor", "HarmonicModel", "SpectrumResult", "spectrum", "__version__",
           "FitOptions", "FitResult", "Stage", "Target", "align", "fit"]
