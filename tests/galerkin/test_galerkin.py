"""The Galerkin forward solver against closed forms, invariances, an independent discretization and finite differences."""

import numpy as np
import pytest
import scipy.linalg

from shspec import ConformalFactor, spectrum
from shspec.errors import BandLimitError, InvalidArgumentError, NotPositiveError
from shspec.galerkin.model import HarmonicModel
from shspec.sphere.harmonics import degrees

from conftest import random_factor_coefficients


def sphere_eigenvalues(k):
    l = np.repeat(np.arange(40), 2 * np.arange(40) + 1)[:k]
    return (l * (l + 1)).astype(float)


@pytest.mark.parametrize("k", [1.5, 2.0])
@pytest.mark.parametrize("axis", [(0, 0, 1), (1, 0, 0), (1, -2, 3)])
def test_boosted_sphere_is_isometric_to_the_round_one(k, axis):
    rho = ConformalFactor.mobius_boost(k, 30, axis)
    lam = spectrum(rho, lmax=30, k=36).eigenvalues
    exact = sphere_eigenvalues(36)
    assert lam[0] == 0.0
    np.testing.assert_allclose(lam[1:], exact[1:], rtol=1e-12, atol=0)


def test_boost_error_falls_exponentially_with_the_basis():
    rho = ConformalFactor.mobius_boost(2.0, 30, (0, 1, 1))
    model = HarmonicModel(30, 30)
    lbs = [6, 10, 14, 18, 22]
    errs = []
    for lb in lbs:
        lam = HarmonicModel(lb, min(30, 2 * lb), table=model.table).spectrum(rho.truncated(min(30, 2 * lb)), 16)
        errs.append(np.max(np.abs(lam.eigenvalues[1:] - sphere_eigenvalues(16)[1:]) / sphere_eigenvalues(16)[1:]))
    errs = np.array(errs)
    assert np.all(np.diff(np.log(errs)) < -1.0), errs  # each 4 degrees gain more than a factor e
    slope = np.polyfit(lbs, np.log(errs), 1)[0]
    assert slope < -0.5, errs  # geometric decay, not algebraic


def test_round_sphere_multiplicities_and_scaling():
    lam = spectrum(ConformalFactor.sphere(4 * np.pi, 2), lmax=12, k=49).eigenvalues
    np.testing.assert_allclose(lam, sphere_eigenvalues(49), atol=1e-12)
    area = 7.0  # lambda scales as 1/c when rho scales by c
    lam2 = spectrum(ConformalFactor.sphere(area, 2), lmax=12, k=49).eigenvalues
    np.testing.assert_allclose(lam2, sphere_eigenvalues(49) * 4 * np.pi / area, atol=1e-12)


