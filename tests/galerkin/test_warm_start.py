"""Warm-started eigenpairs (certified Rayleigh–Ritz from a nearby spectrum) against the cold solve, and the fallback."""

import dataclasses

import numpy as np
import pytest

from shspec.errors import InvalidArgumentError
from shspec.galerkin import model as harmonic_model
from shspec.galerkin.model import WARM_GATE, HarmonicModel
from shspec.inverse.energy import Objective, eigenvalue_weights
from shspec.inverse.parametrization import Parametrization

from conftest import random_factor_coefficients

K = 49  # the multiplets of degree 0 … 6 of the round sphere, whole


def step(rng, a, size):
    """a moved by a random step of relative size ``size`` in the non-gauge coefficients."""
    d = rng.standard_normal(a.size)
    d[:4] = 0
    return a + d * size * np.linalg.norm(a) / np.linalg.norm(d)


def relative_difference(warm, cold):
    return np.max(np.abs(warm.eigenvalues[1:] - cold.eigenvalues[1:]) / cold.eigenvalues[1:])


def check_eigenpairs(model, a, spec, tol):
    """S v = λ M v to ``tol`` relative and VᵀMV = I to 1e-12, from the assembled matrices (independent of either
    solver path)."""
    m = model.mass_matrix(a)
    s = np.diag((lambda l: l * (l + 1.0))(np.repeat(np.arange(model.lmax + 1), 2 * np.arange(model.lmax + 1) + 1)))
    v = spec.eigenvectors
    np.testing.assert_allclose(v.T @ m @ v, np.eye(spec.k), atol=1e-12)
    resid = s @ v - (m @ v) * spec.eigenvalues[None, :]
    assert np.abs(resid).max() <= tol * spec.eigenvalues.max()


@pytest.fixture(scope="module")
def model():
    return HarmonicModel(12, 6)


@pytest.mark.parametrize("size", [0.0, 1e-11, 1e-9])
def test_small_steps_are_warm_and_equal_the_cold_solve(model, rng, size):
    a = random_factor_coefficients(rng, 6, amplitude=0.3)
    start = model.spectrum(a, K)
    b = step(rng, a, size)
    warm = model.spectrum(b, K, start=start)
    cold = model.spectrum(b, K)
    assert warm.solver == "warm" and cold.solver in ("evr", "evd")
    assert relative_difference(warm, cold) <= 1e-13
    # the eigenvalues are certified; the vectors' residual is of the order of the step (the Jacobian's error with it)
    check_eigenpairs(model, b, warm, 1e-12 + 1e3 * size)
    # the eigenvectors (eigenvalues here are separated by >= 6e-4 relative) and so the Jacobian follow to ~ the step
    jw, jc = model.jacobian(warm), model.jacobian(cold)
    assert np.abs(jw - jc).max() <= (1e-12 + 10 * size) * np.abs(jc).max()


def test_a_start_whose_vectors_do_not_fit_falls_back(model, rng):
    # the gate sees the start's coefficients as equal to the new ones, but its vectors belong to another rho: only
    # the residual check can refuse them
    a = random_factor_coefficients(rng, 6, amplitude=0.3)
    other = model.spectrum(random_factor_coefficients(rng, 6, amplitude=0.3), K)
    fake = dataclasses.replace(other, coefficients=a.copy())
    spec = model.spectrum(a, K, start=fake)
    cold = model.spectrum(a, K)
    assert spec.solver == cold.solver != "warm"
    np.testing.assert_array_equal(spec.eigenvalues, cold.eigenvalues)


def test_a_step_beyond_what_rayleigh_ritz_certifies_falls_back(model, rng, monkeypatch):
    a = random_factor_coefficients(rng, 6, amplitude=0.3)
    start = model.spectrum(a, K)
    far = model.spectrum(step(rng, a, 100 * WARM_GATE), K, start=start)  # beyond the gate: not even tried
    assert far.solver != "warm"
    monkeypatch.setattr(harmonic_model, "WARM_GATE", 1.0)  # let the residual check decide
    b = step(rng, a, 1e-5)  # Rayleigh–Ritz errs by ~1e-10 relative here
    spec = model.spectrum(b, K, start=start)
    assert spec.solver != "warm"
    assert relative_difference(spec, model.spectrum(b, K)) == 0


