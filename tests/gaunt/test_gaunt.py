"""Real Gaunt coefficients against sympy's exact ones, quadrature on pyshtools grids, and their symmetries."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sympy.physics.wigner import real_gaunt as sympy_real_gaunt

from shspec import real_gaunt
from shspec.errors import InvalidArgumentError
from shspec.sphere.grid import evaluate_on_grid, glq_grid
from shspec.sphere.harmonics import degree_order


def _lm(lmax):
    l, m = degree_order(lmax)
    return list(zip(l.tolist(), m.tolist()))


def test_all_triples_up_to_degree_4_match_sympy_exactly():
    """Every unordered triple of the 25 harmonics of degree <= 4, zeros included."""
    worst = 0.0
    nonzero = 0
    for (l1, m1), (l2, m2), (l3, m3) in itertools.combinations_with_replacement(_lm(4), 3):
        ours = real_gaunt(l1, m1, l2, m2, l3, m3)
        exact = float(sympy_real_gaunt(l1, l2, l3, m1, m2, m3))
        worst = max(worst, abs(ours - exact))
        nonzero += exact != 0
        if exact == 0:  # structural zeros come out exactly 0; accidental ones (e.g. (20, 3-2, 3-2)) to round-off
            assert abs(ours) < 1e-16, (l1, m1, l2, m2, l3, m3)
    assert worst < 5e-16
    assert nonzero == 238  # the comparison is not vacuous: the non-zero unordered triples of degree <= 4


@settings(max_examples=150, deadline=None)
@given(st.data())
def test_random_triples_up_to_degree_12_match_sympy(data):
    l1, l2 = data.draw(st.integers(0, 12)), data.draw(st.integers(0, 12))
    l3 = data.draw(st.integers(abs(l1 - l2), min(l1 + l2, 12)))
    m1, m2 = data.draw(st.integers(-l1, l1)), data.draw(st.integers(-l2, l2))
    # bias towards the orders that can be non-zero, so that signs are exercised
    m3 = data.draw(st.sampled_from(sorted({m1 + m2, m1 - m2, m2 - m1, -m1 - m2, 0} & set(range(-l3, l3 + 1)))))
    exact = float(sympy_real_gaunt(l1, l2, l3, m1, m2, m3))
    assert abs(real_gaunt(l1, m1, l2, m2, l3, m3) - exact) <= 1e-15 + 1e-13 * abs(exact)


@pytest.fixture(scope="module")
def quad_grid():
    return glq_grid(95)


def _on_grid(grid, l, m):
    e = np.zeros((l + 1) ** 2)
    e[l * l + l + m] = 1.0
    return evaluate_on_grid(e, grid)


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_random_triples_up_to_degree_60_match_quadrature(quad_grid, data):
    """Gauss-Legendre quadrature of degree 95 integrates products of total degree <= 180 exactly."""
    l1, l2 = data.draw(st.integers(0, 60)), data.draw(st.integers(0, 60))
    l3 = data.draw(st.integers(abs(l1 - l2), min(l1 + l2, 60)))
    m1, m2 = data.draw(st.integers(-l1, l1)), data.draw(st.integers(-l2, l2))
    m3 = data.draw(st.sampled_from(sorted({m1 + m2, m1 - m2, m2 - m1, -m1 - m2} & set(range(-l3, l3 + 1)))
                                   or [0]))
    prod = _on_grid(quad_grid, l1, m1) * _on_grid(quad_grid, l2, m2) * _on_grid(quad_grid, l3, m3)
    quad = float(np.sum(prod * quad_grid.weights))
    assert abs(real_gaunt(l1, m1, l2, m2, l3, m3) - quad) < 1e-13


def test_selection_rule_on_orders(rng):
    """Non-zero needs one |m| to be the sum of the other two and an even number of negative orders."""
    checked = 0
    for _ in range(3000):
        l1, l2, l3 = (int(x) for x in rng.integers(0, 9, 3))
        m1, m2, m3 = (int(rng.integers(-l, l + 1)) for l in (l1, l2, l3))
        g = real_gaunt(l1, m1, l2, m2, l3, m3)
        a, b, c = sorted((abs(m1), abs(m2), abs(m3)))
        rule = c == a + b and sum(m < 0 for m in (m1, m2, m3)) % 2 == 0
        rule &= (l1 + l2 + l3) % 2 == 0 and abs(l1 - l2) <= l3 <= l1 + l2
        if not rule:
            assert g == 0.0
        else:
            checked += abs(g) > 1e-14
    assert checked > 50


def test_permutation_symmetry(rng):
    for _ in range(200):
        l = [int(x) for x in rng.integers(0, 10, 3)]
        m = [int(rng.integers(-x, x + 1)) for x in l]
        ref = real_gaunt(l[0], m[0], l[1], m[1], l[2], m[2])
        for p in itertools.permutations(range(3)):
            assert real_gaunt(l[p[0]], m[p[0]], l[p[1]], m[p[1]], l[p[2]], m[p[2]]) == pytest.approx(ref, abs=1e-15)


def test_closed_forms():
    # Y00 is constant 1/sqrt(4pi): G(00, lm, lm) = 1/sqrt(4pi)
    for l, m in [(0, 0), (3, -2), (7, 7), (12, 0)]:
        assert real_gaunt(0, 0, l, m, l, m) == pytest.approx(1 / np.sqrt(4 * np.pi), rel=1e-14)
    # x^2 + y^2 + z^2 = 1: sum_m G(1m, 1m, 00) * sqrt(4pi) / 3 * 4pi/3 ... checked as int (x^2) = 4pi/3
    assert real_gaunt(1, 1, 1, 1, 0, 0) * np.sqrt(4 * np.pi) == pytest.approx(1.0, rel=1e-14)


def test_bad_arguments():
    with pytest.raises(InvalidArgumentError, match="m2"):
        real_gaunt(1, 0, 2, 3, 3, 0)
    with pytest.raises(InvalidArgumentError, match="integer"):
        real_gaunt(1.5, 0, 2, 0, 3, 0)
    with pytest.raises(InvalidArgumentError):
        real_gaunt(-1, 0, 2, 0, 3, 0)
