"""Real Gaunt coefficients ∫ Y_1 Y_2 Y_3 dΩ of shspec's real orthonormal harmonics.

Derivation.  Write each real harmonic through the complex ones (with the Condon–Shortley phase),
S_l^m = Σ_μ U(m, μ) Y_l^μ, where for a = |m| > 0

    U(a, a) = (−1)^a/√2,   U(a, −a) = 1/√2,          (cos aφ)
    U(−a, −a) = i/√2,      U(−a, a) = −i (−1)^a/√2,   (sin aφ)

and U(0, 0) = 1.  Then ∫ S_1 S_2 S_3 = Σ_μ U U U ∫ Y^μ1 Y^μ2 Y^μ3 with the complex Gaunt coefficient

    ∫ Y^μ1 Y^μ2 Y^μ3 dΩ = sqrt[(2l1+1)(2l2+1)(2l3+1)/(4π)] (l1 l2 l3; 0 0 0) (l1 l2 l3; μ1 μ2 μ3),

which needs μ1 + μ2 + μ3 = 0.  With a, b, c the |m|'s this gives the selection rule on the orders:

* one of a, b, c is the sum of the other two (c = a + b, or a = b + c, or b = a + c), and
* the number of negative m's is even (0 or 2): cos·cos and sin·sin make cos, cos·sin makes sin,

besides l1 + l2 + l3 even and the triangle inequality from the (0 0 0) symbol.  The only μ that enter are ±μ* for
one pattern μ*, and since l1 + l2 + l3 is even the complex Gaunt coefficient is the same for μ* and −μ*, so

    G = Re[U(m1,μ1*) U(m2,μ2*) U(m3,μ3*) + U(m1,−μ1*) U(m2,−μ2*) U(m3,−μ3*)] · Gaunt(μ*)

(one term when μ* = 0).  The factor in brackets is one of 0, ±1, ±1/√2, ±1/2.  Because a + b + c is even whenever
the rule holds, the result does not depend on the Condon–Shortley phase: pyshtools' ``csphase=1`` real harmonics
(no phase) give the same coefficients.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..core.checks import check_int
from ..errors import InvalidArgumentError
from ..sphere.harmonics import MAX_DEGREE
from .wigner import family_into, family_range

__all__ = ["real_gaunt", "order_factor"]

_SQRT_HALF = math.sqrt(0.5)
_INV_4PI = 1.0 / (4.0 * math.pi)


@nb.njit(cache=True, nogil=True)
def _u(m, mu):
    """U(m, μ): coefficient of Y^μ in the real harmonic S^m (same l); zero unless |μ| = |m|."""
    a = abs(m)
    if abs(mu) != a:
        return 0.0 + 0.0j
    if m == 0:
        return 1.0 + 0.0j
    parity = 1.0 if a % 2 == 0 else -1.0
    if m > 0:
        return complex(parity * _SQRT_HALF if mu == a else _SQRT_HALF, 0.0)
    if mu == -a:
        return complex(0.0, _SQRT_HALF)
    return complex(0.0, -parity * _SQRT_HALF)


@nb.njit(cache=True, nogil=True)
def order_factor(m1, m2, m3, mu1, mu2, mu3):
    """Re[U U U(μ) + U U U(−μ)]: the factor turning the complex Gaunt coefficient of pattern μ into the real one."""
    z = _u(m1, mu1) * _u(m2, mu2) * _u(m3, mu3)
    if mu1 != 0 or mu2 != 0 or mu3 != 0:
        z += _u(m1, -mu1) * _u(m2, -mu2) * _u(m3, -mu3)
    return z.real


@nb.njit(cache=True, nogil=True)
def _pattern(m1, m2, m3):
    """(ok, μ*) for the real orders: the complex order pattern that the real Gaunt coefficient reduces to."""
    a, b, c = abs(m1), abs(m2), abs(m3)
    if c == a + b:
        return True, a, b, -c
    if a == b + c:
        return True, a, -b, -c
    if b == a + c:
        return True, -a, b, -c
    return False, 0, 0, 0


@nb.njit(cache=True, nogil=True)
def _real_gaunt(l1, m1, l2, m2, l3, m3):
    if (l1 + l2 + l3) % 2 == 1 or l3 < abs(l1 - l2) or l3 > l1 + l2:
        return 0.0
    ok, mu1, mu2, mu3 = _pattern(m1, m2, m3)
    if not ok:
        return 0.0
    f = order_factor(m1, m2, m3, mu1, mu2, mu3)
    if f == 0.0:
        return 0.0
    # both 3j symbols as families over l3 (the cyclic permutation (l3 l1 l2) leaves them unchanged)
    jmin0, jmax0 = family_range(l1, l2, 0, 0)
    w0 = np.empty(jmax0 - jmin0 + 1)
    family_into(l1, l2, 0, 0, w0)
    jmin, jmax = family_range(l1, l2, mu1, mu2)
    if l3 < jmin:
        return 0.0
    w = np.empty(jmax - jmin + 1)
    family_into(l1, l2, mu1, mu2, w)
    pref = math.sqrt((2.0 * l1 + 1.0) * (2.0 * l2 + 1.0) * (2.0 * l3 + 1.0) * _INV_4PI)
    return f * pref * w0[l3 - jmin0] * w[l3 - jmin]


def real_gaunt(l1: int, m1: int, l2: int, m2: int, l3: int, m3: int) -> float:
    """∫_{S²} Y_{l1 m1} Y_{l2 m2} Y_{l3 m3} dΩ for shspec's real orthonormal harmonics.

    Parameters
    ----------
    l1, m1, l2, m2, l3, m3 : int
        Degrees l >= 0 and orders |m| <= l (m < 0: the sin(|m|φ) harmonic).

    Returns
    -------
    float
        The coefficient (dimensionless: the harmonics are orthonormal on the unit sphere).  Exactly 0.0 when a
        selection rule fails (see the module docstring).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import real_gaunt
    >>> round(real_gaunt(0, 0, 0, 0, 0, 0) * np.sqrt(4 * np.pi), 15)   # the integral of Y00^3 is 1/sqrt(4 pi)
    1.0
    """
    vals = []
    for name, v in (("l1", l1), ("m1", m1), ("l2", l2), ("m2", m2), ("l3", l3), ("m3", m3)):
        vals.append(check_int(v, name, minimum=None))
    for l, m, name in ((vals[0], vals[1], "1"), (vals[2], vals[3], "2"), (vals[4], vals[5], "3")):
        if l < 0 or l > MAX_DEGREE:
            raise InvalidArgumentError(f"l{name} = {l} is outside 0..{MAX_DEGREE}")
        if abs(m) > l:
            raise InvalidArgumentError(f"|m{name}| = {abs(m)} exceeds l{name} = {l}")
    return float(_real_gaunt(*vals))
