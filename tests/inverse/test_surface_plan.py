"""Hearing a mesh's surface: the error metric of log rho, the refined target and its Richardson error, and the plan of
a log-rho fit (floor against noise) with its diagnosis where the harmonic basis cannot go."""

import dataclasses
import json

import numpy as np
import pytest

from shspec.cli import main
from shspec.errors import InvalidArgumentError
from shspec.galerkin import LogHarmonicModel
from shspec.galerkin.truncation import basis_degree_for
from shspec.fitting.surface_plan import log_floor, plan_surface_fit
from shspec.mesh.model import MeshModel
from shspec.mesh.refine import refined_eigenvalues, subdivision_eigenvalues
from shspec.mesh.shapes import icosphere, star_surface
from shspec.sphere.grid import evaluate_on_grid, glq_grid
from shspec.sphere.random import random_coefficients
from shspec.fitting.targets import MeshTarget, Target, mesh_target, refined_target, refinement_levels, subdivision_changes


def test_the_log_models_error_metric_is_the_relative_l2_change_of_rho():
    model = LogHarmonicModel(12, 6)
    rng = np.random.default_rng(1)
    u = random_coefficients(rng, 6, 0.6)
    u[0] = 1.0
    du = 1e-6 * rng.standard_normal(u.size)
    grid = glq_grid(60)  # an independent quadrature, exact for the squares of both to rounding
    a, b = np.exp(evaluate_on_grid(u, grid)), np.exp(evaluate_on_grid(u + du, grid))
    expected = np.sqrt(np.sum(grid.weights * (b - a) ** 2) / np.sum(grid.weights * a ** 2))
    assert np.linalg.norm(model.error_root(u) @ du) == pytest.approx(expected, rel=1e-5)
    # the default metric I/|p| is not it: u_00 carries the area, so |du|/|u| depends on the scale
    assert abs(np.linalg.norm(du) / np.linalg.norm(u) / expected - 1) > 0.1


def test_the_refined_target_is_a_subdivisions_spectrum_or_its_richardson_extrapolation_with_honest_errors():
    target = mesh_target(star_surface(3, 3, 0.3, 2), 10, 20, 4)  # 162 vertices: two subdivisions by default
    assert refinement_levels(target.mesh.nvertices) == 2 and refinement_levels(20_000) == 1
    s = refined_eigenvalues(target.mesh, 20, 3)  # the mesh and three subdivisions (10242 vertices)
    coarse, fine = subdivision_eigenvalues(target.mesh, 20)
    np.testing.assert_array_equal(s[:2], [coarse, fine])
    one = refined_target(target, fine)
    np.testing.assert_allclose(one.eigenvalues, fine, rtol=1e-12)
    np.testing.assert_allclose(one.errors[1:], np.abs(coarse[1:] - fine[1:]) / 3, rtol=1e-9)
    np.testing.assert_allclose(subdivision_changes(target)[1:], np.abs(coarse[1:] - fine[1:]) / coarse[1:], rtol=1e-9)
    # second order: one more subdivision moves lambda' by about the Richardson error, far less than it moved lambda
    moved = np.abs(s[2, 1:] - fine[1:])
    assert np.all(moved <= 1.5 * one.errors[1:])
    assert np.median(moved / np.abs(coarse[1:] - fine[1:])) < 0.4
    two = refined_target(target)
    r = [np.sort((4 * s[j + 1] - s[j]) / 3) for j in range(3)]
    np.testing.assert_allclose(two.eigenvalues, r[1], rtol=1e-12)
    change = np.abs(r[1] - r[0])
    window = [change[max(i - 3, 0):i + 4].max() for i in range(20)]  # its own and three neighbours' on each side
    np.testing.assert_allclose(two.errors[1:], window[1:], rtol=1e-9)
    # the extrapolation's change bounds its error, measured against the next extrapolation (a third subdivision);
    # and it is tens of times below the error of lambda'
    assert np.all(np.abs(r[2] - r[1])[1:] <= two.errors[1:])
    assert np.median(two.errors[1:] / one.errors[1:]) < 0.1
    with pytest.raises(InvalidArgumentError, match="not a mesh's cotan spectrum"):
        refined_target(Target("t", target.eigenvalues))
    with pytest.raises(InvalidArgumentError, match="1 or 2 levels"):
        refined_target(target, s[1:])


