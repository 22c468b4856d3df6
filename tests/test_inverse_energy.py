"""The fit energy: gradient and Jacobian against finite differences, weights, regularizers, gauge, errors."""

from __future__ import annotations

import numpy as np
import pytest

from shspec import HarmonicModel
from shspec.errors import InvalidArgumentError, NotPositiveError
from shspec.sphere.harmonics import degrees
from shspec.inverse.energy import Objective, eigenvalue_weights, relative_residual
from shspec.inverse.parametrization import Parametrization
from shspec.mesh.model import MeshModel
from shspec.mesh.shapes import icosphere


def _par(model, params, fit_area):
    return Parametrization.at(params, model.free_parameters(fit_area), model.transform)


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
    obj = Objective(model, target, eigenvalue_weights(target, weights), _par(model, start, True), reg)
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
    obj = Objective(model, target, eigenvalue_weights(target), _par(model, truth, False))
    assert obj.evaluate(obj.initial()).energy < 1e-26
    reg = 1e-2
    obj_r = Objective(model, target, eigenvalue_weights(target), _par(model, truth, False), reg)
    l = degrees(4)
    expected = reg * np.sum((l * (l + 1.0)) ** 2 * truth ** 2)  # R Σ (l(l+1))² a²
    assert obj_r.evaluate(obj_r.initial()).energy == pytest.approx(expected, rel=1e-10)


def test_gauge_leaves_out_a1m_and_optionally_a00():
    model = HarmonicModel(6, 3)
    free = model.free_parameters(fit_area=False)
    assert 0 not in free and not set(free) & {1, 2, 3} and free.size == 16 - 4
    assert 0 in model.free_parameters(fit_area=True)


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
    model = MeshModel(icosphere(1))
    c = 1 + 0.1 * np.random.default_rng(3).standard_normal(model.nparams)
    D = model.regularizer(0.3)
    value, _ = model.bilaplacian_penalty(c, 0.3)
    assert 0.5 * np.sum((D @ c) ** 2) == pytest.approx(value, rel=1e-12)
    assert model.regularizer(0.0) is None
    with pytest.raises(InvalidArgumentError):
        model.regularizer(-1.0)


def test_harmonic_regularizer_is_r_times_the_squared_laplacian():
    model = HarmonicModel(6, 3)
    a = np.random.default_rng(5).standard_normal(16)
    l = degrees(3)
    # ‖Δρ‖² = Σ (l(l+1))² a_lm² on the unit sphere (orthonormal harmonics)
    assert 0.5 * np.sum((model.regularizer(0.2) @ a) ** 2) == pytest.approx(0.2 * np.sum((l * (l + 1.0)) ** 2 * a ** 2))


@pytest.mark.parametrize("reg", [0.0, 1e-3])
def test_log_factor_gradient_and_jacobian_match_finite_differences(reg):
    """c = exp(s): the chain rule of the parametrization against central differences in s, regularizer on s."""
    model = MeshModel(icosphere(1), transform="exp")
    rng = np.random.default_rng(6)
    truth = np.exp(0.5 * rng.standard_normal(model.nparams))
    start = np.exp(0.3 * rng.standard_normal(model.nparams))
    target = model.spectrum(truth, 12).eigenvalues
    obj = Objective(model, target, eigenvalue_weights(target), _par(model, start, True), reg)
    x = obj.initial()
    np.testing.assert_allclose(x, np.log(start), rtol=1e-15)
    ev = obj.evaluate(x, jacobian=True)
    np.testing.assert_allclose(ev.jacobian.T @ ev.residuals, ev.gradient, rtol=1e-9, atol=1e-14)
    h = 1e-6
    for j in (0, 7, x.size - 1):
        e = np.zeros_like(x)
        e[j] = h
        fd = (obj.evaluate(x + e).energy - obj.evaluate(x - e).energy) / (2 * h)
        assert fd == pytest.approx(ev.gradient[j], rel=1e-5, abs=1e-12)
        fd_r = (obj.evaluate(x + e).residuals - obj.evaluate(x - e).residuals) / (2 * h)
        np.testing.assert_allclose(fd_r, ev.jacobian[:, j], rtol=1e-4, atol=1e-9)
    if reg:
        # the regularizer acts on s = log c: its part of the energy is the bi-Laplacian penalty of s
        value, _ = model.bilaplacian_penalty(np.log(start), reg)
        assert 0.5 * np.sum(ev.residuals[target.size:] ** 2) == pytest.approx(value, rel=1e-12)


def test_parametrization_maps_free_variables_and_refuses_bad_input():
    par = Parametrization.at(np.array([2.0, 3.0, 5.0]), [0, 2], "exp")
    np.testing.assert_allclose(par.params(np.log([7.0, 11.0])), [7.0, 3.0, 11.0], rtol=1e-15)
    np.testing.assert_allclose(par.pullback(np.log([7.0, 11.0]), np.array([1.0, 1.0, 1.0])), [7.0, 11.0])
    with pytest.raises(NotPositiveError):
        Parametrization.at(np.array([1.0, -1.0]), [0, 1], "exp")
    with pytest.raises(InvalidArgumentError):
        Parametrization(np.zeros(3), [2, 1])
    with pytest.raises(InvalidArgumentError):
        Parametrization(np.zeros(3), [0], "log")


def test_not_positive_and_bad_input(model):
    target = model.spectrum(_factor(np.random.default_rng(4), 4), 10).eigenvalues
    a = np.zeros(25)
    a[0] = 1.0
    a[6] = 3.0  # a large a_20 makes ρ negative near the poles or the equator
    obj = Objective(model, target, eigenvalue_weights(target), _par(model, a, False))
    with pytest.raises(NotPositiveError):
        obj.evaluate(obj.initial())
    with pytest.raises(InvalidArgumentError):
        Objective(model, target, np.ones(3), Parametrization(a, [4]))
    with pytest.raises(InvalidArgumentError):
        Objective(model, target, eigenvalue_weights(target), Parametrization(np.zeros(9), [4]))
    with pytest.raises(InvalidArgumentError):
        Parametrization(a, [99])
