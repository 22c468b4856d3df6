"""Conventions: flat index, cilm/SHCoeffs round trips, and the harmonics themselves against scipy's complex ones."""

import numpy as np
import pyshtools
import pytest
import scipy.special

from shspec.errors import BandLimitError, ConventionError, InvalidArgumentError
from shspec.sphere.grid import evaluate_on_grid, expand_grid, glq_grid
from shspec.sphere.harmonics import (as_coefficients, cilm_to_vector, degree_order, flat_index, lmax_of_size,
                              shcoeffs_to_vector, vector_to_cilm, vector_to_shcoeffs)


def test_flat_index_order():
    l, m = degree_order(3)
    assert list(zip(l[:5], m[:5])) == [(0, 0), (1, -1), (1, 0), (1, 1), (2, -2)]
    np.testing.assert_array_equal(flat_index(l, m), np.arange(16))
    assert lmax_of_size(16) == 3
    with pytest.raises(InvalidArgumentError):
        lmax_of_size(15)


def test_cilm_round_trip(rng):
    a = rng.standard_normal(49)
    cilm = vector_to_cilm(a)
    assert cilm.shape == (2, 7, 7)
    assert cilm[0, 3, 2] == a[3 * 3 + 3 + 2] and cilm[1, 3, 2] == a[3 * 3 + 3 - 2]
    assert np.all(cilm[1, :, 0] == 0)
    np.testing.assert_array_equal(cilm_to_vector(cilm), a)
    np.testing.assert_array_equal(shcoeffs_to_vector(vector_to_shcoeffs(a)), a)
    padded = as_coefficients(a, 8)
    assert padded.size == 81 and np.all(padded[49:] == 0)


def test_shcoeffs_other_normalization_is_converted(rng):
    a = rng.standard_normal(25)
    c4pi = vector_to_shcoeffs(a).convert(normalization="4pi", csphase=-1)
    np.testing.assert_allclose(shcoeffs_to_vector(c4pi), a, atol=1e-13)
    with pytest.raises(ConventionError):
        shcoeffs_to_vector(pyshtools.SHCoeffs.from_zeros(3, kind="complex"))


def test_bad_vectors():
    with pytest.raises(InvalidArgumentError, match="NaN"):
        as_coefficients([1.0, np.nan, 0, 0])
    with pytest.raises(BandLimitError):
        as_coefficients(np.ones(9), 1)


def test_real_harmonics_match_scipy_complex_ones(rng):
    """Y_lm (m>0) = sqrt2 (-1)^m Re Y_l^m and Y_l,-m = sqrt2 (-1)^m Im Y_l^m, with scipy's Condon-Shortley Y."""
    grid = glq_grid(12)
    theta, phi = np.meshgrid(grid.colat, grid.lon, indexing="ij")
    l, m = degree_order(8)
    for i in rng.choice(l.size, size=25, replace=False):
        e = np.zeros(l.size)
        e[i] = 1.0
        ours = evaluate_on_grid(e, grid)
        y = scipy.special.sph_harm_y(l[i], abs(m[i]), theta, phi)
        if m[i] == 0:
            ref = y.real
        elif m[i] > 0:
            ref = np.sqrt(2) * (-1.0) ** int(m[i]) * y.real
        else:
            ref = np.sqrt(2) * (-1.0) ** int(m[i]) * y.imag
        np.testing.assert_allclose(ours, ref, atol=1e-13, err_msg=f"l={l[i]} m={m[i]}")


def test_degree_one_is_position():
    grid = glq_grid(6)
    xyz = grid.unit_vectors() * np.sqrt(3 / (4 * np.pi))
    for idx, axis in ((1, 1), (2, 2), (3, 0)):  # m=-1 ~ y, m=0 ~ z, m=1 ~ x
        e = np.zeros(4)
        e[idx] = 1
        np.testing.assert_allclose(evaluate_on_grid(e, grid), xyz[..., axis], atol=1e-14)


def test_grid_expansion_round_trip(rng):
    grid = glq_grid(20)
    a = rng.standard_normal(121)
    np.testing.assert_allclose(expand_grid(evaluate_on_grid(a, grid), grid, 10), a, atol=1e-12)
