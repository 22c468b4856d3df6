"""End-to-end validation of the mesh path (the study's Section 2.4): spectra, factors and re-embedding side by side."""

from .validation import ValidationOptions, ValidationResult, validate_target, write_report

__all__ = ["ValidationOptions", "ValidationResult", "validate_target", "write_report"]
