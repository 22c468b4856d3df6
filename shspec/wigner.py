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
* :func:`family_into_dd` in double-double arithmetic (~32 digits, error-free TwoSum/TwoProd), rounded to double at
  the end; the public :func:`wigner3j_family` and :func:`wigner3j` use it.  Every nonzero symbol with l ≤ 60 is
  within a few ulps (measured max 4.4e-16 relative, requirement 1e-13), and exact zeros (structural or not) are
  returned as exact 0.  About 10× the cost of the double path.

Measured accuracy per degree band up to l = 1000 against WIGXJPF (exact to final rounding), and the cost per family
of both paths: docs/wigner_accuracy.md, produced by benchmarks/wigner_accuracy.py.  Only integer arguments are
supported (the spherical-harmonic case).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .errors import InvalidArgumentError
from .harmonics import MAX_DEGREE

__all__ = ["wigner3j", "wigner3j_family", "family_range", "family_into", "family_into_dd", "family_upto_into",
           "factorial_table"]

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


# ---------------------------------------------------------------------------------------------------------------
# Double-double arithmetic.  A value is an unevaluated sum hi + lo with |lo| <= ulp(hi)/2, about 106 bits.  The
# error-free transformations are Knuth's TwoSum and Dekker's TwoProd with Veltkamp splitting (numba has no fma on
# Python < 3.13); they rely on IEEE round-to-nearest without contraction or reassociation, which is what numba
# emits as long as fastmath stays off (the tests check TwoProd against exact rationals).

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


@nb.njit(cache=True, nogil=True)
def _coef_a_dd(j1, j2, j3, m1):
    # A(j1) with the three integer factors exact in double (each < 2**53) and the product and root in double-double
    x = float(j1)
    d = float(j2 - j3)
    s = float(j2 + j3 + 1)
    mm = float(m1)
    f1 = x * x - d * d
    f2 = s * s - x * x
    f3 = x * x - mm * mm
    if f1 <= 0.0 or f2 <= 0.0 or f3 <= 0.0:
        return 0.0, 0.0
    ph, pl = _two_prod(f1, f2)
    ph, pl = _dd_mul_d(ph, pl, f3)
    return _dd_sqrt(ph, pl)


@nb.njit(cache=True, nogil=True)
def _coef_b_int(j1, j2, j3, m1, m2, m3):
    # B(j1) is an integer; int64 keeps it exact for every argument the public functions accept
    j = np.int64(j1)
    c = np.int64(j2) * (j2 + 1) - np.int64(j3) * (j3 + 1)
    return -(2 * j + 1) * (c * m1 - j * (j + 1) * (m3 - m2))


@nb.njit(cache=True, nogil=True)
def _dd_step(c1h, c1l, w1h, w1l, c2h, c2l, w2h, w2l, dh, dl):
    # -(c1 w1 + c2 w2) / d.  When the two terms cancel to below the double-double noise, the true value is
    # indistinguishable from 0, and it is set to exactly 0: this reproduces the non-trivial (Diophantine) zeros of
    # the 3j symbols, e.g. (6 4 4; 2 -2 0), exactly, and changes any other value by less than the noise.
    ph, pl = _dd_mul(c1h, c1l, w1h, w1l)
    qh, ql = _dd_mul(c2h, c2l, w2h, w2l)
    sh, sl = _dd_add(ph, pl, qh, ql)
    if abs(sh) <= _DD_ZERO * (abs(ph) + abs(qh)):
        return 0.0, 0.0
    return _dd_div(-sh, -sl, dh, dl)


@nb.njit(cache=True, nogil=True)
def _dd_step_up(hi, lo, p, bh, bl, cuh, cul, cdh, cdl):
    # w[p+1] from w[p], w[p-1]; rescale everything so far when the growing values approach overflow
    hi[p + 1], lo[p + 1] = _dd_step(bh[p], bl[p], hi[p], lo[p], cuh[p], cul[p], hi[p - 1], lo[p - 1], cdh[p], cdl[p])
    if abs(hi[p + 1]) > _DD_HUGE:
        for t in range(p + 2):
            hi[t] *= _DD_TINY
            lo[t] *= _DD_TINY


@nb.njit(cache=True, nogil=True)
def _dd_step_down(kh, kl, p, bh, bl, cuh, cul, cdh, cdl):
    # w[p-1] from w[p], w[p+1]
    kh[p - 1], kl[p - 1] = _dd_step(cdh[p], cdl[p], kh[p + 1], kl[p + 1], bh[p], bl[p], kh[p], kl[p], cuh[p], cul[p])
    if abs(kh[p - 1]) > _DD_HUGE:
        for t in range(p - 1, kh.size):
            kh[t] *= _DD_TINY
            kl[t] *= _DD_TINY


