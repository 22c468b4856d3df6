"""The fit energy: gradient and Jacobian against finite differences, weights, regularizers, gauge, errors."""

from __future__ import annotations

import numpy as np
import pytest

from shspec import HarmonicModel
from shspec.errors import InvalidArgumentError, NotPositiveError
from shspec.sphere.harmonics import degrees
from shspec.inverse.energy import (Objective, eigenvalue_weights, harmonic_free_indices, regularizer_matrix,
                                   relative_residual)


def _factor(rng, la, amp=0.1):
    a = np.zeros((la + 1) ** 2)
    a[0] = np.sqrt(4 * np.pi)
    a[4:] = amp * rng.standard_normal(a.size - 4)
    return a


@pytest.fixture(scope="module")
def model():
    return HarmonicModel(8, 4)


@pytest.mark.parametrize("weights,reg", [("relative", 0.0), ("absolute", 1e-3)])
def test_gradient_and_jacobian_match_finite_differences(model, weights, reg):
    rng = np.random.default_rng(1)
    truth, start = _factor(rng, 4), _factor(rng, 4)
    target = model.spectrum(truth, 20).eigenvalues
    obj = Objective(model, target, eigenvalue_weights(target, weights), start, harmonic_free_indices(4, True), reg)
    x = obj.initial()
    ev = obj.evaluate(x, jacobian=True)
    # Gauss–Newton's identity: the gradient is Jᵀr.
    np.testing.assert_allclose(ev.jacobian.T @ ev.residuals, ev.gradient, rtol=1e-9, atol=1e-14)
    h = 1e-6
    for j in (0, 1, 5, x.size - 1):
        e = np.zeros_like(x)
        e[j] = h
        fd = (obj.evaluate(x + e).energy - obj.evaluate(x - e).energy) / (2 * h)
        assert fd == pytest.approx(ev.gradient[j], rel=1e-5, abs=1e-10)
        fd_r = (obj.evaluate(x + e).residuals - obj.evaluate(x - e).residuals) / (2 * h)
        np.testing.assert_allclose(fd_r, ev.jacobian[:, j], rtol=1e-4, atol=1e-9)


def test_energy_is_zero_at_the_truth_and_counts_the_regularizer(model):
    rng = np.random.default_rng(2)
    truth = _factor(rng, 4)
    target = model.spectrum(truth, 15).eigenvalues
    free = harmonic_free_indices(4, False)
    obj = Objective(model, target, eigenvalue_weights(target), truth, free)
    assert obj.evaluate(obj.initial()).energy < 1e-26
    reg = 1e-2
    obj_r = Objective(model, target, eigenvalue_weights(target), truth, free, reg)
    l = degrees(4)
    expected = reg * np.sum((l * (l + 1.0)) ** 2 * truth ** 2)  # R Σ (l(l+1))² a²
    assert obj_r.evaluate(obj_r.initial()).energy == pytest.approx(expected, rel=1e-10)


def test_gauge_leaves_out_a1m_and_optionally_a00():
    free = harmonic_free_indices(3, fit_area=False)
    assert 0 not in free and not set(free) & {1, 2, 3} and free.size == 16 - 4
    assert 0 in harmonic_free_indices(3, fit_area=True)


def test_weights_and_relative_residual():
    lam = np.array([0.0, 2.0, 4.0])
    np.testing.assert_allclose(eigenvalue_weights(lam), [0, 0.25, 1 / 16])
    np.testing.assert_allclose(eigenvalue_weights(lam, "absolute"), [0, 1, 1])
    assert relative_residual([0, 2.2, 4.0], lam) == pytest.approx(0.1)
    with pytest.raises(InvalidArgumentError):
        eigenvalue_weights(lam, "squared")
    with pytest.raises(InvalidArgumentError):
        eigenvalue_weights([0.0, -1.0, 2.0])


def test_mesh_regularizer_is_the_bilaplacian_penalty():
    from shspec.mesh.model import MeshModel
    from shspec.mesh.shapes import icosphere

    model = MeshModel(icosphere(1))
    c = 1 + 0.1 * np.random.default_rng(3).standard_normal(model.nparams)
    D = regularizer_matrix(model, 0.3)
    value, _ = model.bilaplacian_penalty(c, 0.3)
    assert 0.5 * np.sum((D @ c) ** 2) == pytest.approx(value, rel=1e-12)
    assert regularizer_matrix(model, 0.0) is None
    with pytest.raises(InvalidArgumentError):
        regularizer_matrix(model, -1.0)


def test_not_positive_and_bad_input(model):
    target = model.spectrum(_factor(np.random.default_rng(4), 4), 10).eigenvalues
    a = np.zeros(25)
    a[0] = 1.0
    a[6] = 3.0  # a large a_20 makes ρ negative near the poles or the equator
    obj = Objective(model, target, eigenvalue_weights(target), a, harmonic_free_indices(4, False))
    with pytest.raises(NotPositiveError):
        obj.evaluate(obj.initial())
    with pytest.raises(InvalidArgumentError):
        Objective(model, target, np.ones(3), a, [4])
    with pytest.raises(InvalidArgumentError):
        Objective(model, target, eigenvalue_weights(target), a, [99])
