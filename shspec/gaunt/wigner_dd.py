"""The double-double twin of the 3j recursion, and the public 3j functions built on it.

:func:`family_into_dd` runs the same two-sided Schulten–Gordon sweeps as :func:`shspec.gaunt.wigner.family_into`
in double-double arithmetic (:mod:`shspec.gaunt.doubledouble`, ~32 digits) and rounds to double at the end;
:func:`wigner3j_family` and :func:`wigner3j` use it.  Accuracy and cost: see :mod:`shspec.gaunt.wigner`.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..core.checks import check_int
from ..errors import InvalidArgumentError
from ..sphere.harmonics import MAX_DEGREE
from .doubledouble import (_DD_HUGE, _DD_TINY, _DD_ZERO, _dd_add, _dd_div, _dd_from_int, _dd_mul, _dd_mul_d,
                           _dd_sqrt, _two_prod)
from .wigner import family_range

__all__ = ["wigner3j", "wigner3j_family", "family_into_dd"]


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

    Cost (one core, measured: :doc:`/wigner_accuracy`): 6–10× the double :func:`family_into`,
    ~2 µs per family at l ≤ 10, ~7 µs at l ≤ 60, ~0.12 ms at l ≤ 1000.

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
        return _single_dd(jmin, j2, j3, m1, hi, lo)
    bh, bl, cuh, cul, cdh, cdl = _coefficients_dd(n, jmin, j2, j3, m1, m2, m3)
    kh = np.empty(n)
    kl = np.empty(n)
    pb = _backward_sweep(kh, kl, jmin, bh, bl, cuh, cul, cdh, cdl)
    if jmin == 0:
        # j2 = j3 and m1 = 0: no lower forbidden region, the backward sweep ran to the end
        for t in range(n):
            hi[t] = kh[t]
            lo[t] = kl[t]
        return _normalize_dd(hi, lo, n, jmin, j2, j3, m1, 1.0)
    mid = _meet(hi, lo, kh, kl, pb, bh, bl, cuh, cul, cdh, cdl)
    sh, sl = _match_dd(hi, lo, kh, kl, mid)
    return _normalize_dd(hi, lo, n, jmin, j2, j3, m1, sh)


@nb.njit(cache=True, nogil=True, inline="always")
def _single_dd(jmin, j2, j3, m1, hi, lo):
    """The one-symbol family: ±1/sqrt(2 jmin + 1) into hi[0] + lo[0]; returns (jmin, 1)."""
    sh, sl = _dd_sqrt(2.0 * jmin + 1.0, 0.0)
    rh, rl = _dd_div(1.0, 0.0, sh, sl)
    if (j2 - j3 - m1) % 2 != 0:
        rh, rl = -rh, -rl
    hi[0] = rh
    lo[0] = rl
    return jmin, 1


@nb.njit(cache=True, nogil=True, inline="always")
def _coefficients_dd(n, jmin, j2, j3, m1, m2, m3):
    """The recursion's coefficient tables (b, cu, cd), each as leading and trailing parts, index t <-> j1 = jmin + t."""
    # the recursion reads  cd[t] w[t+1] + b[t] w[t] + cu[t] w[t-1] = 0,  cd[t] = j1 A(j1+1),  cu[t] = (j1+1) A(j1)
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
    return bh, bl, cuh, cul, cdh, cdl


@nb.njit(cache=True, nogil=True, inline="always")
def _backward_sweep(kh, kl, jmin, bh, bl, cuh, cul, cdh, cdl):
    """Sweep down from jmax through the upper forbidden region into kh + kl; returns the index it stopped at."""
    n = kh.size
    # two-term start: A(jmax + 1) = 0
    kh[n - 1] = 1.0
    kl[n - 1] = 0.0
    kh[n - 2], kl[n - 2] = _dd_div(-bh[n - 1], -bl[n - 1], cuh[n - 1], cul[n - 1])
    pb = n - 2
    while pb > 0 and (jmin == 0 or abs(kh[pb]) > abs(kh[pb + 1])):
        _dd_step_down(kh, kl, pb, bh, bl, cuh, cul, cdh, cdl)
        pb -= 1
    return pb


@nb.njit(cache=True, nogil=True, inline="always")
def _meet(hi, lo, kh, kl, pb, bh, bl, cuh, cul, cdh, cdl):
    """Sweep up from jmin through the lower forbidden region, carry both sweeps to a meeting point; returns it."""
    # two-term start: A(jmin) = 0
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
    return mid


@nb.njit(cache=True, nogil=True, inline="always")
def _match_dd(hi, lo, kh, kl, mid):
    """Join the backward sweep to the forward one at mid, mid + 1 (hi + lo from mid on); returns its scale."""
    n = kh.size
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
    return sh, sl


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


def _check_int(name, value):
    # half-integer spins are not supported: every argument is an integer
    return check_int(value, name, minimum=-2 * MAX_DEGREE, maximum=2 * MAX_DEGREE)


def wigner3j_family(j2: int, j3: int, m2: int, m3: int) -> tuple[int, np.ndarray]:
    """All Wigner 3j symbols (j1 j2 j3; −m2−m3 m2 m3) for j1 = jmin … j2 + j3.

    Parameters
    ----------
    j2, j3 : int
        Degrees, >= 0.
    m2, m3 : int
        Orders, with |m2| <= j2 and |m3| <= j3.

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

    Examples
    --------
    >>> from shspec.gaunt import wigner3j_family
    >>> j1_min, values = wigner3j_family(1, 1, 0, 0)    # (j1 1 1; 0 0 0) for j1 = 0, 1, 2
    >>> j1_min, values.round(6)
    (0, array([-0.57735 ,  0.      ,  0.365148]))
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
        An argument that is not an integer (half-integer spins are not supported), a negative degree (as
        :func:`~shspec.gaunt.real_gaunt.real_gaunt` refuses), or one that exceeds 2 × MAX_DEGREE.

    Examples
    --------
    >>> from shspec import wigner3j
    >>> round(wigner3j(1, 1, 0, 0, 0, 0), 15)    # -1/sqrt(3)
    -0.577350269189626
    """
    args = [_check_int(n, v) for n, v in zip(("l1", "l2", "l3", "m1", "m2", "m3"), (l1, l2, l3, m1, m2, m3))]
    for name, l in zip(("l1", "l2", "l3"), args[:3]):
        if l < 0:
            raise InvalidArgumentError(f"{name} = {l}: degrees are >= 0")
    return float(_wigner3j_scalar(*args))
