"""MeshModel: the SpectralModel of per-vertex conformal factors, checked against finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from shspec.errors import InvalidArgumentError, NotPositiveError
from shspec.mesh.eigen import mesh_spectrum
from shspec.mesh.model import MeshModel
from shspec.mesh.shapes import blob, icosphere
from shspec.spectral_model import SpectralModel


@pytest.fixture(scope="module")
def model():
    return MeshModel(icosphere(2))


def _factors(n, seed=3):
    rng = np.random.default_rng(seed)
    return np.exp(0.3 * rng.standard_normal(n))


def test_is_a_spectral_model(model):
    assert isinstance(model, SpectralModel) and model.nparams == 162


def test_unit_factors_give_the_mesh_spectrum_and_scaling(model):
    # k = 9 = all of l ≤ 2, so that no exact multiplet of the icosphere is cut.
    ref = mesh_spectrum(model.mesh, 9, whole_multiplets=False).eigenvalues
    np.testing.assert_allclose(model.spectrum(np.ones(162), 9).eigenvalues, ref, atol=1e-12)
    # A constant factor s scales every area by s and every eigenvalue by 1/s.
    np.testing.assert_allclose(model.spectrum(np.full(162, 2.5), 9).eigenvalues, ref / 2.5, atol=1e-12)
    with pytest.warns(RuntimeWarning, match="degenerate group"):
        model.spectrum(np.ones(162), 5)  # cuts the 5-fold l = 2 multiplet after its first member


def test_jacobian_matches_finite_differences(model):
    c = _factors(162)
    spec = model.spectrum(c, 8)
    J = model.jacobian(spec)
    assert J.shape == (8, 162)
    # h balances truncation (~h²) against the dense solver's rounding (~1e-12 absolute, divided by h).
    h = 1e-4
    for j in (0, 17, 101):
        e = np.zeros(162)
        e[j] = h
        fd = (model.spectrum(c + e, 8).eigenvalues - model.spectrum(c - e, 8).eigenvalues) / (2 * h)
        np.testing.assert_allclose(J[:, j], fd, rtol=1e-6, atol=1e-8)
    # Euler's relation for a degree −1 homogeneous function: Σ_j c_j ∂λ_i/∂c_j = −λ_i.
    np.testing.assert_allclose(J @ c, -spec.eigenvalues, atol=1e-10)


def test_energy_gradient_matches_finite_differences_on_the_lanczos_path():
    model = MeshModel(blob(4))  # 2562 vertices
    c = _factors(model.nparams, seed=5)
    target = model.spectrum(np.ones(model.nparams), 12).eigenvalues * 1.1
    energy, grad, spec = model.energy(c, target)
    np.testing.assert_allclose(model.contract(spec, np.ones(12)), model.jacobian(spec).sum(axis=0), rtol=1e-12)
    rng = np.random.default_rng(0)
    d = rng.standard_normal(model.nparams) * c
    h = 1e-6
    fd = (model.energy(c + h * d, target)[0] - model.energy(c - h * d, target)[0]) / (2 * h)
    assert grad @ d == pytest.approx(fd, rel=1e-6)


def test_bilaplacian_penalty(model):
    c = _factors(162)
    value, grad = model.bilaplacian_penalty(c, 0.7)
    # Zero on constants (to rounding, against a value of order 1e2 here).
    assert model.bilaplacian_penalty(np.full(162, 3.0), 0.7)[0] < 1e-9 * value
    d = _factors(162, seed=9)
    h = 1e-5
    fd = (model.bilaplacian_penalty(c + h * d, 0.7)[0] - model.bilaplacian_penalty(c - h * d, 0.7)[0]) / (2 * h)
    assert grad @ d == pytest.approx(fd, rel=1e-8)
    Lc = model.stiffness @ c
    assert value == pytest.approx(0.7 * np.sum(Lc ** 2 / model.vertex_areas), rel=1e-12)


def test_argument_errors(model):
    c = np.ones(162)
    c[4] = 0.0
    with pytest.raises(NotPositiveError, match="vertex 4"):
        model.spectrum(c, 5)
    with pytest.raises(InvalidArgumentError, match="shape"):
        model.spectrum(np.ones(10), 5)
    c[4] = np.nan
    with pytest.raises(InvalidArgumentError, match="NaN"):
        model.spectrum(c, 5)
    spec = model.spectrum(np.ones(162), 4)
    with pytest.raises(InvalidArgumentError, match="coef"):
        model.contract(spec, np.ones(3))
    with pytest.raises(InvalidArgumentError, match="weight"):
        model.bilaplacian_penalty(np.ones(162), -1.0)
