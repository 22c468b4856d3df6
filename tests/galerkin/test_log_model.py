"""rho = exp(u): closed forms (the round and the Möbius-boosted sphere), the mass of the linear model on an
independent expansion, derivatives against finite differences, symmetries, positivity by construction, and a fit
that hears a log-harmonic truth."""

import numpy as np
import pytest

from shspec import ConformalFactor
from shspec.errors import InvalidArgumentError, NotPositiveError
from shspec.galerkin import HarmonicModel, LogHarmonicModel
from shspec.galerkin.model import rotation_generators
from shspec.inverse import FitOptions, align, fit
from shspec.sphere.grid import evaluate_on_grid, expand_grid, glq_grid
from shspec.sphere.random import random_coefficients
from shspec.fitting.targets import Target

L = np.repeat(np.arange(6), 2 * np.arange(6) + 1)
EXACT = L * (L + 1.0)


def _random_u(seed, la, amplitude):
    return random_coefficients(np.random.default_rng(seed), la, amplitude * np.sqrt(4 * np.pi))


def test_constant_log_rho_is_a_round_sphere_of_the_area_it_says():
    model = LogHarmonicModel(10, 4)
    u = np.zeros(model.nparams)
    np.testing.assert_allclose(model.spectrum(u, 36).eigenvalues[1:], EXACT[1:36], rtol=1e-13)
    u[0] = 0.7  # rho = exp(0.7 / sqrt(4 pi)) everywhere: the eigenvalues scale by its inverse
    np.testing.assert_allclose(model.eigenvalues(u, 36)[1:], EXACT[1:36] * np.exp(-0.7 / np.sqrt(4 * np.pi)),
                               rtol=1e-13)
    assert model.area(u) == pytest.approx(4 * np.pi * np.exp(0.7 / np.sqrt(4 * np.pi)), rel=1e-14)


@pytest.mark.parametrize("la, tol", [(12, 2e-10), (16, 1e-13)])
def test_the_log_of_a_boosted_sphere_is_heard_as_the_unit_sphere(la, tol):
    # log rho_k is smooth: degree 16 of it gives the round spectrum to rounding on Lb = 20 (measured 4.1e-14; 1.0e-10
    # at degree 12), where rho itself needs degree 30
    rho = ConformalFactor.mobius_boost(1.5, lmax=40, axis=(1, -1, 2))
    grid = glq_grid(80)
    u = expand_grid(np.log(evaluate_on_grid(rho.coefficients, grid)), grid, la)
    lam = LogHarmonicModel(20, la).spectrum(u, 36).eigenvalues
    np.testing.assert_allclose(lam[1:], EXACT[1:36], rtol=tol)


def test_the_mass_is_that_of_an_independent_expansion_of_exp_u():
    u = _random_u(1, 4, 0.8)
    model = LogHarmonicModel(12, 4)
    fine = glq_grid(70)  # an unrelated, finer grid: the same metric up to aliasing
    a = expand_grid(np.exp(evaluate_on_grid(u, fine)), fine, 24)
    reference = HarmonicModel(12, 24).spectrum(a, 40).eigenvalues
    np.testing.assert_allclose(model.spectrum(u, 40).eigenvalues[1:], reference[1:], rtol=1e-13)


def test_derivatives_match_finite_differences_and_the_contraction():
    model = LogHarmonicModel(10, 4)
    u = _random_u(2, 4, 0.8)
    spec = model.spectrum(u, 30)
    jac = model.jacobian(spec)
    h = 1e-6
    fd = np.stack([(model.eigenvalues(u + h * e, 30) - model.eigenvalues(u - h * e, 30)) / (2 * h)
                   for e in np.eye(model.nparams)], axis=1)
    assert np.max(np.abs(jac - fd)) <= 1e-7 * np.max(np.abs(jac))
    coef = np.random.default_rng(0).standard_normal(30)
    np.testing.assert_allclose(model.contract(spec, coef), jac.T @ coef, rtol=1e-12, atol=1e-12 * np.abs(jac).max())
    # the rotations are invisible to the spectrum: in the Jacobian's null space
    assert np.max(np.abs(jac @ rotation_generators(u))) <= 1e-10 * np.max(np.abs(jac))
    with pytest.raises(InvalidArgumentError, match="spectrum of a solve of this model"):
        model.jacobian(HarmonicModel(10, 4).spectrum(np.eye(1, 25, 0).ravel() * 3.5, 30))


def test_rho_spanning_decades_is_a_metric_and_an_overflow_is_a_rejected_point():
    model = LogHarmonicModel(12, 4)
    u = 6 * _random_u(1, 4, 0.8)
    rho = model.rho_on_grid(u)
    assert rho.max() / rho.min() > 1e4
    lam = model.spectrum(u, 20).eigenvalues
    assert np.all(np.diff(lam) >= 0) and lam[1] > 0  # no positivity check to fail: M is SPD for every u
    with pytest.raises(NotPositiveError, match="beyond double precision"):
        model.spectrum(u * 1000, 20)


def test_a_log_rho_beyond_the_cap_is_a_rejected_point():
    # a Levenberg-Marquardt trial step of a star target's fit (La = 2, Lb = 3): exp is finite (1e36 at most), but
    # ρ spans e^±83; a rejected trial point, not a crash of the fit
    model = LogHarmonicModel(3, 2)
    u = np.array([0.123, 0, 0, 0, 27.646, -0.065, 0.08, -152.613, -0.05])
    assert np.all(np.isfinite(model.rho_on_grid(0.5 * u)))  # log rho 41 at most: evaluated
    assert np.isfinite(model.spectrum(0.5 * u, 6).eigenvalues).all()
    with pytest.raises(NotPositiveError, match="beyond double precision"):
        model.spectrum(u, 6)


@pytest.mark.slow
def test_a_fit_hears_a_log_harmonic_truth():
    model = LogHarmonicModel(10, 3)
    u = _random_u(3, 3, 0.6)
    truth = model.to_factor(u)
    target = Target("log truth", model.eigenvalues(u, 36), truth=truth)
    result = fit(target, model, FitOptions(starts=2, seed=0))
    assert result.success_count >= 1 and result.best.relative_residual < 1e-10
    assert align(result.factor(), truth).relative_error < 1e-8
    assert result.identifiability().error_estimate is not None


@pytest.mark.slow
def test_cli_fits_log_rho(tmp_path):
    import json

    from shspec.cli import main

    model = LogHarmonicModel(8, 2)
    spectrum = tmp_path / "s.txt"
    np.savetxt(spectrum, model.eigenvalues(_random_u(4, 2, 0.5), 16))
    assert main(["fit", "--target", f"spectrum:{spectrum}", "--model", "log", "--lmax", "8", "--lmax-factor", "2",
                 "--numeig", "16", "--starts", "2", "--quiet", "--out", str(tmp_path / "fit")]) == 0
    summary = json.loads((tmp_path / "fit" / "summary.json").read_text())
    assert summary["model"].startswith("log-harmonic Lb=8 La=2") and summary["relative_residual"] < 1e-10