def _planned_target(mesh, numeig):
    return refined_target(mesh_target(mesh, 20, numeig, 12, source="pl"))


@pytest.mark.slow
def test_the_plan_balances_the_floor_of_the_basis_against_the_targets_errors():
    target = _planned_target(star_surface(3, 3, 0.3, 3), 160)
    plan = plan_surface_fit(target, accuracy=0.05)
    floors = {r.lmax_factor: r.floor for r in plan.rows}
    las = sorted(floors)
    assert all(floors[a] >= floors[b] for a, b in zip(las, las[1:]))  # nested least squares
    for la in (2, las[-1]):
        assert floors[la] == pytest.approx(log_floor(target.sphere, target.factors, la)[1], rel=1e-12)
    chosen = next(r for r in plan.rows if (r.lmax_factor, r.numeig) == (plan.lmax_factor, plan.numeig))
    assert plan.noise == chosen.noise and plan.floor == chosen.floor
    # each La is searched with 2.5 eigenvalues per coefficient (all of them if fewer); the plan is the fewest
    # coefficients whose prediction with the misfit is within 10 % of that of the lowest error bar without it
    searched = {}
    for r in plan.rows:
        if np.isfinite(r.predicted) and (r.numeig >= 2.5 * (r.lmax_factor + 1) ** 2 or r.numeig == target.numeig):
            searched.setdefault(r.lmax_factor, r)
    assert searched[plan.lmax_factor] == chosen
    first = min(searched.values(), key=lambda r: r.predicted)

    def unpolished(la, k):
        return plan_surface_fit(target, accuracy=0.05, candidates=[la], numeigs=[k], polish=False)

    assert unpolished(first.lmax_factor, first.numeig).predicted == pytest.approx(plan.best_predicted, rel=1e-12)
    assert plan.lmax_factor <= first.lmax_factor
    assert unpolished(plan.lmax_factor, plan.numeig).predicted <= 1.1 * plan.best_predicted
    for la in range(min(searched), plan.lmax_factor):
        assert unpolished(la, searched[la].numeig).predicted > 1.1 * plan.best_predicted
    # against the factors, the fit is held to the target's errors and its reference's own misfit as well; polished
    # against the spectrum, the reference matches it closer than the factors' expansion does
    assert plan.predicted >= chosen.predicted and plan.predicted >= plan.bias > 0
    loose = unpolished(plan.lmax_factor, plan.numeig)
    assert loose.bias is None
    blind = plan_surface_fit(dataclasses.replace(target, truth=None), accuracy=0.05)  # nothing to align the bias with
    assert blind.bias is None and blind.lmax_factor == plan.lmax_factor and blind.predicted <= plan.predicted
    chi2 = [np.sum(((LogHarmonicModel(plan.lmax, plan.lmax_factor).eigenvalues(p.reference, plan.numeig)
                     - target.eigenvalues[:plan.numeig])[1:] / loose.fit_errors[1:]) ** 2) for p in (plan, loose)]
    assert chi2[0] < chi2[1]
    lam = target.eigenvalues[:plan.numeig]
    np.testing.assert_allclose(plan.fit_errors[1:] ** 2 - target.errors[1:plan.numeig] ** 2,
                               (LogHarmonicModel(plan.lmax, plan.lmax_factor).eigenvalues(plan.reference, plan.numeig)
                                - lam)[1:] ** 2, rtol=1e-6, atol=1e-14 * lam[-1] ** 2)
    assert plan.reference_misfit == pytest.approx(np.max(np.sqrt(np.maximum(plan.fit_errors[1:] ** 2 - target.errors[
        1:plan.numeig] ** 2, 0)) / lam[1:]), rel=1e-6)
    # the noise grows with the degree at a fixed K: more unknowns from the same eigenvalues
    noise = [r.noise for r in plan.rows if r.numeig == target.numeig]
    assert noise[-1] > noise[0]
    assert plan.lmax >= basis_degree_for(plan.numeig, plan.lmax_factor)
    record = json.loads(json.dumps(plan.to_dict()))
    assert record["feasible"] == plan.feasible and record["lmax_factor"] == plan.lmax_factor
    assert (plan.diagnosis() is None) == plan.feasible
    # limited by the target's errors, or by the factors' own spectral misfit: each says which
    by_noise = dataclasses.replace(plan, floor=0.01, noise=0.2, predicted=0.3, accuracy=0.05)
    assert by_noise.diagnosis().startswith("the target's errors allow rho to about 0.2 only")
    by_misfit = dataclasses.replace(plan, floor=0.01, noise=0.01, predicted=0.3, accuracy=0.05)
    assert "misses their spectrum" in by_misfit.diagnosis() and "about 0.3 between" in by_misfit.diagnosis()