@nb.njit(cache=True, nogil=True)
def family_into_dd(j2, j3, m2, m3, hi, lo):
    """Double-double twin of :func:`family_into`: the family as ``hi[0:n] + lo[0:n]``; returns (jmin, n).

    The same two-sided Schulten–Gordon sweeps as :func:`family_into`, with every coefficient (A as the root of an
    exact integer product, B as an exact integer) and every operation carried in double-double (~32 digits), so the
    rounding error of the recursion, even where it passes near a node, ends up far below one double ulp;
    ``hi`` alone is the correctly rounded double of ``hi + lo`` and is what :func:`wigner3j_family` returns.
    Structural zeros (B ≡ 0, e.g. all m = 0 with odd j1 + j2 + j3) come out as exact zeros.

    Cost (one core, measured by ``benchmarks/wigner_accuracy.py``): 6–10× the double :func:`family_into`,
    ~2 µs per family at l ≤ 10, ~7 µs at l ≤ 60, ~0.12 ms at l ≤ 1000 (see docs/wigner_accuracy.md).

    Parameters
    ----------
    j2, j3, m2, m3 : int
        As in :func:`family_into`.
    hi, lo : (>= n,) float64 arrays
        Overwritten in ``[0:n]`` with the leading and trailing parts of w(jmin), …, w(jmax).
    """
    jmin, jmax = family_range(j2, j3, m2, m3)
    if jmin > jmax:
        return jmin, 0
    m1 = -(m2 + m3)
    n = jmax - jmin + 1
    if n == 1:
        sh, sl = _dd_sqrt(2.0 * jmin + 1.0, 0.0)
        rh, rl = _dd_div(1.0, 0.0, sh, sl)
        if (j2 - j3 - m1) % 2 != 0:
            rh, rl = -rh, -rl
        hi[0] = rh
        lo[0] = rl
        return jmin, 1

    # coefficient tables, index t <-> j1 = jmin + t:  the recursion reads
    #   cd[t] w[t+1] + b[t] w[t] + cu[t] w[t-1] = 0,  cd[t] = j1 A(j1+1),  cu[t] = (j1+1) A(j1)
    bh = np.empty(n)
    bl = np.empty(n)
    cuh = np.empty(n)
    cul = np.empty(n)
    cdh = np.empty(n)
    cdl = np.empty(n)
    a0h, a0l = _coef_a_dd(jmin, j2, j3, m1)
    for t in range(n):
        j = jmin + t
        bh[t], bl[t] = _dd_from_int(_coef_b_int(j, j2, j3, m1, m2, m3))
        a1h, a1l = _coef_a_dd(j + 1, j2, j3, m1)
        cuh[t], cul[t] = _dd_mul_d(a0h, a0l, float(j + 1))
        cdh[t], cdl[t] = _dd_mul_d(a1h, a1l, float(j))
        a0h, a0l = a1h, a1l

    kh = np.empty(n)
    kl = np.empty(n)
    # backward sweep from jmax through the upper forbidden region (two-term start: A(jmax + 1) = 0)
    kh[n - 1] = 1.0
    kl[n - 1] = 0.0
    kh[n - 2], kl[n - 2] = _dd_div(-bh[n - 1], -bl[n - 1], cuh[n - 1], cul[n - 1])
    pb = n - 2
    while pb > 0 and (jmin == 0 or abs(kh[pb]) > abs(kh[pb + 1])):
        _dd_step_down(kh, kl, pb, bh, bl, cuh, cul, cdh, cdl)
        pb -= 1
    if jmin == 0:
        # j2 = j3 and m1 = 0: no lower forbidden region, the backward sweep ran to the end
        for t in range(n):
            hi[t] = kh[t]
            lo[t] = kl[t]
        return _normalize_dd(hi, lo, n, jmin, j2, j3, m1, 1.0)

    # forward sweep from jmin through the lower forbidden region (two-term start: A(jmin) = 0)
    hi[0] = 1.0
    lo[0] = 0.0
    hi[1], lo[1] = _dd_div(-bh[0], -bl[0], cdh[0], cdl[0])
    pf = 1
    while pf < pb + 1 and abs(hi[pf]) > abs(hi[pf - 1]):
        _dd_step_up(hi, lo, pf, bh, bl, cuh, cul, cdh, cdl)
        pf += 1
    mid = pb if pf > pb else (pf + pb) // 2
    while pf < mid + 1:
        _dd_step_up(hi, lo, pf, bh, bl, cuh, cul, cdh, cdl)
        pf += 1
    while pb > mid:
        _dd_step_down(kh, kl, pb, bh, bl, cuh, cul, cdh, cdl)
        pb -= 1
    # bring both sweeps to O(1) at the meeting points by exact powers of two, so that the products below cannot
    # overflow (Veltkamp splitting overflows above ~2**996), then least-squares match on the two points
    ef = math.frexp(max(abs(hi[mid]), abs(hi[mid + 1])))[1]
    ek = math.frexp(max(abs(kh[mid]), abs(kh[mid + 1])))[1]
    f = math.ldexp(1.0, -ef)
    for t in range(mid + 2):
        hi[t] *= f
        lo[t] *= f
    f = math.ldexp(1.0, -ek)
    for t in range(mid, n):
        kh[t] *= f
        kl[t] *= f
    xh, xl = _dd_mul(hi[mid], lo[mid], kh[mid], kl[mid])
    yh, yl = _dd_mul(hi[mid + 1], lo[mid + 1], kh[mid + 1], kl[mid + 1])
    nh, nl = _dd_add(xh, xl, yh, yl)
    xh, xl = _dd_mul(kh[mid], kl[mid], kh[mid], kl[mid])
    yh, yl = _dd_mul(kh[mid + 1], kl[mid + 1], kh[mid + 1], kl[mid + 1])
    dh, dl = _dd_add(xh, xl, yh, yl)
    sh, sl = _dd_div(nh, nl, dh, dl)
    for t in range(mid, n):
        hi[t], lo[t] = _dd_mul(kh[t], kl[t], sh, sl)
    return _normalize_dd(hi, lo, n, jmin, j2, j3, m1, sh)


