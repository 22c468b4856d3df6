"""A target's own error, used everywhere: weights 1/sigma^2, success as residuals consistent with the errors, and an
error bar for rho that contains the error measured against the truth; from a spectrum file's error column or
--noise on the command line."""

import json

import numpy as np
import pytest

from shspec import ConformalFactor, HarmonicModel
from shspec.cli import main
from shspec.errors import InvalidArgumentError
from shspec.inverse import FitOptions, Stage, align, fit
from shspec.inverse.energy import eigenvalue_weights
from shspec.inverse.problem import consistent_with_errors
from shspec.sphere.random import random_centred_coefficients
from shspec.fitting.targets import Target

SIGMA = 1e-6


@pytest.fixture(scope="module")
def noisy():
    truth = ConformalFactor(random_centred_coefficients(5, 4, 0.2))
    model = HarmonicModel(12, 4)
    exact = model.eigenvalues(truth.coefficients, 49)
    noise = np.r_[0.0, np.random.default_rng(7).standard_normal(48)]
    return Target("noisy", exact * (1 + SIGMA * noise), truth=truth, errors=SIGMA * exact), model


def test_errors_are_validated_and_cut_with_the_target(noisy):
    target, _ = noisy
    with pytest.raises(InvalidArgumentError, match="error of eigenvalue 3 is 0"):
        Target("t", target.eigenvalues, errors=np.r_[target.errors[:3], 0.0, target.errors[4:]])
    with pytest.raises(InvalidArgumentError, match="shape of its eigenvalues"):
        Target("t", target.eigenvalues, errors=target.errors[:5])
    cut = target.first(10)
    assert cut.numeig == 10 and np.array_equal(cut.errors, target.errors[:10])
    np.testing.assert_array_equal(eigenvalue_weights(cut.eigenvalues, "relative", cut.errors)[1:],
                                  1 / cut.errors[1:] ** 2)


def test_consistency_with_errors_is_a_chi_square_test():
    lam = np.arange(50.0)
    err = np.r_[0.0, np.full(49, 0.1)]
    assert consistent_with_errors(lam + np.r_[0, np.full(49, 0.1)], lam, err)  # chi^2/nu = 1
    assert not consistent_with_errors(lam + np.r_[0, np.full(49, 0.3)], lam, err)  # chi^2/nu = 9


@pytest.mark.slow
def test_a_noisy_target_succeeds_at_its_noise_and_its_error_bar_holds_the_measured_error(noisy):
    target, model = noisy
    result = fit(target, model, FitOptions(starts=2, seed=0))
    assert result.best.success and 1e-7 < result.best.relative_residual < 1e-4  # at the noise, not below it
    ident = result.identifiability()
    measured = align(result.factor(), target.truth).relative_error
    assert ident.converged and ident.noise_error is not None
    assert ident.noise_error / 3 <= measured <= 3 * ident.noise_error
    assert "error bar" in ident.statement() and ident.to_dict()["error_bar"] == ident.noise_error
    exact_rules = fit(Target("as exact", target.eigenvalues, truth=target.truth), model,
                      FitOptions(starts=1, basin_hops=0, schedule=(Stage(),)), init=result.best.params)
    assert not exact_rules.best.success  # the same spectrum held to 1e-10 cannot succeed: its noise is 1e-6


@pytest.mark.slow
def test_cli_takes_the_error_column_of_a_spectrum_file_or_noise(noisy, tmp_path):
    target, _ = noisy
    with_errors = tmp_path / "with_errors.txt"
    np.savetxt(with_errors, np.c_[np.arange(target.numeig), target.eigenvalues, target.errors])
    plain = tmp_path / "plain.txt"
    np.savetxt(plain, target.eigenvalues)
    common = ["--lmax", "12", "--lmax-factor", "4", "--numeig", "49", "--starts", "1", "--quiet"]
    for spec, extra, out in ((with_errors, [], "a"), (plain, ["--noise", f"{SIGMA}"], "b")):
        assert main(["fit", "--target", f"spectrum:{spec}", *common, *extra, "--out", str(tmp_path / out)]) == 0
        summary = json.loads((tmp_path / out / "summary.json").read_text())
        assert "chi^2" in summary["success_definition"] and summary["successes"] == 1
        assert 0 < summary["identifiability"]["error_bar"] < 1e-2
        # said before the fit, at a random start: the same order as the bar at the solution
        assert summary["identifiability"]["error_bar"] / 10 < summary["expected_error"] < 10 * summary[
            "identifiability"]["error_bar"]


@pytest.mark.slow
def test_a_harmonic_fit_of_a_mesh_spectrum_fits_to_the_mesh_discretization_error(tmp_path, capsys):
    from shspec.mesh.refine import eigenvalue_errors
    from shspec.mesh.shapes import star_surface
    from shspec.fitting.targets import RICHARDSON_FACTOR, mesh_target, with_discretization_errors

    target = with_discretization_errors(mesh_target(star_surface(3, 3, 0.3, 2), 10, 25, 4))
    _, rel = eigenvalue_errors(target.mesh, 25)
    np.testing.assert_allclose(target.errors[1:], RICHARDSON_FACTOR * rel[1:] * target.eigenvalues[1:], rtol=1e-12)
    common = ["--target", "star:3,3,0.3", "--subdivisions", "2", "--lmax", "10", "--lmax-factor", "4",
              "--numeig", "25", "--starts", "1", "--max-iter", "10", "--basin-hops", "0", "--model", "harmonic"]
    assert main(["fit", *common, "--out", str(tmp_path / "harmonic")]) == 0
    assert "estimated discretization error" in capsys.readouterr().err
    summary = json.loads((tmp_path / "harmonic" / "summary.json").read_text())
    assert "chi^2" in summary["success_definition"]
    assert main(["fit", *common, "--model", "mesh", "--quiet", "--out", str(tmp_path / "mesh")]) == 0
    summary = json.loads((tmp_path / "mesh" / "summary.json").read_text())
    assert "chi^2" not in summary["success_definition"]  # the mesh model shares the mesh's discretization
    with pytest.raises(InvalidArgumentError, match="not a mesh's cotan spectrum"):
        with_discretization_errors(Target("t", target.eigenvalues))


@pytest.mark.slow
def test_the_error_bar_of_a_log_rho_fit_is_an_error_of_rho_and_holds_the_measured_error():
    from shspec.galerkin import LogHarmonicModel
    from shspec.sphere.random import random_coefficients

    model = LogHarmonicModel(9, 3)
    u = random_coefficients(np.random.default_rng(3), 3, 0.3 * np.sqrt(4 * np.pi), low=2)
    exact = model.eigenvalues(u, 30)
    sigma = 1e-5
    noise = np.r_[0.0, np.random.default_rng(8).standard_normal(29)]
    target = Target("noisy log", exact * (1 + sigma * noise), truth=model.to_factor(u), errors=sigma * exact)
    result = fit(target, model, FitOptions(starts=1, seed=0))
    assert result.best.success
    ident = result.identifiability()
    measured = align(result.factor(), target.truth).relative_error
    assert ident.noise_error / 3 <= measured <= 3 * ident.noise_error
