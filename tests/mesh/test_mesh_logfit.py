"""Log-factor mesh fits: the Dirichlet regularizer's square root, the study's cost (cotan-squared penalty), the
gradient of the log-parametrized energy, the exactly representable ("cmcf") target, and a factor field spanning 1e4
recovered from its own spectrum."""

from __future__ import annotations

import numpy as np
import pytest

from shspec.errors import InvalidArgumentError
from shspec.inverse import FitOptions, fit
from shspec.inverse.identifiability import determined_directions
from shspec.inverse.energy import Objective, eigenvalue_weights
from shspec.inverse.parametrization import Parametrization
from shspec.mesh.cmcf import cmcf
from shspec.mesh.cotan import cotan_stiffness
from shspec.mesh.model import MeshModel, dirichlet_root
from shspec.mesh.shapes import blob, icosphere
from shspec.sphere.evaluate import sample_harmonic
from shspec.sphere.random import random_coefficients
from shspec.fitting.targets import Target, mesh_target


def test_dirichlet_root_squares_to_the_cotan_form():
    # An irregular mesh (the blob surface, obtuse angles included): the square root holds on any mesh.
    mesh = blob(2)
    G = dirichlet_root(mesh)
    L = cotan_stiffness(mesh)
    u = np.random.default_rng(0).standard_normal(mesh.nvertices)
    np.testing.assert_allclose(np.sum((G @ u) ** 2), u @ (L @ u), rtol=1e-12)
    np.testing.assert_allclose((G.T @ G).toarray(), L.toarray(), atol=1e-12)
    # a linear function x on the unit icosphere's faces: ∫|∇x|² = Σ_f A_f |P_f e_x|², P_f the projector on face f
    sphere = icosphere(2)
    p = sphere.vertices[sphere.faces]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    n /= np.linalg.norm(n, axis=1)[:, None]
    exact = np.sum(area * (1.0 - n[:, 0] ** 2))
    np.testing.assert_allclose(np.sum((dirichlet_root(sphere) @ sphere.vertices[:, 0]) ** 2), exact, rtol=1e-12)


def test_regularizer_kinds_give_their_forms():
    model = MeshModel(blob(1), transform="exp", reg_kind="dirichlet")
    u = np.random.default_rng(1).standard_normal(model.nparams)
    D = model.regularizer(0.3)
    np.testing.assert_allclose(0.5 * np.sum((D @ u) ** 2), 0.3 * (u @ (model.stiffness @ u)) / 2, rtol=1e-12)
    bil = MeshModel(blob(1)).regularizer(0.3)
    np.testing.assert_allclose(0.5 * np.sum((bil @ u) ** 2), MeshModel(blob(1)).bilaplacian_penalty(u, 0.3)[0],
                               rtol=1e-12)
    assert model.regularizer(0.0) is None
    with pytest.raises(Exception, match="reg_kind"):
        MeshModel(blob(1), reg_kind="tv")


def test_cotan_squared_energy_is_the_studys_eigencost():
    # eigencost.m of levincoolxyz/invspec, written out independently with a dense solve: its mass is
    # diag(1/exp(s_study))·M, so s_study = −log c; J = ½ Σ_{i≥1} ((λ_i − λ*_i)/λ*_i)² + reg·s_studyᵀ L² s_study / 2
    sphere = icosphere(1)
    n = sphere.nvertices
    model = MeshModel(sphere, transform="exp", reg_kind="cotan-squared")
    rng = np.random.default_rng(5)
    target = model.spectrum(np.exp(0.6 * rng.standard_normal(n)), 20).eigenvalues
    target[0] = 0.0
    s = 0.5 * rng.standard_normal(n)
    reg = 0.05
    L = cotan_stiffness(sphere).toarray()
    m = model.vertex_areas
    lam = np.linalg.eigvalsh((L / np.sqrt(m * np.exp(s))[:, None]) / np.sqrt(m * np.exp(s))[None, :])[:20]
    s_study = -s
    study = 0.5 * np.sum(((lam[1:] - target[1:]) / target[1:]) ** 2) + reg * s_study @ (L @ (L @ s_study)) / 2
    obj = Objective(model, target, eigenvalue_weights(target), Parametrization.at(np.exp(s), np.arange(n), "exp"),
                    reg)
    ev = obj.evaluate(obj.initial(), jacobian=True)
    np.testing.assert_allclose(ev.energy, study, rtol=1e-10)
    # and the penalty alone is the squared norm of L s, R/2 ‖Ls‖², with its gradient by finite differences
    D = model.regularizer(reg)
    np.testing.assert_allclose(0.5 * np.sum((D @ s) ** 2), reg / 2 * np.sum((L @ s) ** 2), rtol=1e-12)
    h = 1e-5
    x = obj.initial()
    for j in (0, 17, n - 1):
        e = np.zeros(x.size)
        e[j] = h
        fd = (obj.evaluate(x + e).energy - obj.evaluate(x - e).energy) / (2 * h)
        np.testing.assert_allclose(ev.gradient[j], fd, rtol=1e-6, atol=1e-10)


def test_log_energy_gradient_with_dirichlet_matches_finite_differences():
    sphere = icosphere(1)
    model = MeshModel(sphere, transform="exp", reg_kind="dirichlet")
    rng = np.random.default_rng(2)
    truth = np.exp(0.5 * rng.standard_normal(sphere.nvertices))
    target = model.spectrum(truth, 12).eigenvalues
    target[0] = 0.0
    start = np.exp(0.4 * rng.standard_normal(sphere.nvertices))
    obj = Objective(model, target, eigenvalue_weights(target), Parametrization.at(start, np.arange(42), "exp"), 0.07)
    x = obj.initial()
    ev = obj.evaluate(x, jacobian=True)
    np.testing.assert_allclose(ev.jacobian.T @ ev.residuals, ev.gradient, rtol=1e-10, atol=1e-14)
    h = 1e-5
    for j in (0, 13, 41):
        e = np.zeros(x.size)
        e[j] = h
        fd = (obj.evaluate(x + e).energy - obj.evaluate(x - e).energy) / (2 * h)
        np.testing.assert_allclose(ev.gradient[j], fd, rtol=1e-6, atol=1e-10)