@nb.njit(cache=True, nogil=True)
def _normalize_dd(hi, lo, n, jmin, j2, j3, m1, sign_last):
    # scale by an exact power of two so that the largest value is O(1), then divide by sqrt(Σ (2 j1 + 1) w²);
    # sign_last is the sign of the unnormalized w(jmax), which may have underflowed to 0 (see _normalize)
    big = 0.0
    for t in range(n):
        big = max(big, abs(hi[t]))
    f = math.ldexp(1.0, -math.frexp(big)[1])
    sh = 0.0
    sl = 0.0
    for t in range(n):
        hi[t] *= f
        lo[t] *= f
        qh, ql = _dd_mul(hi[t], lo[t], hi[t], lo[t])
        qh, ql = _dd_mul_d(qh, ql, 2.0 * (jmin + t) + 1.0)
        sh, sl = _dd_add(sh, sl, qh, ql)
    rh, rl = _dd_sqrt(sh, sl)
    ch, cl = _dd_div(1.0, 0.0, rh, rl)
    if (sign_last < 0) == ((j2 - j3 - m1) % 2 == 0):
        ch, cl = -ch, -cl
    for t in range(n):
        hi[t], lo[t] = _dd_mul(hi[t], lo[t], ch, cl)
    return jmin, n


# ---------------------------------------------------------------------------------------------------------------
# Truncated families.  The Gaunt tables need a family only up to the factor band limit La, often far below
# jmax = j2 + j3.  Started from the exact first symbol (a closed form of factorials, evaluated in double-double),
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
    """The family from jmin up to ``jtop`` (< jmax) by the forward recursion from the exact first symbol.

    Returns (jmin, n, ok): ``out[0:n]`` holds w(jmin … jtop) when ok; ok is False when the range reaches the upper
    forbidden region (or jmin = 0, where the recursion has no two-term start), and the caller must use
    :func:`family_into`.  ``fh, fl, fe`` is :func:`factorial_table` of at least j2 + j3 + jtop + 1.
    """
    jmin, jmax = family_range(j2, j3, m2, m3)
    if jmin > jmax or jmin == 0 or jtop >= jmax or jtop < jmin:
        return jmin, 0, False
    m1 = -(m2 + m3)
    n = jtop - jmin + 1
    out[0] = 1.0
    if n == 1:
        mant, e = _first_symbol(j2, j3, m2, m3, jmin, fh, fl, fe)
        out[0] = math.ldexp(mant, e)
        return jmin, 1, True
    a_next = _coef_a(jmin + 1, j2, j3, m1)
    out[1] = -_coef_b(jmin, j2, j3, m1, m2, m3) / (jmin * a_next)
    scale = 0
    a_j = a_next
    for p in range(1, n - 1):
        j = jmin + p
        a_next = _coef_a(j + 1, j2, j3, m1)
        b = _coef_b(j, j2, j3, m1, m2, m3)
        out[p + 1] = -(b * out[p] + (j + 1) * a_j * out[p - 1]) / (j * a_next)
        # real characteristic roots with decaying values: the upper forbidden region, unstable forwards
        if b * b >= 4.0 * j * (j + 1) * a_j * a_next and abs(out[p + 1]) < abs(out[p]):
            return jmin, 0, False
        if abs(out[p + 1]) > _HUGE:
            for t in range(p + 2):
                out[t] = math.ldexp(out[t], -_SCALE_EXP)
            scale += 1
        a_j = a_next
    mant, e = _first_symbol(j2, j3, m2, m3, jmin, fh, fl, fe)
    e += scale * _SCALE_EXP
    for t in range(n):
        out[t] = math.ldexp(out[t] * mant, e)
    return jmin, n, True