@pytest.mark.slow
def test_factors_spanning_decades_are_diagnosed_before_fitting(tmp_path, capsys):
    sphere = icosphere(3)
    z = sphere.vertices[:, 2]
    factors = np.exp(9 * z ** 12)  # a narrow cap 8000 times larger than the rest
    spectrum = MeshModel(sphere).spectrum(factors, 60).eigenvalues
    spectrum[0] = 0.0
    target = MeshTarget("cap", spectrum, errors=np.r_[0.0, 1e-3 * spectrum[1:]], sphere=sphere, factors=factors)
    plan = plan_surface_fit(target, accuracy=0.05)
    assert plan.beyond_basis and not plan.feasible
    assert plan.floor > 0.05 and plan.factor_range[1] / plan.factor_range[0] > 1000
    assert "--model mesh" in plan.diagnosis() and "span" in plan.diagnosis()
    assert main(["fit", "--target", "mesh:spot_600", "--out", str(tmp_path / "spot")]) == 1
    err = capsys.readouterr().err
    assert "cannot reach" in err and "--model mesh" in err and not (tmp_path / "spot" / "summary.json").exists()
    with pytest.raises(InvalidArgumentError, match="no errors"):
        plan_surface_fit(MeshTarget("t", spectrum, sphere=sphere, factors=factors))
    with pytest.raises(InvalidArgumentError, match="needs a MeshTarget"):
        plan_surface_fit(Target("t", spectrum, errors=target.errors))


@pytest.mark.slow
def test_a_planned_fit_and_validation_of_a_small_star_mesh_compare_with_its_cmcf_factors(tmp_path, capsys):
    from shspec.mesh.mesh_files import save_mesh

    path = save_mesh(star_surface(3, 3, 0.3, 2), tmp_path / "star.obj")
    assert main(["fit", "--target", f"mesh:{path}", "--starts", "1", "--quiet", "--out", str(tmp_path / "fit")]) == 0
    summary = json.loads((tmp_path / "fit" / "summary.json").read_text())
    plan, surface = summary["surface_plan"], summary["surface"]
    assert summary["model"].startswith("log-harmonic") and summary["numeig"] == plan["numeig"]
    assert summary["expected_error"] == plan["predicted"]
    assert surface["floor"] == pytest.approx(plan["floor"], rel=1e-9)  # the same best expansion, two paths
    assert surface["floor"] <= surface["error_bar"] and 0 < surface["factor_error"] < 1
    assert 0.5 < surface["log_correlation"] <= 1
    assert summary["rho_error"]["value"] == surface["factor_error"]  # measured, beside the bar it is held to
    assert main(["validate", "--target", f"mesh:{path}", "--no-fit", "--out", str(tmp_path / "v")]) == 0
    report = json.loads((tmp_path / "v" / "summary.json").read_text())
    assert report["plan"]["lmax_factor"] == plan["lmax_factor"] and report["status"]["cmcf_harmonic"] == "ok"
    assert "Hearing the shape" in (tmp_path / "v" / "report.md").read_text()


@pytest.mark.slow
def test_a_linear_harmonic_fit_of_spot_ends_with_a_result_whatever_its_positivity(tmp_path):
    """The issue's case: spot_600 through linear rho of degree 4 aborted after its first stage on positivity; now every
    fit ends with its best result written."""
    out = tmp_path / "spot"
    assert main(["fit", "--target", "mesh:spot_600", "--model", "harmonic", "--lmax", "10", "--lmax-factor", "4",
                 "--numeig", "25", "--starts", "1", "--max-iter", "10", "--basin-hops", "0", "--quiet", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["starts"]) == 1 and np.isfinite(summary["energy"])