def test_rotation_and_scaling_invariance(rng):
    rho = ConformalFactor(random_factor_coefficients(rng, 6, amplitude=0.4))
    base = spectrum(rho, lmax=20, k=60).eigenvalues
    for angles in [(30, 40, 50), (0, 180, 0), (123, 17, -80)]:
        rot = spectrum(rho.rotated(*angles), lmax=20, k=60).eigenvalues
        np.testing.assert_allclose(rot, base, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(spectrum(rho.scaled(2.5), lmax=20, k=60).eigenvalues, base / 2.5, rtol=1e-13)


def test_agrees_with_a_dense_generalized_solver_and_is_m_orthonormal(rng):
    model = HarmonicModel(14, 6)
    a = random_factor_coefficients(rng, 6, amplitude=0.5)
    spec = model.spectrum(a, 80)
    m = model.mass_matrix(a)
    s = np.diag((degrees(14) * (degrees(14) + 1)).astype(float))
    ref = scipy.linalg.eigh(s, m, eigvals_only=True, subset_by_index=[0, 79])
    np.testing.assert_allclose(spec.eigenvalues, ref, rtol=1e-11, atol=1e-11)
    v = spec.eigenvectors
    np.testing.assert_allclose(v.T @ m @ v, np.eye(80), atol=1e-12)
    np.testing.assert_allclose(s @ v, m @ v * spec.eigenvalues, atol=1e-9 * spec.eigenvalues.max())


@pytest.mark.filterwarnings("ignore::shspec.errors.TruncationWarning")  # coarse bases on purpose
def test_galerkin_eigenvalues_decrease_with_the_basis(rng):
    rho = ConformalFactor(random_factor_coefficients(rng, 8, amplitude=0.6))
    prev = None
    for lb in (8, 10, 13, 16, 20):
        lam = spectrum(rho, lmax=lb, k=40).eigenvalues
        if prev is not None:
            assert np.all(lam <= prev + 1e-10 * prev.max())
            assert np.any(lam < prev - 1e-6)
        prev = lam


def test_jacobian_and_gradient_match_finite_differences(rng):
    model = HarmonicModel(12, 4)
    a = random_factor_coefficients(rng, 4, amplitude=0.3)
    k = 30
    spec = model.spectrum(a, k)
    jac = model.jacobian(spec)
    h = 1e-6
    fd = np.empty_like(jac)
    for j in range(model.nparams):
        e = np.zeros(model.nparams)
        e[j] = h
        fd[:, j] = (model.spectrum(a + e, k).eigenvalues - model.spectrum(a - e, k).eigenvalues) / (2 * h)
    # away from degeneracies: compare eigenvalues that are well separated from their neighbours
    lam = spec.eigenvalues
    gap = np.minimum(np.diff(lam, prepend=-np.inf), np.diff(lam, append=np.inf))
    ok = gap > 1e-3 * lam.max()
    assert ok.sum() > 10
    np.testing.assert_allclose(jac[ok], fd[ok], rtol=1e-6, atol=1e-6 * np.abs(jac).max())
    target = lam * (1 + 0.02 * rng.standard_normal(k))
    energy, grad, _ = model.energy(a, target)
    fd_grad = np.array([(model.energy(a + h * e, target)[0] - model.energy(a - h * e, target)[0]) / (2 * h)
                        for e in np.eye(model.nparams)])
    np.testing.assert_allclose(grad, fd_grad, rtol=1e-6, atol=1e-8 * np.abs(grad).max())
    np.testing.assert_allclose(grad, jac.T @ (lam - target), rtol=1e-10, atol=1e-12)


def test_negative_factor_says_where(rng):
    a = np.zeros(9)
    a[0] = np.sqrt(4 * np.pi)
    a[2] = 3.0  # rho = 1 + 3 * sqrt(3/4pi) z is negative near the south pole
    with pytest.raises(NotPositiveError, match="colatitude 1[78][0-9]"):
        spectrum(a, lmax=8, k=10)


def test_bad_arguments():
    rho = ConformalFactor.sphere(lmax=2)
    with pytest.raises(BandLimitError, match="raise lmax"):
        spectrum(rho, lmax=3, k=17)
    with pytest.raises(InvalidArgumentError):
        spectrum(rho, lmax=3, k=0)
    with pytest.raises(InvalidArgumentError, match="NaN"):
        spectrum(np.array([np.nan, 0, 0, 0]), lmax=3, k=4)
    with pytest.raises(InvalidArgumentError, match="coefficients"):
        HarmonicModel(6, 2).spectrum(np.ones(4), 3)
    with pytest.raises(BandLimitError, match="precompute"):
        HarmonicModel(41, 37, build=False)


@pytest.mark.parametrize("k", [1, 2, 20, 120, 169])
def test_eigenvalues_alone_equal_the_spectrum(rng, k):
    # k = 20 takes the MRRR subset driver, 120 and 169 the full divide and conquer (shspec.galerkin.eigen)
    model = HarmonicModel(12, 4)
    a = random_factor_coefficients(rng, 4, amplitude=0.3)
    full = model.spectrum(a, k)
    np.testing.assert_allclose(model.eigenvalues(a, k), full.eigenvalues, rtol=1e-13, atol=1e-13)
    assert k < 3 or full.solver == ("evr" if k == 20 else "evd")
