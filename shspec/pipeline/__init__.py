"""End-to-end validation of the mesh path (the study's Section 2.4): spectra, factors and re-embedding side by side;
the recursive fit-and-embed refinement of its Section 3.2.3; and the adaptive fit from an icosphere (its A.5)."""

from .adaptive import AdaptiveOptions, AdaptiveResult, AdaptiveStage, adaptive_fit
from .recursive import RecursiveOptions, RecursiveResult, RefinementPass, recursive_fit
from .validation import ValidationOptions, ValidationResult, validate_target, write_report

__all__ = ["AdaptiveOptions", "AdaptiveResult", "AdaptiveStage", "adaptive_fit", "RecursiveOptions", "RecursiveResult", "RefinementPass", "recursive_fit", "ValidationOptions",
           "ValidationResult", "validate_target", "write_report"]
