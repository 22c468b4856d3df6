"""The inverse solver: recover ρ (or per-vertex factors) from a Laplace–Beltrami spectrum.

It sees a discretization only through :class:`~shspec.spectral_model.SpectralModel`, and what it fits through a
:class:`Target` (built by :mod:`shspec.fitting`, which also plans a fit: :func:`shspec.fitting.prepare_fit`).
Pipeline: a :class:`Target` (spectrum, and the truth when known) → :func:`fit` with :class:`FitOptions` (optimizer, weights, regularizer,
schedule of :class:`Stage` s, starts) over a :class:`~shspec.inverse.parametrization.Parametrization` of the
model's parameters → :class:`FitResult` (every start, the distinct local solutions; :func:`write_result` saves
result.h5, summary.json and the figures) → :func:`align` against the truth (Möbius centering, best element of O(3)).
"""

from .align import Alignment, align
from .checkpoint import load_result_summary, save_result
from .energy import Objective, eigenvalue_weights, relative_residual, target_pairs
from .multistart import distinct_solutions, fit
from .options import FitOptions
from .output import summary, write_result
from .parametrization import Parametrization
from .results import FitResult, StartResult
from .schedule import Stage, default_schedule, degree_ramp, numeig_ramp, parity_ramp, parse_schedule
from .target import Target, estimate_area

__all__ = ["Alignment", "align", "load_result_summary", "save_result", "Objective", "eigenvalue_weights",
           "relative_residual", "summary", "write_result", "distinct_solutions", "fit", "FitOptions", "FitResult", "Stage", "StartResult",
           "parse_schedule", "Parametrization", "default_schedule", "numeig_ramp", "degree_ramp", "parity_ramp",
           "Target", "estimate_area", "target_pairs"]