def test_cmcf_target_is_the_sphere_carrying_the_cmcf_factors():
    t = mesh_target(blob(1), 8, 10, 3, source="cmcf")
    lam = MeshModel(t.sphere).spectrum(t.factors, 10).eigenvalues
    np.testing.assert_allclose(t.eigenvalues[1:], lam[1:], rtol=1e-12)
    assert t.source == "cmcf" and t.eigenvalues[0] == 0.0
    pl = mesh_target(blob(1), 8, 10, 3, source="pl")
    assert np.max(np.abs(pl.eigenvalues[1:] / t.eigenvalues[1:] - 1)) > 1e-4  # a different spectrum


def test_mesh_target_takes_the_meshs_own_flow_and_refuses_another():
    mesh = blob(1)
    flow = cmcf(mesh)
    given = mesh_target(mesh, 8, 10, 3, source="cmcf", flow=flow)
    assert given.sphere is flow.sphere and given.factors is flow.factors
    np.testing.assert_array_equal(given.eigenvalues, mesh_target(mesh, 8, 10, 3, source="cmcf").eigenvalues)
    with pytest.raises(InvalidArgumentError, match="faces differ"):
        mesh_target(mesh, 8, 10, 3, flow=cmcf(blob(2)))
    with pytest.raises(InvalidArgumentError, match="CMCFResult"):
        mesh_target(mesh, 8, 10, 3, flow=flow.sphere)


def test_factors_spanning_1e4_recovered_from_their_own_spectrum():
    # Target (b) on a synthetic case: a generic smooth log field of range log(1e4) on a 42-vertex sphere and its 41
    # lowest eigenvalues (40 equations for 42 unknowns: two directions stay free, so the error is measured over the
    # directions the eigenvalues determine).  LM in s = log c from a start 0.3 % (RMS in s) off.
    sphere = icosphere(1)
    n = sphere.nvertices
    field = sample_harmonic(random_coefficients(np.random.default_rng(5), 3, 1.0), sphere.vertices)
    s_true = (field - field.min()) / np.ptp(field) * np.log(1e4)
    truth = np.exp(s_true)
    model = MeshModel(sphere, transform="exp")
    lam = model.spectrum(truth, n - 1).eigenvalues
    lam[0] = 0.0
    target = Target("synthetic", lam, area=float(truth @ model.vertex_areas))
    start = s_true + 0.003 * np.random.default_rng(3).standard_normal(n)
    # Levenberg–Marquardt: the quadratic final convergence of a zero-residual problem (the mesh default is L-BFGS)
    result = fit(target, model, FitOptions(optimizer="lm", starts=1, schedule=(), max_iter=60, basin_hops=0),
                 init=np.exp(start))
    B = determined_directions(model, truth, n - 1)
    assert B.shape == (n, n - 2)
    err = np.linalg.norm(B.T @ (np.log(result.best.params) - s_true)) / np.sqrt(n)
    assert result.best.relative_residual < 1e-10
    assert err < 1e-3 and err < 0.1 * np.linalg.norm(B.T @ (start - s_true)) / np.sqrt(n)


def test_log_step_beyond_double_precision_is_a_rejected_point():
    from shspec.errors import NotPositiveError

    par = Parametrization.at(np.ones(3), np.arange(3), "exp")
    with pytest.raises(NotPositiveError, match="overflows"):
        par.params(np.array([0.0, 800.0, 0.0]))


@pytest.mark.slow
def test_cli_fits_log_factors_with_auto_numeig_and_adaptive(tmp_path):
    import json

    from shspec.cli import main

    out = tmp_path / "auto"
    assert main(["fit", "--target", "star:3,3,0.5", "--subdivisions", "1", "--model", "mesh", "--numeig", "auto",
                 "--numeig-tol", "0.05", "--reg", "0.01", "--starts", "1", "--max-iter", "3", "--quiet",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    auto = summary["numeig_auto"]
    assert summary["numeig"] == auto["chosen"] < auto["of"] and auto["largest_kept_error"] <= 0.05
    assert auto["first_dropped_error"] > 0.05
    assert "exp reg=cotan-squared" in summary["model"] and summary["aligned"] is False
    c = np.loadtxt(out / "factors.txt")
    assert c.shape == (42,) and c.min() == pytest.approx(summary["fitted_range"][0])
    out2 = tmp_path / "adaptive"
    assert main(["fit", "--target", "star:3,3,0.5", "--subdivisions", "2", "--model", "mesh", "--numeig", "20",
                 "--adaptive", "--adaptive-start", "1", "--adaptive-growth", "2", "--reg", "0.01", "--starts", "1", "--max-iter", "3",
                 "--quiet", "--out", str(out2)]) == 0
    summary = json.loads((out2 / "summary.json").read_text())
    assert summary["adaptive"]["sizes"] == [42, 84, 162] and summary["aligned"] is True
    assert np.loadtxt(out2 / "factors.txt").shape == (162,)
    out3 = tmp_path / "all"
    assert main(["fit", "--target", "star:3,3,0.5", "--subdivisions", "1", "--model", "mesh", "--numeig", "all",
                 "--starts", "1", "--max-iter", "2", "--quiet", "--out", str(out3)]) == 0
    assert json.loads((out3 / "summary.json").read_text())["numeig"] == 41