def _check_int(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InvalidArgumentError(f"{name} must be an integer (half-integer spins are not supported), got {value!r}")
    value = int(value)
    if abs(value) > 2 * MAX_DEGREE:
        raise InvalidArgumentError(f"{name} = {value} is out of range (|{name}| <= {2 * MAX_DEGREE})")
    return value


def wigner3j_family(j2: int, j3: int, m2: int, m3: int) -> tuple[int, np.ndarray]:
    """All Wigner 3j symbols (j1 j2 j3; −m2−m3 m2 m3) for j1 = jmin … j2 + j3.

    Parameters
    ----------
    j2, j3 : int, >= 0
    m2, m3 : int, |m2| <= j2, |m3| <= j3

    Returns
    -------
    jmin : int
        First j1 of the family, max(|j2 − j3|, |m2 + m3|).
    w : (j2 + j3 − jmin + 1,) float array
        w[t] is the symbol with j1 = jmin + t.  Empty when the arguments admit no symbol.

    Notes
    -----
    Computed in double-double (:func:`family_into_dd`) and rounded: every nonzero symbol with l ≤ 60 to ≤ 1e-13
    relative (measured ≤ 5e-16), exact zeros as 0.0; see docs/wigner_accuracy.md for larger l.  Cost ~7 µs per
    family at l ≤ 60; when an absolute error of 2e-14 × max|w| is enough, :func:`family_into` is 6–10× faster.
    """
    j2, j3, m2, m3 = (_check_int(n, v) for n, v in (("j2", j2), ("j3", j3), ("m2", m2), ("m3", m3)))
    if j2 < 0 or j3 < 0:
        raise InvalidArgumentError(f"j2 and j3 must be >= 0, got {j2}, {j3}")
    jmin, jmax = family_range(j2, j3, m2, m3)
    out = np.zeros(max(jmax - jmin + 1, 0))
    if out.size:
        family_into_dd(j2, j3, m2, m3, out, np.empty(out.size))
        out += 0.0  # -0.0 -> 0.0
    return jmin, out


@nb.njit(cache=True, nogil=True)
def _wigner3j_scalar(j1, j2, j3, m1, m2, m3):
    if m1 + m2 + m3 != 0 or j1 < 0 or j2 < 0 or j3 < 0:
        return 0.0
    if abs(m1) > j1 or abs(m2) > j2 or abs(m3) > j3:
        return 0.0
    if j1 < abs(j2 - j3) or j1 > j2 + j3:
        return 0.0
    jmin, jmax = family_range(j2, j3, m2, m3)
    hi = np.empty(jmax - jmin + 1)
    lo = np.empty(jmax - jmin + 1)
    family_into_dd(j2, j3, m2, m3, hi, lo)
    return hi[j1 - jmin] + 0.0  # -0.0 -> 0.0


def wigner3j(l1: int, l2: int, l3: int, m1: int, m2: int, m3: int) -> float:
    """The Wigner 3j symbol (l1 l2 l3; m1 m2 m3) for integer arguments.

    Zero when the selection rules fail (m1 + m2 + m3 ≠ 0, triangle inequality, |m| > l).  Computed from the family
    over l1 (see :func:`wigner3j_family`), so many symbols of one family are cheaper through that function.
    Accuracy: ≤ 1e-13 relative for every nonzero symbol with l ≤ 60 (measured ≤ 5e-16), exact zeros as 0.0.

    Raises
    ------
    InvalidArgumentError
        An argument that is not an integer (half-integer spins are not supported) or exceeds 2 × MAX_DEGREE.
    """
    args = [_check_int(n, v) for n, v in zip(("l1", "l2", "l3", "m1", "m2", "m3"), (l1, l2, l3, m1, m2, m3))]
    return float(_wigner3j_scalar(*args))
