"""Real orthonormal spherical harmonics: flat indexing and conversion to and from pyshtools.

shspec uses the real harmonics of pyshtools with ``normalization='ortho'`` and ``csphase=1``: for m > 0 the
cos(mφ) function, for m < 0 the sin(|m|φ) function, each of unit L2 norm on the unit sphere.  A coefficient vector
of band limit L has ``(L+1)**2`` entries in the flat order ``i = l*l + l + m``.

Normalization.  A flat vector is shspec's own and orthonormal.  A ``pyshtools.SHCoeffs`` says its normalization and
is converted.  A raw cilm array says nothing, and pyshtools' default is '4pi' (ρ read as orthonormal would then be
√(4π) too small, its spectrum √(4π) too large, and nothing would tell): :func:`as_coefficients`, which every
routine taking ρ uses, accepts one only with its ``normalization`` given, and :func:`cilm_to_vector` converts any.
"""

from __future__ import annotations

import numpy as np
import pyshtools

from ..core.checks import real_array
from ..errors import BandLimitError, ConventionError, InvalidArgumentError

__all__ = [
    "MAX_DEGREE",
    "ncoeffs",
    "flat_index",
    "degree_order",
    "degrees",
    "lmax_of_size",
    "vector_to_cilm",
    "cilm_to_vector",
    "vector_to_shcoeffs",
    "shcoeffs_to_vector",
    "as_coefficients",
    "NORMALIZATIONS",
]

#: The normalizations of real harmonics pyshtools knows (shspec's own is 'ortho').
NORMALIZATIONS = ("ortho", "4pi", "schmidt", "unnorm")

#: Largest band limit any shspec routine accepts; beyond it tables and grids no longer fit a workstation.
MAX_DEGREE = 2000


