"""Tests of shspec.gaunt.wigner and wigner_dd: accuracy against exact values, selection rules, symmetries, orthogonality, errors.

The exact reference is WIGXJPF (pywigxjpf: exact integer arithmetic, rounded once to double) and, for a few small
symbols, sympy's closed form.  The accuracy contract checked here:

* public ``wigner3j`` / ``wigner3j_family`` (double-double path): relative error ≤ 1e-13 for every nonzero symbol
  with l ≤ 60, and exact 0.0 for every symbol that is exactly zero;
* ``family_into`` (double path, used by the Gaunt tables): absolute error ≤ 2e-14 × max|w| of the family, l ≤ 60
  (typically a few 1e-15; the worst found, 1.14e-14, is the family (j1 49 53; −2 −48 50), checked explicitly).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from shspec.errors import InvalidArgumentError
from shspec.gaunt.doubledouble import _two_prod
from shspec.gaunt.wigner import family_into, family_range
from shspec.gaunt.wigner_dd import family_into_dd, wigner3j, wigner3j_family

L = 60  # the degree range of the accuracy contract
REL_TOL = 1e-13  # public path, relative, every nonzero symbol
ABS_TOL_DOUBLE = 2e-14  # double path, absolute, in units of the family maximum (measured max 1.14e-14)
FAST = settings(max_examples=150, deadline=None)


_PEER = {}


@pytest.fixture(scope="module")
def wigxjpf():
    """The exact reference (skips only the tests that compare with it when pywigxjpf is missing)."""
    wig = pytest.importorskip("pywigxjpf")
    # two_j up to 2 (2 L) = 240: the families over j1 reach j2 + j3 = 2 L
    wig.wig_table_init(4 * L + 8, 3)
    wig.wig_temp_init(4 * L + 8)
    _PEER["wigxjpf"] = wig
    yield wig


def exact(l1, l2, l3, m1, m2, m3):
    return _PEER["wigxjpf"].wig3jj(2 * l1, 2 * l2, 2 * l3, 2 * m1, 2 * m2, 2 * m3)


def exact_family(j2, j3, m2, m3):
    jmin, jmax = family_range(j2, j3, m2, m3)
    m1 = -(m2 + m3)
    return jmin, np.array([exact(j1, j2, j3, m1, m2, m3) for j1 in range(jmin, jmax + 1)])


@st.composite
def families(draw, lmax=L, zero_m=0.15):
    j2 = draw(st.integers(0, lmax))
    j3 = draw(st.integers(0, lmax))
    if draw(st.floats(0, 1)) < zero_m:
        return j2, j3, 0, 0
    m2 = draw(st.integers(-j2, j2))
    m3 = draw(st.integers(-j3, j3))
    return j2, j3, m2, m3


@st.composite
def symbols(draw, lmax=L):
    """Valid (l1 l2 l3; m1 m2 m3): triangle, m1 + m2 + m3 = 0, |m| <= l, all l <= lmax."""
    l2 = draw(st.integers(0, lmax))
    l3 = draw(st.integers(0, lmax))
    l1 = draw(st.integers(abs(l2 - l3), min(l2 + l3, lmax)))
    m2 = draw(st.integers(-l2, l2))
    m3 = draw(st.integers(max(-l3, -l1 - m2), min(l3, l1 - m2)))
    return l1, l2, l3, -(m2 + m3), m2, m3


def check_relative(got, ref):
    """Relative error ≤ REL_TOL on nonzero references, exact 0 on zero ones."""
    got = np.asarray(got, dtype=float)
    ref = np.asarray(ref, dtype=float)
    zero = ref == 0.0
    assert np.all(got[zero] == 0.0), f"exact zeros computed as {got[zero][got[zero] != 0]}"
    rel = np.abs(got[~zero] - ref[~zero]) / np.abs(ref[~zero])
    assert rel.size == 0 or rel.max() <= REL_TOL, f"max relative error {rel.max():.3g}"


# ----------------------------------------------------------------------------------------------------------------
# accuracy against exact values


@FAST
@given(families())
def test_family_matches_wigxjpf_relative(wigxjpf, fam):
    j2, j3, m2, m3 = fam
    jmin, w = wigner3j_family(j2, j3, m2, m3)
    jmin_ref, ref = exact_family(j2, j3, m2, m3)
    assert jmin == jmin_ref and w.shape == ref.shape
    # the whole family (j1 up to 2 L), which includes every symbol with all l <= L
    check_relative(w, ref)


@FAST
@given(symbols())
def test_scalar_matches_wigxjpf_relative(wigxjpf, sym):
    check_relative([wigner3j(*sym)], [exact(*sym)])


@pytest.mark.parametrize(
    "sym",
    [(0, 0, 0, 0, 0, 0), (1, 1, 0, 0, 0, 0), (2, 2, 2, 0, 0, 0), (3, 2, 1, -1, 1, 0), (5, 4, 3, 2, -1, -1),
     (6, 4, 4, 2, -2, 0), (10, 7, 5, -3, 3, 0), (12, 12, 12, 4, -8, 4), (20, 15, 9, 7, -6, -1)],
)
def test_small_symbols_match_sympy(sym):
    sympy_wigner = pytest.importorskip("sympy.physics.wigner")
    ref = float(sympy_wigner.wigner_3j(*sym).evalf(40))
    if ref == 0.0:
        assert wigner3j(*sym) == 0.0
    else:
        assert abs(wigner3j(*sym) - ref) <= 4e-16 * abs(ref)


@FAST
@given(families())
@example((49, 53, -48, 50))  # the worst family found by benchmarks/wigner_accuracy.py: 1.14e-14 x max
def test_double_path_absolute_error(wigxjpf, fam):
    # the Gaunt tables use the double path: absolute error bound in units of the family maximum
    j2, j3, m2, m3 = fam
    jmin, ref = exact_family(j2, j3, m2, m3)
    out = np.full(ref.size + 3, np.nan)
    jmin_d, n = family_into(j2, j3, m2, m3, out)
    assert (jmin_d, n) == (jmin, ref.size)
    assert np.max(np.abs(out[:n] - ref)) <= ABS_TOL_DOUBLE * np.max(np.abs(ref))


@FAST
@given(families())
def test_double_double_parts(fam):
    # family_into_dd: same range as family_into, hi is the rounded value of hi + lo, and hi + lo agrees with the
    # double path to the latter's accuracy
    j2, j3, m2, m3 = fam
    n_max = j2 + j3 + 1
    hi, lo = np.full(n_max + 2, np.nan), np.full(n_max + 2, np.nan)
    d = np.full(n_max + 2, np.nan)
    assert family_into_dd(j2, j3, m2, m3, hi, lo) == family_into(j2, j3, m2, m3, d)
    _, n = family_into(j2, j3, m2, m3, d)
    assert np.all(hi[:n] + lo[:n] == hi[:n])
    assert np.all(np.abs(lo[:n]) <= 0.5 * np.spacing(np.abs(hi[:n])))
    assert np.max(np.abs(hi[:n] - d[:n]), initial=0.0) <= ABS_TOL_DOUBLE * np.max(np.abs(hi[:n]), initial=0.0)


def test_two_prod_is_error_free():
    # the double-double kernels need IEEE products without fused contraction: a*b == p + e exactly
    rng = np.random.default_rng(0)
    for a, b in zip(rng.standard_normal(200) * 1e3, rng.standard_normal(200) * 1e-2):
        p, e = _two_prod(float(a), float(b))
        assert Fraction(p) + Fraction(e) == Fraction(float(a)) * Fraction(float(b))


def test_large_degree_spot_values(wigxjpf):
    # beyond the tested contract the public path stays within a few ulps (see docs/wigner_accuracy.md)
    wigxjpf.wig_table_init(2 * 2000 + 8, 3)
    wigxjpf.wig_temp_init(2 * 2000 + 8)
    try:
        for j1, j2, j3, m2, m3 in [(701, 400, 500, -120, 37), (1000, 500, 500, 0, 0), (333, 600, 300, 250, -3)]:
            m1 = -(m2 + m3)
            ref = wigxjpf.wig3jj(2 * j1, 2 * j2, 2 * j3, 2 * m1, 2 * m2, 2 * m3)
            assert abs(wigner3j(j1, j2, j3, m1, m2, m3) - ref) <= 1e-15 * abs(ref)
        # families whose w(jmax) underflows in the rescaled sweeps (formerly a sign flip of the whole family in
        # both paths) or whose meeting values were large enough to overflow the double-double splitting (NaN)
        for j2, j3, m2, m3 in [(761, 718, -758, 567), (949, 286, 710, -253), (711, 422, 369, -403)]:
            m1 = -(m2 + m3)
            jmin, w = wigner3j_family(j2, j3, m2, m3)
            d = np.empty(w.size)
            family_into(j2, j3, m2, m3, d)
            for t in (0, int(np.argmax(np.abs(w))), w.size // 2):
                ref = wigxjpf.wig3jj(2 * (jmin + t), 2 * j2, 2 * j3, 2 * m1, 2 * m2, 2 * m3)
                assert abs(w[t] - ref) <= 1e-15 * abs(ref)
                assert abs(d[t] - ref) <= 1e-13 * np.max(np.abs(w))
    finally:
        wigxjpf.wig_table_init(4 * L + 8, 3)
        wigxjpf.wig_temp_init(4 * L + 8)


# ----------------------------------------------------------------------------------------------------------------
# selection rules and exact zeros


@pytest.mark.parametrize(
    "sym",
    [(2, 2, 2, 1, 1, 1),  # m1 + m2 + m3 != 0
     (1, 1, 3, 0, 0, 0),  # triangle
     (5, 1, 1, 0, 0, 0),  # triangle
     (2, 2, 2, 3, -3, 0),  # |m1| > l1
     (2, 2, 2, 0, 3, -3),  # |m2| > l2
     (3, 2, 2, 0, 0, 0),  # odd sum, all m = 0
     (5, 7, 9, 0, 0, 0),
     (4, 3, 4, 1, -2, 1),  # two equal columns, odd sum
     (6, 4, 4, 2, -2, 0)],  # a non-trivial (Diophantine) zero
)
def test_zeros_are_exact(sym):
    w = wigner3j(*sym)
    assert w == 0.0 and math.copysign(1.0, w) == 1.0


@FAST
@given(st.integers(0, L), st.integers(0, L), st.integers(0, 2 * L))
def test_odd_sum_with_zero_m_is_exact_zero(l1, l2, l3):
    w = wigner3j(l1, l2, l3, 0, 0, 0)
    if (l1 + l2 + l3) % 2 or not abs(l2 - l3) <= l1 <= l2 + l3:
        assert w == 0.0
    else:
        assert w != 0.0


def test_empty_family():
    jmin, w = wigner3j_family(1, 2, 2, 0)  # |m2| > j2
    assert w.shape == (0,)
    out = np.zeros(4)
    assert family_into(1, 2, 2, 0, out)[1] == 0
    assert family_into_dd(1, 2, 2, 0, out, out.copy())[1] == 0


# ----------------------------------------------------------------------------------------------------------------
# symmetries


@FAST
@given(symbols())
def test_column_permutations(sym):
    l1, l2, l3, m1, m2, m3 = sym
    w = wigner3j(*sym)
    odd = -1.0 if (l1 + l2 + l3) % 2 else 1.0
    cols = [(l1, m1), (l2, m2), (l3, m3)]
    for perm, sign in [((1, 2, 0), 1.0), ((2, 0, 1), 1.0), ((1, 0, 2), odd), ((0, 2, 1), odd), ((2, 1, 0), odd)]:
        (a, x), (b, y), (c, z) = (cols[p] for p in perm)
        assert wigner3j(a, b, c, x, y, z) == pytest.approx(sign * w, rel=2 * REL_TOL, abs=0)


@FAST
@given(symbols())
def test_sign_flip_of_m(sym):
    l1, l2, l3, m1, m2, m3 = sym
    sign = -1.0 if (l1 + l2 + l3) % 2 else 1.0
    assert wigner3j(l1, l2, l3, -m1, -m2, -m3) == pytest.approx(sign * wigner3j(*sym), rel=2 * REL_TOL, abs=0)


def _regge_square(l1, l2, l3, m1, m2, m3):
    return np.array([[-l1 + l2 + l3, l1 - l2 + l3, l1 + l2 - l3],
                     [l1 - m1, l2 - m2, l3 - m3],
                     [l1 + m1, l2 + m2, l3 + m3]])


def _from_regge_square(r):
    return (*((r[1] + r[2]) // 2), *((r[2] - r[1]) // 2))


@FAST
@given(symbols())
def test_regge_transposition(sym):
    # the 3j symbol is invariant under transposition of the Regge square
    assert _from_regge_square(_regge_square(*sym)) == sym
    r = _regge_square(*sym).T
    assume(np.all((r[1] + r[2]) % 2 == 0))  # otherwise the partner has half-integer spins
    other = _from_regge_square(r)
    assert wigner3j(*other) == pytest.approx(wigner3j(*sym), rel=2 * REL_TOL, abs=0)


# ----------------------------------------------------------------------------------------------------------------
# orthogonality


@settings(max_examples=40, deadline=None)
@given(families(lmax=40, zero_m=0.0), st.integers(0, 80))
def test_orthogonality_over_j1(fam, k):
    # Σ_j1 (2 j1 + 1) (j1 j2 j3; m1 m2 m3)(j1 j2 j3; m1 m2' m3') = δ_{m2 m2'} for m2 + m3 = m2' + m3'
    j2, j3, m2, m3 = fam
    lo2, hi2 = max(-j2, m2 + m3 - j3), min(j2, m2 + m3 + j3)
    m2p = lo2 + k % (hi2 - lo2 + 1)
    m3p = m2 + m3 - m2p
    jmin, a = wigner3j_family(j2, j3, m2, m3)
    jminp, b = wigner3j_family(j2, j3, m2p, m3p)
    assert jmin == jminp
    s = np.sum((2.0 * np.arange(jmin, jmin + a.size) + 1.0) * a * b)
    assert s == pytest.approx(1.0 if m2p == m2 else 0.0, abs=1e-14)


@pytest.mark.parametrize("j2, j3, m1", [(7, 5, 0), (12, 9, -3), (20, 20, 0), (33, 18, 11), (40, 35, -40)])
def test_orthogonality_over_m(j2, j3, m1):
    # Σ_{m2 + m3 = -m1} (j1 j2 j3; m1 m2 m3)(j1' j2 j3; m1 m2 m3) = δ_{j1 j1'} / (2 j1 + 1)
    jmin = max(abs(j2 - j3), abs(m1))
    n = j2 + j3 - jmin + 1
    gram = np.zeros((n, n))
    for m2 in range(-j2, j2 + 1):
        m3 = -m1 - m2
        if abs(m3) > j3:
            continue
        jm, w = wigner3j_family(j2, j3, m2, m3)
        assert jm == jmin
        gram += np.outer(w, w)
    expected = np.diag(1.0 / (2.0 * np.arange(jmin, j2 + j3 + 1) + 1.0))
    np.testing.assert_allclose(gram, expected, rtol=0, atol=1e-15)


# ----------------------------------------------------------------------------------------------------------------
# argument errors


@pytest.mark.parametrize(
    "args",
    [(1.5, 1, 1, 0, 0, 0), (1, 0.5, 0.5, 0, 0, 0), ("2", 1, 1, 0, 0, 0), (True, 1, 1, 0, 0, 0),
     (10**6, 10**6, 1, 0, 0, 0), (1, 1, 1, 0, 0, 10**9)],
)
def test_invalid_arguments_raise(args):
    with pytest.raises(InvalidArgumentError):
        wigner3j(*args)


@pytest.mark.parametrize("args", [(1.0, 1, 0, 0), (-1, 2, 0, 0), (10**7, 1, 0, 0), (2, 2, None, 0)])
def test_invalid_family_arguments_raise(args):
    with pytest.raises(InvalidArgumentError):
        wigner3j_family(*args)


def test_numpy_integers_accepted():
    assert wigner3j(*np.array([2, 2, 2, 0, 0, 0])) == pytest.approx(-math.sqrt(2.0 / 35.0), rel=1e-15)
    assert wigner3j_family(np.int32(1), np.int64(1), 0, 0)[1] == pytest.approx([-1 / math.sqrt(3), 0.0, math.sqrt(2 / 15)])


def _random_families(rng, count, low, high):
    """(j2, j3, m2, m3, jmin, jmax) of ``count`` random draws of a family, degrees in [low, high) (empty families
    skipped); lazy, so that the caller's own draws from ``rng`` interleave with these in a fixed order."""
    for _ in range(count):
        j2, j3 = (int(x) for x in rng.integers(low, high, 2))
        m2, m3 = int(rng.integers(-j2, j2 + 1)), int(rng.integers(-j3, j3 + 1))
        jmin, jmax = family_range(j2, j3, m2, m3)
        if jmin <= jmax:
            yield j2, j3, m2, m3, jmin, jmax


