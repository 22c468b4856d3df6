"""End-to-end validation of the mesh path (the study's Section 2.4): spectra, factors and re-embedding side by side.
The fit strategies it uses (the recursive fit-and-embed refinement of the study's Section 3.2.3, the adaptive fit
from an icosphere of its A.5) live in :mod:`shspec.fitting`."""

from .validation import ValidationOptions, ValidationResult, validate_target, write_report

__all__ = ["ValidationOptions", "ValidationResult", "validate_target", "write_report"]
