"""Double-double arithmetic for the exact 3j paths (numba).

A value is an unevaluated sum hi + lo with |lo| <= ulp(hi)/2, about 106 bits.  The
error-free transformations are Knuth's TwoSum and Dekker's TwoProd with Veltkamp splitting (numba has no fma on
Python < 3.13); they rely on IEEE round-to-nearest without contraction or reassociation, which is what numba
emits as long as fastmath stays off (the tests check TwoProd against exact rationals).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_SPLIT = 134217729.0  # 2**27 + 1
_DD_HUGE = 2.0 ** 500
_DD_TINY = 2.0 ** -500
_DD_ZERO = 2.0 ** -93  # cancellation below this fraction of the terms: an exact zero


@nb.njit(cache=True, nogil=True)
def _two_sum(a, b):
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


@nb.njit(cache=True, nogil=True)
def _quick_two_sum(a, b):
    # needs |a| >= |b| (or a == 0)
    s = a + b
    return s, b - (s - a)


@nb.njit(cache=True, nogil=True)
def _two_prod(a, b):
    p = a * b
    t = _SPLIT * a
    ah = t - (t - a)
    al = a - ah
    t = _SPLIT * b
    bh = t - (t - b)
    bl = b - bh
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


@nb.njit(cache=True, nogil=True)
def _dd_add(ah, al, bh, bl):
    s, e = _two_sum(ah, bh)
    t, f = _two_sum(al, bl)
    e += t
    s, e = _quick_two_sum(s, e)
    e += f
    return _quick_two_sum(s, e)


@nb.njit(cache=True, nogil=True)
def _dd_mul(ah, al, bh, bl):
    p, e = _two_prod(ah, bh)
    e += ah * bl + al * bh
    return _quick_two_sum(p, e)


@nb.njit(cache=True, nogil=True)
def _dd_mul_d(ah, al, b):
    p, e = _two_prod(ah, b)
    e += al * b
    return _quick_two_sum(p, e)


@nb.njit(cache=True, nogil=True)
def _dd_div(ah, al, bh, bl):
    # long division with one correction step: relative error ~ 2**-104
    q1 = ah / bh
    ph, pl = _dd_mul_d(bh, bl, q1)
    rh, rl = _dd_add(ah, al, -ph, -pl)
    q2 = rh / bh
    ph, pl = _dd_mul_d(bh, bl, q2)
    rh, rl = _dd_add(rh, rl, -ph, -pl)
    q3 = rh / bh
    q1, q2 = _quick_two_sum(q1, q2)
    return _dd_add(q1, q2, q3, 0.0)


@nb.njit(cache=True, nogil=True)
def _dd_sqrt(ah, al):
    # one Newton (Heron) correction of the double square root: sqrt(a) = x + (a - x²) / (2x)
    if ah <= 0.0:
        return 0.0, 0.0
    x = math.sqrt(ah)
    p, e = _two_prod(x, x)
    r = ((ah - p) - e + al) / (2.0 * x)
    return _quick_two_sum(x, r)


@nb.njit(cache=True, nogil=True)
def _dd_from_int(k):
    # an int64 as an exact double-double (|k| < 2**63)
    h = float(k)
    return h, float(k - np.int64(h))
