"""The quadrature quadratic forms v_qᵀ G_k v_q against the Gaunt-table kernel and a dense Gaunt tensor."""

import numpy as np
import pytest

from shspec.errors import InvalidArgumentError
from shspec.galerkin.gridforms import GridQuadraticForms
from shspec.galerkin.model import HarmonicModel
from shspec.gaunt.build import build_table
from shspec.sphere.harmonics import ncoeffs

from conftest import random_factor_coefficients


@pytest.mark.slow
@pytest.mark.parametrize("lmax, lmax_factor", [(5, 3), (4, 8), (9, 0), (12, 7)])
def test_quadratic_forms_equal_the_table_kernel(rng, lmax, lmax_factor):
    table = build_table(lmax, lmax_factor)
    vecs = rng.standard_normal((ncoeffs(lmax), 7))
    forms = GridQuadraticForms(lmax, lmax_factor)
    expected = table.quadratic_forms(vecs)
    got = forms(vecs)
    assert got.shape == (ncoeffs(lmax_factor), 7)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    coef = rng.standard_normal(7)
    np.testing.assert_allclose(forms.weighted(vecs, coef), expected @ coef, rtol=0,
                               atol=1e-12 * np.abs(expected @ coef).max())


def test_quadratic_forms_equal_a_dense_gaunt_tensor(rng):
    # G_ijk = ∫ Y_i Y_j Y_k column by column from the table's mass matrices (M(e_k) = G_k), an independent route
    table = build_table(4, 3)
    dense = np.stack([table.mass_matrix(e) for e in np.eye(ncoeffs(3))], axis=-1)
    vecs = rng.standard_normal((ncoeffs(4), 3))
    np.testing.assert_allclose(GridQuadraticForms(4, 3)(vecs), np.einsum("ijk,iq,jq->kq", dense, vecs, vecs),
                               rtol=0, atol=1e-13 * np.abs(dense).max() * np.abs(vecs).max() ** 2 * 25 ** 2)


@pytest.mark.slow
def test_model_jacobian_and_gradient_use_the_same_forms(rng):
    model = HarmonicModel(10, 5)
    a = random_factor_coefficients(rng, 5, amplitude=0.3)
    spec = model.spectrum(a, 40)
    q = model.table.quadratic_forms(spec.eigenvectors)
    jac = model.jacobian(spec)
    np.testing.assert_allclose(jac, -(q * spec.eigenvalues[None, :]).T, rtol=0, atol=1e-12 * np.abs(jac).max())
    coef = rng.standard_normal(40)
    b = (spec.eigenvectors * (coef * spec.eigenvalues)[None, :]) @ spec.eigenvectors.T
    grad = model.contract(spec, coef)
    np.testing.assert_allclose(grad, -model.table.contract(b), rtol=0, atol=1e-12 * np.abs(grad).max())


def test_bad_shapes_are_named():
    forms = GridQuadraticForms(3, 2)
    with pytest.raises(InvalidArgumentError, match="shape"):
        forms(np.ones((15, 2)))
    with pytest.raises(InvalidArgumentError, match="coef"):
        forms.weighted(np.ones((16, 2)), np.ones(3))
    with pytest.raises(InvalidArgumentError):
        GridQuadraticForms(3, 7)