def test_near_round_clusters(model, rng):
    # multiplets of the round sphere split by ~1e-7: single eigenvectors are nearly arbitrary inside a cluster, the
    # eigenvalues and the cluster sums of the Jacobian are not
    a = np.zeros(model.nparams)
    a[0] = np.sqrt(4 * np.pi)
    a = step(rng, a, 1e-7)
    start = model.spectrum(a, K)
    b = step(rng, a, 1e-10)
    warm, cold = model.spectrum(b, K, start=start), model.spectrum(b, K)
    assert warm.solver == "warm"
    assert relative_difference(warm, cold) <= 1e-13
    check_eigenpairs(model, b, warm, 1e-7)
    jw, jc = model.jacobian(warm), model.jacobian(cold)
    for l in range(7):
        rows = slice(l * l, (l + 1) ** 2)
        np.testing.assert_allclose(jw[rows].sum(axis=0), jc[rows].sum(axis=0), rtol=0,
                                   atol=1e-9 * np.abs(jc).max())  # ~ the vectors' residual (step 1e-10)


def test_a_multiplet_cut_by_k_falls_back(model):
    # the round sphere with k = 50 cuts the 13 functions of degree 6: no gap between wanted and unwanted
    a = np.zeros(model.nparams)
    a[0] = np.sqrt(4 * np.pi)
    start = model.spectrum(a, 50)
    assert model.spectrum(a, 50, start=start).solver != "warm"
    assert model.spectrum(a, K, start=model.spectrum(a, K)).solver == "warm"


def test_other_starts_are_ignored_or_refused(model, rng):
    a = random_factor_coefficients(rng, 6, amplitude=0.3)
    assert model.spectrum(a, K, start=model.spectrum(a, K + 1)).solver != "warm"  # another k
    assert model.spectrum(a, K, start=HarmonicModel(11, 6).spectrum(a, K)).solver != "warm"  # another basis
    with pytest.raises(InvalidArgumentError, match="start"):
        model.spectrum(a, K, start=np.ones(3))


def test_the_objective_warm_starts_from_its_last_evaluation(rng):
    calls = []

    class Spy(HarmonicModel):
        def spectrum(self, params, k, *, start=None):
            spec = super().spectrum(params, k, start=start)
            calls.append((start, spec.solver))
            return spec

    model = Spy(12, 6)
    a = random_factor_coefficients(rng, 6, amplitude=0.3)
    target = model.spectrum(step(rng, a, 1e-3), K).eigenvalues
    calls.clear()
    par = Parametrization.at(a, model.free_parameters(fit_area=False))
    objective = Objective(model, target, eigenvalue_weights(target), par)
    x = par.initial()
    first = objective.evaluate(x, jacobian=True)
    again = objective.evaluate(x, jacobian=True)
    assert calls[0][0] is None and calls[1][1] == "warm"
    np.testing.assert_allclose(again.residuals, first.residuals, rtol=0, atol=1e-13)  # relative eigenvalue errors
    np.testing.assert_allclose(again.jacobian, first.jacobian, rtol=0, atol=1e-11 * np.abs(first.jacobian).max())


def test_a_solve_without_guard_vectors_is_the_same_and_never_a_warm_start(model, rng):
    a = random_factor_coefficients(rng, 6, amplitude=0.3)
    with_guards = model.spectrum(a, K)
    alone = model.spectrum(a, K, guards=False)
    assert with_guards.reduced_vectors.shape[1] > K - 1 == alone.reduced_vectors.shape[1]
    np.testing.assert_allclose(alone.eigenvalues, with_guards.eigenvalues, rtol=1e-13, atol=1e-13)
    check_eigenpairs(model, a, alone, 1e-12)
    assert model.spectrum(a, K, start=alone).solver != "warm"  # its vectors leave no room to certify the gap
