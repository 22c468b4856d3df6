"""Argument checks shared by every public function: one wording for one kind of mistake."""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError

__all__ = ["check_int", "check_float", "check_choice", "check_options", "real_array", "finite_array"]


def check_int(value, name: str, *, minimum: int | None = 0, maximum: int | None = None,
              allow_none: bool = False) -> int | None:
    """``value`` as an int after checking that it is an integer (not a bool) in [minimum, maximum].

    Raises
    ------
    InvalidArgumentError
        Naming ``name``, the bound and the value.
    """
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InvalidArgumentError(f"{name} must be an integer, got {value!r}")
    value = int(value)
    if minimum is not None and value < minimum:
        raise InvalidArgumentError(f"{name} must be an integer >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise InvalidArgumentError(f"{name} must be an integer <= {maximum}, got {value}")
    return value


def check_float(value, name: str, *, minimum: float | None = None, positive: bool = False) -> float:
    """``value`` as a finite float, checked to be ≥ ``minimum`` (and > 0 if ``positive``).

    Raises
    ------
    InvalidArgumentError
        Naming ``name`` and the value.
    """
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise InvalidArgumentError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(value):
        raise InvalidArgumentError(f"{name} must be finite, got {value}")
    if positive and not value > 0:
        raise InvalidArgumentError(f"{name} must be > 0, got {value}")
    if minimum is not None and value < minimum:
        raise InvalidArgumentError(f"{name} must be >= {minimum:g}, got {value}")
    return value


def check_choice(value, name: str, choices) -> str:
    """``value`` after checking that it is one of the strings ``choices`` (an array or another type is refused by
    name, not by numpy's "truth value of an array is ambiguous").

    Raises
    ------
    InvalidArgumentError
        Naming ``name``, the choices and the value.
    """
    if not isinstance(value, str) or value not in choices:
        raise InvalidArgumentError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value


def real_array(value, name: str, *, error: type[Exception] = InvalidArgumentError) -> np.ndarray:
    """``value`` as a float64 array, refusing what a plain ``np.asarray(value, dtype=float)`` would mangle.

    Complex values are refused, not cast (numpy's cast drops the imaginary part with only a ComplexWarning);
    strings, ragged lists and other non-numeric objects are refused by name instead of raising a bare
    ``TypeError`` or ``ValueError``.

    Raises
    ------
    InvalidArgumentError (or ``error``)
        Naming ``name`` and what was wrong.
    """
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nested lists
        raise error(f"{name} must be a numeric array: {exc}") from None
    if np.iscomplexobj(arr):
        raise error(f"{name} must be real, got complex values (dtype {arr.dtype}); pass the real part explicitly "
                    "if it is what you mean")
    if arr.dtype.kind not in "biuf":
        try:
            arr = arr.astype(float)
        except (TypeError, ValueError):
            raise error(f"{name} must be numeric, got {type(value).__name__} of {arr.dtype}") from None
    return np.asarray(arr, dtype=np.float64)


def finite_array(value, name: str, shape: tuple) -> np.ndarray:
    """``value`` as a float64 array of ``shape`` with finite entries (:func:`real_array` first).

    A wrong shape and a NaN are told apart: the message names the shape expected and given, or the first entry
    that is not finite (a NaN in an array of the right shape is not a shape problem).

    Raises
    ------
    InvalidArgumentError
        Naming ``name`` and the problem.
    """
    arr = real_array(value, name)
    if arr.shape != tuple(shape):
        raise InvalidArgumentError(f"{name} must have shape {tuple(shape)}, got shape {arr.shape}")
    bad = np.argwhere(~np.isfinite(arr))
    if bad.size:
        where = tuple(int(i) for i in bad[0])
        raise InvalidArgumentError(f"{name} must be finite; entry {where[0] if len(where) == 1 else where} is "
                                   f"{arr[where]}")
    return arr


def check_options(options, cls: type, name: str = "options"):
    """``options``, or ``cls()`` when it is None, after checking that it is an instance of the options class ``cls``.

    Raises
    ------
    InvalidArgumentError
        Naming the argument (``name``), the class expected and the type given.
    """
    opt = options if options is not None else cls()
    if not isinstance(opt, cls):
        raise InvalidArgumentError(f"{name} must be {cls.__name__}, got {type(opt).__name__}")
    return opt
