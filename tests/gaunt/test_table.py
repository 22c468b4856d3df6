"""Gaunt tables: layout, kernels against brute force, restriction, and the mass matrix against quadrature."""

import numpy as np
import pytest

from shspec import real_gaunt
from shspec.errors import BandLimitError, InvalidArgumentError
from shspec.sphere.grid import evaluate_on_grid, glq_grid
from shspec.sphere.harmonics import degree_order
from shspec.gaunt.build import build_table
from shspec.gaunt.table import GauntTable, table_size

from conftest import random_factor_coefficients


def _dense_gaunt(lmax, lmax_factor):
    l, m = degree_order(lmax)
    la, ma = degree_order(lmax_factor)
    g = np.zeros((l.size, l.size, la.size))
    for i in range(l.size):
        for j in range(i, l.size):
            for k in range(la.size):
                g[i, j, k] = g[j, i, k] = real_gaunt(int(l[i]), int(m[i]), int(l[j]), int(m[j]), int(la[k]),
                                                     int(ma[k]))
    return g


@pytest.fixture(scope="module")
def small():
    return build_table(6, 5), _dense_gaunt(6, 5)


def test_kernels_match_brute_force(small, rng):
    table, g = small
    a = rng.standard_normal(table.nfactor)
    m = table.mass_matrix(a)
    np.testing.assert_allclose(m, np.einsum("ijk,k->ij", g, a), atol=1e-15)
    np.testing.assert_array_equal(m, m.T)
    upper = table.mass_matrix(a, symmetrize=False)
    np.testing.assert_array_equal(np.triu(upper), np.triu(m))
    assert np.all(np.tril(upper, -1) == 0)
    b = rng.standard_normal((table.nbasis, table.nbasis))
    np.testing.assert_allclose(table.contract(b), np.einsum("ijk,ij->k", g, b), atol=1e-14)
    v = rng.standard_normal((table.nbasis, 4))
    np.testing.assert_allclose(table.quadratic_forms(v), np.einsum("ijk,iq,jq->kq", g, v, v), atol=1e-14)


def test_counts(small):
    table, g = small
    # each stored value stands for up to 4 sign patterns and both orders of (i, j): about 1/8 of the non-zeros
    assert np.count_nonzero(np.abs(g) > 1e-15) / table.values.size == pytest.approx(8, rel=0.35)
    assert table_size(30, 15) == 414588
    assert table_size(60, 30) == 11510584


def test_restriction_equals_direct_build():
    big = build_table(12, 9)
    for lb, la in [(12, 9), (10, 9), (12, 4), (7, 3), (3, 0)]:
        # equal to round-off: a family truncated at a smaller La may take the other recursion path
        np.testing.assert_allclose(big.restrict(lb, la).values, build_table(lb, la).values, rtol=0, atol=2e-15)
    with pytest.raises(BandLimitError):
        big.restrict(13, 4)


def test_constant_factor_gives_identity_mass():
    table = build_table(20, 10)
    a = np.zeros(table.nfactor)
    a[0] = np.sqrt(4 * np.pi)
    np.testing.assert_allclose(table.mass_matrix(a), np.eye(table.nbasis), atol=1e-13)


def test_mass_matrix_against_quadrature(rng):
    """M_ij = int rho Y_i Y_j by Gauss-Legendre quadrature, with no Gaunt coefficient involved."""
    lb, la = 14, 8
    table = build_table(lb, la)
    a = random_factor_coefficients(rng, la, amplitude=0.3)
    grid = glq_grid(lb + la // 2 + 2)  # exact for total degree 2*lb + la
    rho = evaluate_on_grid(a, grid)
    basis = np.stack([evaluate_on_grid(np.eye(table.nbasis)[i], grid) for i in range(table.nbasis)])
    y = basis.reshape(table.nbasis, -1)
    quad = (y * (rho * grid.weights).ravel()[None, :]) @ y.T
    np.testing.assert_allclose(table.mass_matrix(a), quad, atol=2e-14)


def test_bad_limits_and_inputs():
    with pytest.raises(BandLimitError, match="2\\*lmax"):
        build_table(4, 9)
    with pytest.raises(BandLimitError):
        build_table(-1, 0)
    with pytest.raises(BandLimitError):
        build_table(True, 0)
    table = build_table(4, 2)
    with pytest.raises(InvalidArgumentError, match="shape"):
        table.mass_matrix(np.ones(4))
    with pytest.raises(InvalidArgumentError, match="NaN"):
        table.mass_matrix(np.full(9, np.nan))
    with pytest.raises(InvalidArgumentError):
        GauntTable(4, 2, np.zeros(3))


@pytest.mark.slow
def test_larger_table_entries_match_quadrature():
    """Most families of a (40, 20) table come from the truncated forward recursion; check whole slices G_{..k}
    against Gauss–Legendre quadrature of Y_i Y_j Y_k with harmonics from scipy (no 3j symbol involved)."""
    from shspec.sphere.evaluate import harmonic_matrix

    lb, la = 40, 20
    table = build_table(lb, la)
    grid = glq_grid((2 * lb + la) // 2 + 1)  # exact for polynomial degree 2·Lb + La
    Y = harmonic_matrix(grid.unit_vectors().reshape(-1, 3), lb)
    w = grid.weights.ravel()
    rng = np.random.default_rng(3)
    ks = [0, 4, 6, 8, (la + 1) ** 2 - 1, *rng.integers(0, (la + 1) ** 2, 6)]
    for k in ks:
        e = np.zeros((la + 1) ** 2)
        e[k] = 1.0
        quad = Y.T @ ((w * Y[:, k])[:, None] * Y)
        np.testing.assert_allclose(table.mass_matrix(e), quad, rtol=0, atol=5e-14)


def test_verify_table_reports_the_worst_sampled_entry():
    """verify_table recomputes entries through real_gaunt (the same double recursion): it must find a planted error."""
    from shspec.gaunt.cache import verify_table

    table = build_table(12, 6)
    assert verify_table(table, samples=500, seed=3) < 5e-15
    damaged = GauntTable(12, 6, table.values.copy())
    damaged.values[:] += 1e-9
    assert verify_table(damaged, samples=500, seed=3) > 5e-10
