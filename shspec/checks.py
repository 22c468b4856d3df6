"""Argument checks shared by modules that have no domain-specific helper (counts, worker numbers, sizes)."""

from __future__ import annotations

import numpy as np

from .errors import InvalidArgumentError

__all__ = ["check_int"]


def check_int(value, name: str, *, minimum: int = 0, maximum: int | None = None) -> int:
    """Return ``value`` as an int after checking that it is an integer (not a bool) in [minimum, maximum].

    Raises
    ------
    InvalidArgumentError
        Naming ``name`` and the offending value.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InvalidArgumentError(f"{name} must be an integer, got {value!r}")
    value = int(value)
    if value < minimum:
        raise InvalidArgumentError(f"{name} must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise InvalidArgumentError(f"{name} must be <= {maximum}, got {value}")
    return value