def check_degree(value, name: str, *, minimum: int = 0, maximum: int = MAX_DEGREE) -> int:
    """Return ``value`` as an int after checking that it is an integer in [minimum, maximum]."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise BandLimitError(f"{name} must be an integer, got {value!r}")
    value = int(value)
    if value < minimum:
        raise BandLimitError(f"{name} must be >= {minimum}, got {value}")
    if value > maximum:
        raise BandLimitError(f"{name} = {value} is absurdly large (the limit is {maximum})")
    return value


def ncoeffs(lmax: int) -> int:
    """Number of real harmonics of degree <= lmax, ``(lmax+1)**2``.

    Examples
    --------
    >>> from shspec import ncoeffs
    >>> ncoeffs(3)          # (L + 1)^2 coefficients up to degree 3
    16
    """
    lmax = check_degree(lmax, "lmax")
    return (lmax + 1) ** 2


def flat_index(l, m):
    """Flat index ``l*l + l + m`` of the harmonic (l, m); works elementwise on arrays.

    Examples
    --------
    >>> from shspec import flat_index
    >>> flat_index(2, -1)   # l*l + l + m
    5
    """
    l = real_array(l, "l")
    m = real_array(m, "m")
    if np.any(l != np.round(l)) or np.any(m != np.round(m)):
        raise InvalidArgumentError("the degree l and order m must be integers")
    try:
        l, m = np.broadcast_arrays(l.astype(np.int64), m.astype(np.int64))
    except ValueError:
        raise InvalidArgumentError(f"l and m of shapes {l.shape} and {m.shape} do not broadcast") from None
    if np.any(l < 0) or np.any(np.abs(m) > l):
        raise InvalidArgumentError("need l >= 0 and |m| <= l")
    return l * l + l + m


def degree_order(lmax: int) -> tuple[np.ndarray, np.ndarray]:
    """Degrees and orders of the flat basis up to lmax.

    Returns
    -------
    l, m : (N,) int64 arrays, N = (lmax+1)**2, with ``flat_index(l, m) == arange(N)``.

    Examples
    --------
    >>> from shspec import degree_order
    >>> degree_order(1)
    (array([0, 1, 1, 1]), array([ 0, -1,  0,  1]))
    """
    lmax = check_degree(lmax, "lmax")
    l = np.repeat(np.arange(lmax + 1), 2 * np.arange(lmax + 1) + 1)
    m = np.arange((lmax + 1) ** 2) - l * l - l
    return l, m


def degrees(lmax: int) -> np.ndarray:
    """(N,) int64 array of the degree of each flat index up to lmax."""
    return degree_order(lmax)[0]


def lmax_of_size(n: int) -> int:
    """Band limit L of a flat vector of length n = (L+1)**2; raises if n is not a square."""
    root = int(round(np.sqrt(n)))
    if n < 1 or root * root != n:
        raise InvalidArgumentError(f"a coefficient vector has (L+1)**2 entries; {n} is not a square")
    return root - 1


def vector_to_cilm(a) -> np.ndarray:
    """Flat coefficient vector (N,) -> pyshtools array cilm (2, L+1, L+1).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import vector_to_cilm
    >>> cilm = vector_to_cilm(np.arange(9.0))   # pyshtools' layout: [cos/sin, l, m]
    >>> cilm.shape, cilm[0, 2, 1], cilm[1, 2, 1]   # a_{2,1} and a_{2,-1}
    ((2, 3, 3), 7.0, 5.0)
    """
    a = _finite_vector(a, "coefficient vector")
    lmax = lmax_of_size(a.size)
    l, m = degree_order(lmax)
    cilm = np.zeros((2, lmax + 1, lmax + 1))
    pos = m >= 0
    cilm[0, l[pos], m[pos]] = a[pos]
    cilm[1, l[~pos], -m[~pos]] = a[~pos]
    return cilm


def cilm_to_vector(cilm, lmax: int | None = None, *, normalization: str = "ortho", csphase: int = 1) -> np.ndarray:
    """pyshtools array cilm (2, L+1, L+1) -> flat coefficient vector (N,), truncated or zero-padded to lmax.

    ``normalization`` and ``csphase`` are the array's, as pyshtools names them (:data:`NORMALIZATIONS`; default
    shspec's own, 'ortho' with csphase 1); another is converted by pyshtools.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import cilm_to_vector, vector_to_cilm
    >>> a = np.arange(9.0)
    >>> bool(np.array_equal(cilm_to_vector(vector_to_cilm(a)), a))
    True
    """
    cilm = real_array(cilm, "cilm")
    if normalization not in NORMALIZATIONS or csphase not in (1, -1):
        raise ConventionError(f"a cilm array's normalization is one of {NORMALIZATIONS} and its csphase 1 or -1, got "
                              f"{normalization!r} and {csphase!r}")
    if cilm.ndim != 3 or cilm.shape[0] != 2 or cilm.shape[1] != cilm.shape[2]:
        raise InvalidArgumentError(f"a cilm array has shape (2, L+1, L+1), got {cilm.shape}")
    if not np.all(np.isfinite(cilm)):
        raise InvalidArgumentError("cilm contains NaN or inf")
    sine0 = np.flatnonzero(cilm[1, :, 0] != 0)
    if sine0.size:  # sin(0 phi) = 0: such a coefficient means nothing, and dropping it silently hides a mix-up
        l0 = int(sine0[0])
        raise ConventionError(f"cilm[1, {l0}, 0] = {cilm[1, l0, 0]:g} is a sine coefficient at order m = 0, which "
                              "does not exist; the array is probably in another layout")
    if normalization != "ortho" or csphase != 1:
        return shcoeffs_to_vector(pyshtools.SHCoeffs.from_array(cilm, normalization=normalization, csphase=csphase),
                                  lmax)
    have = cilm.shape[1] - 1
    lmax = have if lmax is None else check_degree(lmax, "lmax")
    l, m = degree_order(lmax)
    out = np.zeros(l.size)
    ok = l <= have
    pos = ok & (m >= 0)
    neg = ok & (m < 0)
    out[pos] = cilm[0, l[pos], m[pos]]
    out[neg] = cilm[1, l[neg], -m[neg]]
    return out


def vector_to_shcoeffs(a) -> pyshtools.SHCoeffs:
    """Flat coefficient vector -> ``pyshtools.SHCoeffs`` with normalization 'ortho' and csphase 1.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import vector_to_shcoeffs
    >>> coeffs = vector_to_shcoeffs(np.arange(9.0))
    >>> type(coeffs).__name__, coeffs.normalization, coeffs.csphase
    ('SHRealCoeffs', 'ortho', 1)
    """
    return pyshtools.SHCoeffs.from_array(vector_to_cilm(a), normalization="ortho", csphase=1)


def shcoeffs_to_vector(coeffs: pyshtools.SHCoeffs, lmax: int | None = None) -> np.ndarray:
    """``pyshtools.SHCoeffs`` (any normalization, real) -> flat vector in shspec's convention.

    Coefficients in another normalization or phase are converted by pyshtools; complex ones are refused.
    """
    if getattr(coeffs, "kind", "real") != "real":
        raise ConventionError("complex SHCoeffs are not supported; convert with .convert(kind='real')")
    if coeffs.normalization != "ortho" or coeffs.csphase != 1:
        coeffs = coeffs.convert(normalization="ortho", csphase=1)
    return cilm_to_vector(coeffs.coeffs, lmax)


def as_coefficients(value, lmax: int | None = None, *, normalization: str | None = None,
                    csphase: int = 1) -> np.ndarray:
    """Flat coefficient vector from a flat vector (shspec's, orthonormal), an SHCoeffs object (converted) or a cilm
    array whose ``normalization`` (and ``csphase``) the caller gives (module notes).

    Raises
    ------
    ConventionError
        For a cilm array without its ``normalization``, or a flat vector said to be in another than shspec's.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.sphere.harmonics import as_coefficients
    >>> cilm = np.zeros((2, 3, 3)); cilm[0, 0, 0] = 1.0     # rho = 1 in pyshtools' default, '4pi'
    >>> round(float(as_coefficients(cilm, normalization="4pi")[0]), 4)   # sqrt(4 pi): the same rho, orthonormal
    3.5449
    """
    if isinstance(value, pyshtools.SHCoeffs):
        return shcoeffs_to_vector(value, lmax)
    arr = real_array(value, "coefficients")
    if arr.ndim == 3:
        if normalization is None:
            raise ConventionError(
                "a cilm array does not say its normalization, and pyshtools' default ('4pi') is not shspec's "
                "('ortho'): give it (normalization='ortho', '4pi', 'schmidt' or 'unnorm'), or pass a "
                "pyshtools.SHCoeffs, which carries it, or flat coefficients")
        return cilm_to_vector(arr, lmax, normalization=normalization, csphase=csphase)
    if (normalization or "ortho") != "ortho" or csphase != 1:
        raise ConventionError("flat coefficients are shspec's own, orthonormal with csphase 1; a vector in another "
                              "normalization is given as a cilm array or an SHCoeffs")
    vec = _finite_vector(arr, "coefficient vector")
    if lmax is None:
        return vec
    have = lmax_of_size(vec.size)
    lmax = check_degree(lmax, "lmax")
    out = np.zeros(ncoeffs(lmax))
    n = min(vec.size, out.size)
    out[:n] = vec[:n]
    if have > lmax and np.any(vec[out.size:] != 0):
        raise BandLimitError(f"coefficients of degree up to {have} do not fit the band limit {lmax}")
    return out


def _finite_vector(a, what: str) -> np.ndarray:
    arr = real_array(a, what)
    if arr.ndim != 1:
        raise InvalidArgumentError(f"{what} must be one-dimensional, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.flatnonzero(~np.isfinite(arr))
        raise InvalidArgumentError(f"{what} has NaN or inf at flat index {bad[:5].tolist()}")
    return arr
