"""Fits planned from what a user has, and the fit strategies built on the inverse solver.

:func:`prepare_fit` turns a target (a mesh, a spectrum file or array, a harmonic ρ; :class:`FitRequest`) into a
:class:`FitPlan`: the target with its errors, the model, the options, and the reasons for La, K, Lb and the penalty;
``shspec.inverse.fit(plan)`` runs it, and ``shspec fit`` is the same two calls.  The targets' builders
(:mod:`~shspec.fitting.targets`), the plans of K (:mod:`~shspec.fitting.numeig_plan`) and of a mesh's log-ρ fit
(:mod:`~shspec.fitting.surface_plan`), starting points read from files (:mod:`~shspec.fitting.initial`) and the
mesh fits that refine as they go (:func:`adaptive_fit`, :func:`recursive_fit`) live here.
"""

from .adaptive import AdaptiveOptions, AdaptiveResult, AdaptiveStage, adaptive_fit
from .initial import initial_parameters, read_initial, read_truth
from .numeig_plan import NumeigPlan, plan_fit, plan_numeig
from .plan import Choice, FitPlan, prepare_fit
from .recursive import RecursiveOptions, RecursiveResult, RefinementPass, recursive_fit
from .request import MODEL_KINDS, FitRequest
from .surface_plan import SurfacePlan, plan_surface_fit
from .targets import (BLOB_HARMONIC, MeshTarget, blob_factor, harmonic_target, mesh_target, parse_target,
                      read_spectrum, refined_target, spectrum_target, with_discretization_errors)

__all__ = ["prepare_fit", "FitPlan", "FitRequest", "Choice", "MODEL_KINDS", "BLOB_HARMONIC", "MeshTarget",
           "blob_factor", "harmonic_target", "mesh_target", "parse_target", "read_spectrum", "refined_target",
           "spectrum_target", "with_discretization_errors", "NumeigPlan", "plan_fit", "plan_numeig", "SurfacePlan",
           "plan_surface_fit", "initial_parameters", "read_initial", "read_truth", "AdaptiveOptions",
           "AdaptiveResult", "AdaptiveStage", "adaptive_fit", "RecursiveOptions", "RecursiveResult",
           "RefinementPass", "recursive_fit"]
