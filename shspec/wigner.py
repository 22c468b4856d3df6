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

Only integer arguments are supported (the spherical-harmonic case).  Accuracy (measured against exact values,
see the README): ≤ 1e-14 relative for l ≤ 60 away from accidental near-zeros, and graceful growth to l = 1000.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .errors import InvalidArgumentError
from .harmonics import MAX_DEGREE

__all__ = ["wigner3j", "wigner3j_family", "family_range"]

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
def _step_up(w, p, jmin, j2, j3, m1, m2, m3):
    # w[p+1] from w[p], w[p-1]; rescale everything so far when the growing values approach overflow
    j = jmin + p
    w[p + 1] = -(_coef_b(j, j2, j3, m1, m2, m3) * w[p] + (j + 1) * _coef_a(j, j2, j3, m1) * w[p - 1]) / (
        j * _coef_a(j + 1, j2, j3, m1))
    if abs(w[p + 1]) > _HUGE:
        for t in range(p + 2):
            w[t] *= _TINY


@nb.njit(cache=True, nogil=True)
def _step_down(w, p, jmin, j2, j3, m1, m2, m3):
    # w[p-1] from w[p], w[p+1]
    j = jmin + p
    w[p - 1] = -(j * _coef_a(j + 1, j2, j3, m1) * w[p + 1] + _coef_b(j, j2, j3, m1, m2, m3) * w[p]) / (
        (j + 1) * _coef_a(j, j2, j3, m1))
    if abs(w[p - 1]) > _HUGE:
        for t in range(p - 1, w.size):
            w[t] *= _TINY


@nb.njit(cache=True, nogil=True)
def family_into(j2, j3, m2, m3, out):
    """Fill ``out[0:n]`` with w(jmin), …, w(jmax) of one family; returns (jmin, n).  ``out`` needs n entries."""
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
    # backward sweep from jmax through the upper forbidden region, where the values grow downwards
    back[n - 1] = 1.0
    back[n - 2] = -_coef_b(jmax, j2, j3, m1, m2, m3) / ((jmax + 1) * _coef_a(jmax, j2, j3, m1))
    pb = n - 2  # lowest position filled by the backward sweep
    while pb > 0 and abs(back[pb]) > abs(back[pb + 1]):
        _step_down(back, pb, jmin, j2, j3, m1, m2, m3)
        pb -= 1
    if jmin == 0:
        # j2 = j3 and m1 = 0: no lower forbidden region, the backward sweep may run to the end
        while pb > 0:
            _step_down(back, pb, jmin, j2, j3, m1, m2, m3)
            pb -= 1
        for t in range(n):
            out[t] = back[t]
        return _normalize(out, n, jmin, j2, j3, m1)

    # forward sweep from jmin through the lower forbidden region
    out[0] = 1.0
    out[1] = -_coef_b(jmin, j2, j3, m1, m2, m3) / (jmin * _coef_a(jmin + 1, j2, j3, m1))
    pf = 1  # highest position filled by the forward sweep
    while pf < pb + 1 and abs(out[pf]) > abs(out[pf - 1]):
        _step_up(out, pf, jmin, j2, j3, m1, m2, m3)
        pf += 1
    # through the oscillatory region both directions are neutral: meet in its middle to halve the longer run
    mid = pb if pf > pb else (pf + pb) // 2
    while pf < mid + 1:
        _step_up(out, pf, jmin, j2, j3, m1, m2, m3)
        pf += 1
    while pb > mid:
        _step_down(back, pb, jmin, j2, j3, m1, m2, m3)
        pb -= 1
    # least-squares match on the two points both sweeps hold; they cannot both be near a node
    num = out[mid] * back[mid] + out[mid + 1] * back[mid + 1]
    den = back[mid] * back[mid] + back[mid + 1] * back[mid + 1]
    scale = num / den
    for t in range(mid, n):
        out[t] = back[t] * scale
    return _normalize(out, n, jmin, j2, j3, m1)


@nb.njit(cache=True, nogil=True)
def _normalize(out, n, jmin, j2, j3, m1):
    # the sum is accumulated with the largest values scaled to O(1) so that it neither overflows nor underflows
    big = 0.0
    for t in range(n):
        big = max(big, abs(out[t]))
    s = 0.0
    for t in range(n):
        v = out[t] / big
        s += (2.0 * (jmin + t) + 1.0) * v * v
    c = 1.0 / (big * math.sqrt(s))
    if (out[n - 1] < 0) == ((j2 - j3 - m1) % 2 == 0):
        c = -c
    for t in range(n):
        out[t] *= c
    return jmin, n


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
    """
    j2, j3, m2, m3 = (_check_int(n, v) for n, v in (("j2", j2), ("j3", j3), ("m2", m2), ("m3", m3)))
    if j2 < 0 or j3 < 0:
        raise InvalidArgumentError(f"j2 and j3 must be >= 0, got {j2}, {j3}")
    jmin, jmax = family_range(j2, j3, m2, m3)
    out = np.zeros(max(jmax - jmin + 1, 0))
    if out.size:
        family_into(j2, j3, m2, m3, out)
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
    out = np.empty(jmax - jmin + 1)
    family_into(j2, j3, m2, m3, out)
    return out[j1 - jmin]


def wigner3j(l1: int, l2: int, l3: int, m1: int, m2: int, m3: int) -> float:
    """The Wigner 3j symbol (l1 l2 l3; m1 m2 m3) for integer arguments.

    Zero when the selection rules fail (m1 + m2 + m3 ≠ 0, triangle inequality, |m| > l).  Computed from the family
    over l1 (see :func:`wigner3j_family`), so many symbols of one family are cheaper through that function.
    """
    args = [_check_int(n, v) for n, v in zip(("l1", "l2", "l3", "m1", "m2", "m3"), (l1, l2, l3, m1, m2, m3))]
    return float(_wigner3j_scalar(*args))
