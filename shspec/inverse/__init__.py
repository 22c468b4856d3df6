"""The inverse solver: recover ρ (or per-vertex factors) from a Laplace–Beltrami spectrum.

Pipeline: a :class:`Target` (spectrum, and the truth when known) → :func:`fit` with :class:`FitOptions` (optimizer,
weights, regularizer, schedule of :class:`Stage` s, starts) → :class:`FitResult` (every start, the distinct local
solutions) → :func:`align` against the truth (Möbius centering, best element of O(3)) → :func:`save_result` and the
figures of :mod:`shspec.inverse.plots`.
"""

from .align import Alignment, align
from .checkpoint import load_result_summary, save_result
from .energy import Objective, eigenvalue_weights, relative_residual
from .multistart import distinct_solutions, fit
from .options import FitOptions, FitResult, Stage, StartResult, parse_schedule
from .schedule import degree_ramp, numeig_ramp
from .targets import (BLOB_HARMONIC, Target, blob_factor, random_centred_coefficients, estimate_area, harmonic_target, mesh_target, parse_target,
                      read_spectrum, spectrum_target)

__all__ = ["Alignment", "align",
           "load_result_summary", "save_result", "Objective", "eigenvalue_weights", "relative_residual",
           "distinct_solutions", "fit", "FitOptions", "FitResult", "Stage", "StartResult", "parse_schedule",
           "numeig_ramp", "degree_ramp", "BLOB_HARMONIC", "Target", "blob_factor", "random_centred_coefficients", "estimate_area", "harmonic_target",
           "mesh_target", "parse_target", "read_spectrum", "spectrum_target"]
