"""Wigner 3j symbols by the Schulten–Gordon three-term recursion (numba).

A *family* is the set of symbols

    ( j1  j2  j3 )
    ( m1  m2  m3 ),   m1 = −m2 − m3,   j1 = jmin … jmax,

for fixed (j2, j3, m2, m3), with jmin = max(|j2 − j3|, |m1|) and jmax = j2 + j3.  The symbols obey the recursion
(Schulten & Gordon, J. Math. Phys. 16, 1961 (1975))

    j1 A(j1+1) w(j1+1) + B(j1) w(j1) + (j1+1) A(j1) w(j1−1) = 0,
    A(j1) = sqrt[(j1² − (j2−j3)²) ((j2+j3+1)² − j1²) (j1² − m1²)],
    B(j1) = −(2 j1 + 1) [j2(j2+1) m1 − j3(j3+1) m1 − j1(j1+1)(m3 − m2)].

Near each end of the range the symbols lie in a classically forbidden region where they grow away from the end;
there each end's recursion runs in its stable direction (the two-term start of Luscombe & Luban, Phys. Rev. E 57,
7274 (1998), w(jmin±1) from w(jmin) alone, because A vanishes at the ends).  The forward sweep from jmin stops at
the first local maximum of |w|, where the oscillatory region begins, and the backward sweep from jmax runs down to
meet it; the two are matched by least squares on the two overlapping points, which are never near a node.
Intermediate values are rescaled against overflow, the family is normalized by Σ (2 j1 + 1) w² = 1 and the sign is
fixed by sgn w(jmax) = (−1)^(j2 − j3 − m1).

Two implementations of the same sweeps:

* :func:`family_into` in double precision, for the hot loop of the Gaunt table builder.  Its error is absolute:
  typically a few 1e-15 × (largest |w| of the family), at most 1.2e-14 × max|w| measured at l ≤ 60 and 5e-14 at
  l ≤ 1000, so the relative error grows near accidental near-zeros of a family (measured up to 4e-11 at l ≤ 60,
  1e-9 at l ≤ 200).
* :func:`~shspec.gaunt.wigner_dd.family_into_dd` in double-double arithmetic (~32 digits, error-free TwoSum/TwoProd), rounded to double at
  the end; the public :func:`~shspec.gaunt.wigner_dd.wigner3j_family` and
  :func:`~shspec.gaunt.wigner_dd.wigner3j` use it.  Every nonzero symbol with l ≤ 60 is
  within a few ulps (measured max 4.4e-16 relative, requirement 1e-13), and exact zeros (structural or not) are
  returned as exact 0.  About 10× the cost of the double path.

Measured accuracy per degree band up to l = 1000 against WIGXJPF (exact to final rounding), and the cost per family
of both paths: :doc:`/wigner_accuracy`.  Only integer arguments are
supported (the spherical-harmonic case).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .doubledouble import _dd_div, _dd_mul, _dd_mul_d, _dd_sqrt

__all__ = ["family_range", "family_into", "family_upto_into", "factorial_table"]

_HUGE = 1.0e150
_TINY = 1.0 / _HUGE


@nb.njit(cache=True, nogil=True)
def _coef_a(j1, j2, j3, m1):
    x = float(j1)
    d = float(j2 - j3)
    s = float(j2 + j3 + 1)
    mm = float(m1)
    return math.sqrt((x * x - d * d) * (s * s - x * x) * (x * x - mm * mm))


@nb.njit(cache=True, nogil=True)
def _coef_b(j1, j2, j3, m1, m2, m3):
    x = float(j1)
    return -(2.0 * x + 1.0) * (
        float(j2) * (j2 + 1) * m1 - float(j3) * (j3 + 1) * m1 - x * (x + 1.0) * (m3 - m2)
    )


@nb.njit(cache=True, nogil=True)
def family_range(j2, j3, m2, m3):
    """(jmin, jmax) of the family over j1; jmin > jmax when the family is empty."""
    m1 = -(m2 + m3)
    if abs(m2) > j2 or abs(m3) > j3 or j2 < 0 or j3 < 0:
        return 1, 0
    jmin = max(abs(j2 - j3), abs(m1))
    return jmin, j2 + j3


@nb.njit(cache=True, nogil=True)
def _step_up(w, p, jmin, j2, j3, m1, m2, m3, a_j):
    """w[p+1] from w[p], w[p−1], given a_j = A(jmin+p); returns A(jmin+p+1) for the next step.

    Rescales everything so far when the growing values approach overflow.
    """
    j = jmin + p
    a_next = _coef_a(j + 1, j2, j3, m1)
    w[p + 1] = -(_coef_b(j, j2, j3, m1, m2, m3) * w[p] + (j + 1) * a_j * w[p - 1]) / (j * a_next)
    if abs(w[p + 1]) > _HUGE:
        for t in range(p + 2):
            w[t] *= _TINY
    return a_next


@nb.njit(cache=True, nogil=True)
def _step_down(w, p, jmin, j2, j3, m1, m2, m3, a_next):
    """w[p−1] from w[p], w[p+1], given a_next = A(jmin+p+1); returns A(jmin+p) for the next step."""
    j = jmin + p
    a_j = _coef_a(j, j2, j3, m1)
    w[p - 1] = -(j * a_next * w[p + 1] + _coef_b(j, j2, j3, m1, m2, m3) * w[p]) / ((j + 1) * a_j)
    if abs(w[p - 1]) > _HUGE:
        for t in range(p - 1, w.size):
            w[t] *= _TINY
    return a_j


@nb.njit(cache=True, nogil=True)
def family_into(j2, j3, m2, m3, out):
    """Fill ``out[0:n]`` with w(jmin), …, w(jmax) of one family in double precision; returns (jmin, n).

    ``out`` needs n = j2 + j3 − jmin + 1 entries.  This is the fast path used by the Gaunt table builder: the error
    is absolute, a few 1e-15 × max|w| typically and ≤ 1.2e-14 × max|w| measured at l ≤ 60 (tested ≤ 2e-14), so
    symbols near an accidental node of the family have larger *relative* errors; :func:`family_into_dd` is the
    accurate twin.  Cost (one core): ~0.2 µs per family at l ≤ 10, ~1 µs at l ≤ 60, ~20 µs at l ≤ 1000.
    """
    jmin, jmax = family_range(j2, j3, m2, m3)
    if jmin > jmax:
        return jmin, 0
    m1 = -(m2 + m3)
    n = jmax - jmin + 1
    if n == 1:
        sign = 1.0 if (j2 - j3 - m1) % 2 == 0 else -1.0
        out[0] = sign / math.sqrt(2.0 * jmin + 1.0)
        return jmin, 1

    back = np.empty(n)
    # backward sweep from jmax through the upper forbidden region, where the values grow downwards; A(j) is
    # carried from one step to the next, so each step costs one square root
    a_down = _coef_a(jmax, j2, j3, m1)
    back[n - 1] = 1.0
    back[n - 2] = -_coef_b(jmax, j2, j3, m1, m2, m3) / ((jmax + 1) * a_down)
    pb = n - 2  # lowest position filled by the backward sweep
    while pb > 0 and abs(back[pb]) > abs(back[pb + 1]):
        a_down = _step_down(back, pb, jmin, j2, j3, m1, m2, m3, a_down)
        pb -= 1
    if jmin == 0:
        # j2 = j3 and m1 = 0: no lower forbidden region, the backward sweep may run to the end
        while pb > 0:
            a_down = _step_down(back, pb, jmin, j2, j3, m1, m2, m3, a_down)
            pb -= 1
        for t in range(n):
            out[t] = back[t]
        return _normalize(out, n, jmin, j2, j3, m1, 1.0)

    # forward sweep from jmin through the lower forbidden region
    a_up = _coef_a(jmin + 1, j2, j3, m1)
    out[0] = 1.0
    out[1] = -_coef_b(jmin, j2, j3, m1, m2, m3) / (jmin * a_up)
    pf = 1  # highest position filled by the forward sweep
    while pf < pb + 1 and abs(out[pf]) > abs(out[pf - 1]):
        a_up = _step_up(out, pf, jmin, j2, j3, m1, m2, m3, a_up)
        pf += 1
    # through the oscillatory region both directions are neutral: meet in its middle to halve the longer run
    mid = pb if pf > pb else (pf + pb) // 2
    while pf < mid + 1:
        a_up = _step_up(out, pf, jmin, j2, j3, m1, m2, m3, a_up)
        pf += 1
    while pb > mid:
        a_down = _step_down(back, pb, jmin, j2, j3, m1, m2, m3, a_down)
        pb -= 1
    # least-squares match on the two points both sweeps hold; they cannot both be near a node
    num = out[mid] * back[mid] + out[mid + 1] * back[mid + 1]
    den = back[mid] * back[mid] + back[mid + 1] * back[mid + 1]
    scale = num / den
    for t in range(mid, n):
        out[t] = back[t] * scale
    return _normalize(out, n, jmin, j2, j3, m1, scale)


@nb.njit(cache=True, nogil=True)
def _normalize(out, n, jmin, j2, j3, m1, sign_last):
    # the sum is accumulated with the largest values scaled to O(1) so that it neither overflows nor underflows.
    # sign_last carries the sign of the unnormalized w(jmax): the value itself may have underflowed to 0 in the
    # rescalings when the upper forbidden region is deep (which used to flip whole families at large l).
    big = 0.0
    for t in range(n):
        big = max(big, abs(out[t]))
    s = 0.0
    for t in range(n):
        v = out[t] / big
        s += (2.0 * (jmin + t) + 1.0) * v * v
    c = 1.0 / (big * math.sqrt(s))
    if (sign_last < 0) == ((j2 - j3 - m1) % 2 == 0):
        c = -c
    for t in range(n):
        out[t] *= c
    return jmin, n


# the forward recursion is stable through the lower forbidden region (values grow) and neutral through the
# oscillatory one; it becomes unstable only in the upper forbidden region, where values decay.  There the truncated
# sweep gives up and the caller falls back to the two-sided full family.

_SCALE_EXP = 500  # rescaling by exact powers of two keeps track of the scale without rounding


@nb.njit(cache=True)
def factorial_table(nmax):
    """n! = (hi[n] + lo[n]) · 2**exp[n] for n = 0 … nmax, hi in [0.5, 1): double-double mantissas, exact exponents."""
    hi = np.empty(nmax + 1)
    lo = np.empty(nmax + 1)
    ex = np.empty(nmax + 1, dtype=np.int64)
    h, l, e = 0.5, 0.0, 1
    hi[0], lo[0], ex[0] = h, l, e
    for n in range(1, nmax + 1):
        h, l = _dd_mul_d(h, l, float(n))
        m, k = math.frexp(h)
        h, l = m, math.ldexp(l, -k)
        e += k
        hi[n], lo[n], ex[n] = h, l, e
    return hi, lo, ex


@nb.njit(cache=True, nogil=True)
def _factorial_ratio_sqrt(num, den, fh, fl, fe):
    """sqrt(Π num! / Π den!) as (mantissa, exponent of two), the mantissa rounded from double-double."""
    h, l, e = 1.0, 0.0, 0
    for n in num:
        h, l = _dd_mul(h, l, fh[n], fl[n])
        e += fe[n]
    for n in den:
        h, l = _dd_div(h, l, fh[n], fl[n])
        e -= fe[n]
    m, k = math.frexp(h)
    h, l = m, math.ldexp(l, -k)
    e += k
    if e % 2 != 0:
        h, l = 2.0 * h, 2.0 * l
        e -= 1
    h, l = _dd_sqrt(h, l)
    return h + l, e // 2


@nb.njit(cache=True, nogil=True)
def _first_symbol(j2, j3, m2, m3, jmin, fh, fl, fe):
    """The symbol (jmin j2 j3; m1 m2 m3) in closed form, as (signed mantissa, exponent of two)."""
    m1 = -(m2 + m3)
    j1 = jmin
    if j1 == abs(j2 - j3):
        # stretched: the largest j is the sum of the other two; (a b a+b; α β −α−β) after a column swap if needed
        if j2 >= j3:
            a, b, al, be = j1, j3, m1, m3
            sign = 1 if (j1 + j2 + j3) % 2 == 0 else -1  # odd permutation (j1 j3 j2)
        else:
            a, b, al, be = j1, j2, m1, m2
            sign = 1
        if (a - b + al + be) % 2 != 0:
            sign = -sign
        num = (2 * a, 2 * b, a + b + al + be, a + b - al - be)
        den = (2 * a + 2 * b + 1, a + al, a - al, b + be, b - be)
    else:
        # j1 = |m1|: (j1 j2 j3; j1, −j1−m3, m3), after flipping every m when m1 = −j1
        sign = 1
        if m1 < 0:
            if (j1 + j2 + j3) % 2 != 0:
                sign = -1
            m3 = -m3
        if (-j1 + j2 + m3) % 2 != 0:
            sign = -sign
        num = (2 * j1, -j1 + j2 + j3, j1 + j2 + m3, j3 - m3)
        den = (j1 + j2 + j3 + 1, j1 - j2 + j3, j1 + j2 - j3, -j1 + j2 - m3, j3 + m3)
    m, e = _factorial_ratio_sqrt(num, den, fh, fl, fe)
    return sign * m, e


@nb.njit(cache=True, nogil=True)
def family_upto_into(j2, j3, m2, m3, jtop, out, fh, fl, fe):
    """The family from jmin up to ``jtop`` by the forward recursion from the exact first symbol, as far as it is stable.

    Returns (jmin, n, ok): ``out[0:n]`` holds w(jmin … jmin + n − 1).  ok is True when that is the whole range up to
    ``jtop``; otherwise the recursion reached the upper forbidden region (or jtop = jmax, or jmin = 0, where the
    recursion has no two-term start) and the caller must take w(jmin + n …) from :func:`family_into`.  Each value
    depends only on the family and its j, never on ``jtop``: the sweep is the same prefix whatever ``jtop`` is, its
    rescalings only touch the two values the recursion carries on, and where it stops does not depend on ``jtop``
    either, so a table built for a smaller La holds the very same bits as one built for a larger La and restricted.
    ``fh, fl, fe`` is :func:`factorial_table` of at least j2 + j3 + jtop + 1.
    """
    jmin, jmax = family_range(j2, j3, m2, m3)
    if jmin > jmax or jmin == 0 or jtop < jmin:
        return jmin, 0, False
    m1 = -(m2 + m3)
    ok = jtop < jmax
    n = min(jtop, jmax - 1) - jmin + 1  # w(jmax) is never taken from the forward sweep
    if n == 0:
        return jmin, 0, False
    mant, e = _first_symbol(j2, j3, m2, m3, jmin, fh, fl, fe)
    # w(jmin + t) = r_t · mant · 2**(e + _SCALE_EXP · k_t), r the unnormalized sweep and k_t the rescalings before t
    out[0] = math.ldexp(mant, e)
    if n == 1:
        return jmin, 1, ok
    a_next = _coef_a(jmin + 1, j2, j3, m1)
    prev, cur = 1.0, -_coef_b(jmin, j2, j3, m1, m2, m3) / (jmin * a_next)
    out[1] = math.ldexp(cur * mant, e)
    a_j = a_next
    for p in range(1, n - 1):
        j = jmin + p
        a_next = _coef_a(j + 1, j2, j3, m1)
        b = _coef_b(j, j2, j3, m1, m2, m3)
        new = -(b * cur + (j + 1) * a_j * prev) / (j * a_next)
        # real characteristic roots with decaying values: the upper forbidden region, unstable forwards
        if b * b >= 4.0 * j * (j + 1) * a_j * a_next and abs(new) < abs(cur):
            return jmin, p + 1, False
        prev, cur = cur, new
        if abs(cur) > _HUGE:
            prev, cur = math.ldexp(prev, -_SCALE_EXP), math.ldexp(cur, -_SCALE_EXP)
            e += _SCALE_EXP
        out[p + 1] = math.ldexp(cur * mant, e)
        a_j = a_next
    return jmin, n, ok
