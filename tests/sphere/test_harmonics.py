"""Conventions: flat index, cilm/SHCoeffs round trips, and the harmonics themselves against scipy's complex ones."""

import numpy as np
import pyshtools
import pytest
import scipy.special

from shspec.errors import BandLimitError, ConventionError, InvalidArgumentError
from shspec.sphere.factor import ConformalFactor
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


@pytest.mark.parametrize("lmax, lc", [(20, 8), (47, 15), (78, 39)])
def test_grid_transforms_agree_with_pyshtools(rng, lmax, lc):
    """The tabulated transforms give pyshtools' MakeGridGLQ and SHExpandGLQ to rounding, on a grid finer than the
    coefficients and for a function (exp) that is not band-limited."""
    grid = glq_grid(lmax)
    a = rng.standard_normal((lc + 1) ** 2)
    cilm = np.zeros((2, lmax + 1, lmax + 1))
    cilm[:, : lc + 1, : lc + 1] = vector_to_cilm(a)
    values = evaluate_on_grid(a, grid)
    ref = pyshtools.expand.MakeGridGLQ(cilm, grid.zero, lmax=lmax, norm=4, csphase=1, lmax_calc=lc)
    assert np.max(np.abs(values - ref)) <= 1e-13 * np.max(np.abs(ref))
    f = np.exp(0.1 * values)
    ref = cilm_to_vector(pyshtools.expand.SHExpandGLQ(f, grid.w, grid.zero, norm=4, csphase=1, lmax_calc=lmax))
    assert np.max(np.abs(expand_grid(f, grid, lmax) - ref)) <= 1e-13 * np.max(np.abs(ref))


def test_no_transform_plans_its_ffts_by_timing(monkeypatch, rng):
    """pyshtools' GLQ transforms plan FFTW by measuring (FFTW_MEASURE), so their bits depend on the load: the
    grids, the log-ρ model's mass and the Möbius centring must not use them."""
    from shspec.galerkin.log_model import LogHarmonicModel
    from shspec.sphere.mobius import center_harmonic

    def refuse(*args, **kwargs):
        raise AssertionError("an FFTW-planned pyshtools transform was called")

    monkeypatch.setattr(pyshtools.expand, "MakeGridGLQ", refuse)
    monkeypatch.setattr(pyshtools.expand, "SHExpandGLQ", refuse)
    grid = glq_grid(16)
    a = rng.standard_normal(49) * 0.05
    expand_grid(evaluate_on_grid(a, grid), grid, 6)
    u = np.zeros(16)
    u[4:] = a[4:16]
    LogHarmonicModel(8, 3).eigenvalues(u, 10)
    rho = np.zeros(16)
    rho[0], rho[1:] = np.sqrt(4 * np.pi), 0.1 * a[1:16]
    center_harmonic(rho)


# issue 50 item 24: a raw cilm array does not carry its normalization ------------------------------------------

def _blob_in(normalization: str, csphase: int = 1) -> np.ndarray:
    from shspec.fitting import blob_factor

    ortho = pyshtools.SHCoeffs.from_array(blob_factor().to_cilm(), normalization="ortho", csphase=1)
    return ortho.convert(normalization=normalization, csphase=csphase).coeffs


def test_a_raw_cilm_array_without_its_normalization_is_refused_by_name():
    import shspec

    cilm = _blob_in("4pi")  # what pyshtools.expand gives by default: read as orthonormal it was rho / sqrt(4 pi)
    for call in (lambda: as_coefficients(cilm), lambda: ConformalFactor(cilm), lambda: shspec.spectrum(cilm, 8, 5)):
        with pytest.raises(ConventionError, match="does not say its normalization.*'4pi'"):
            call()
    with pytest.raises(ConventionError, match="flat coefficients are shspec's own"):
        as_coefficients(np.ones(4), normalization="4pi")


@pytest.mark.parametrize("normalization", ["ortho", "4pi", "schmidt", "unnorm"])
@pytest.mark.parametrize("csphase", [1, -1])
def test_a_cilm_array_in_any_normalization_is_converted_when_it_says_which(normalization, csphase):
    from shspec.fitting import blob_factor

    cilm = _blob_in(normalization, csphase)
    expected = blob_factor().coefficients
    np.testing.assert_allclose(as_coefficients(cilm, normalization=normalization, csphase=csphase), expected,
                               rtol=1e-12, atol=1e-14)
    rho = ConformalFactor(cilm, normalization=normalization, csphase=csphase)
    assert rho.area == pytest.approx(4 * np.pi, rel=1e-12)
    np.testing.assert_allclose(cilm_to_vector(cilm, normalization=normalization, csphase=csphase), expected,
                               rtol=1e-12, atol=1e-14)
    shc = pyshtools.SHCoeffs.from_array(cilm, normalization=normalization, csphase=csphase)
    np.testing.assert_allclose(as_coefficients(shc), expected, rtol=1e-12, atol=1e-14)  # an SHCoeffs says it
