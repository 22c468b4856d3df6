"""Functions on the unit sphere: harmonic index conventions, grids, evaluation, O(3) and Möbius maps, and ρ itself.

Everything here is independent of any discretization of the Laplacian: :mod:`~shspec.sphere.harmonics` (flat
index l*l + l + m, pyshtools cilm and SHCoeffs), :mod:`~shspec.sphere.grid` (Gauss–Legendre grids and transforms),
:mod:`~shspec.sphere.evaluate` (harmonics at scattered points), :mod:`~shspec.sphere.rotate` (rotations, the
mirror, per-degree power), :mod:`~shspec.sphere.mobius` (Möbius maps and centering of ρ) and
:mod:`~shspec.sphere.factor` (:class:`ConformalFactor`, the conformal factor ρ as a value object).
"""

from .evaluate import harmonic_matrix, points_to_angles, sample_harmonic
from .factor import ConformalFactor, as_factor
from .grid import GLQGrid, evaluate_on_grid, expand_grid, glq_grid
from .harmonics import (as_coefficients, cilm_to_vector, degree_order, degrees, flat_index, lmax_of_size, ncoeffs,
                        shcoeffs_to_vector, vector_to_cilm, vector_to_shcoeffs)
from .mobius import HarmonicCentering, center_harmonic, mobius_scale, mobius_translate
from .rotate import mirror_coefficients, power_spectrum, rotate_coefficients

__all__ = [
    "ncoeffs", "flat_index", "degree_order", "degrees", "lmax_of_size", "vector_to_cilm", "cilm_to_vector",
    "vector_to_shcoeffs", "shcoeffs_to_vector", "as_coefficients",
    "GLQGrid", "glq_grid", "evaluate_on_grid", "expand_grid",
    "points_to_angles", "harmonic_matrix", "sample_harmonic",
    "power_spectrum", "rotate_coefficients", "mirror_coefficients",
    "mobius_translate", "mobius_scale", "center_harmonic", "HarmonicCentering",
    "ConformalFactor", "as_factor",
]