def test_truncated_forward_family_matches_double_double():
    """family_upto_into: exact first symbol + forward recursion, up to jtop; it must refuse the unstable region."""
    from shspec.gaunt.wigner import factorial_table, family_upto_into
    from shspec.gaunt.wigner_dd import family_into_dd

    fh, fl, fe = factorial_table(400)
    rng = np.random.default_rng(7)
    accepted = refused = 0
    worst = 0.0
    for j2, j3, m2, m3, jmin, jmax in _random_families(rng, 3000, 0, 80):
        jtop = int(rng.integers(jmin, jmax + 1))
        out = np.zeros(jmax - jmin + 1)
        _, n, ok = family_upto_into(j2, j3, m2, m3, jtop, out, fh, fl, fe)
        if not ok:
            refused += 1
            continue
        accepted += 1
        hi, lo = np.zeros(jmax - jmin + 1), np.zeros(jmax - jmin + 1)
        family_into_dd(j2, j3, m2, m3, hi, lo)
        assert n == jtop - jmin + 1
        worst = max(worst, np.max(np.abs(out[:n] - hi[:n])) / np.max(np.abs(hi)))
    assert worst <= 2e-14
    assert accepted > 1000 and refused > 100  # both paths exercised


def test_forward_family_values_do_not_depend_on_where_the_sweep_is_asked_to_stop():
    # the sweep stops where the family makes it unstable, not at jtop: so a table's values do not depend on its La
    from shspec.gaunt.wigner import factorial_table, family_upto_into

    fh, fl, fe = factorial_table(400)
    partial = 0
    for j2, j3, m2, m3, jmin, jmax in _random_families(np.random.default_rng(11), 400, 1, 60):
        full = np.zeros(jmax - jmin + 1)
        _, nfull, _ = family_upto_into(j2, j3, m2, m3, jmax, full, fh, fl, fe)
        for jtop in range(jmin, jmax + 1, 3):
            out = np.zeros(jmax - jmin + 1)
            _, n, ok = family_upto_into(j2, j3, m2, m3, jtop, out, fh, fl, fe)
            assert n == (jtop - jmin + 1 if ok else min(nfull, jtop - jmin + 1))
            assert np.array_equal(out[:n], full[:n])  # the same bits, whatever jtop
            partial += not ok and n > 0
    assert partial > 50  # the stop inside the range (upper forbidden region) is exercised


def test_negative_degrees_are_refused_like_real_gaunt():
    from shspec.errors import InvalidArgumentError
    from shspec.gaunt.real_gaunt import real_gaunt

    for bad in [(-1, 1, 1, 0, 0, 0), (1, -1, 1, 0, 0, 0), (1, 1, -2, 0, 0, 0)]:
        with pytest.raises(InvalidArgumentError, match="degrees are >= 0"):
            wigner3j(*bad)
    with pytest.raises(InvalidArgumentError):
        real_gaunt(-1, 0, 1, 0, 1, 0)
