"""The fit energy: gradient and Jacobian against finite differences, weights, regularizers, gauge, errors."""

from __future__ import annotations

import numpy as np
import pytest

from shspec import HarmonicModel
from shspec.errors import InvalidArgumentError, NotPositiveError
from shspec.sphere.harmonics import degrees
from shspec.sphere.evaluate import sample_harmonic
from shspec.sphere.random import random_centred_coefficients
from shspec.inverse.energy import Objective, eigenvalue_weights, relative_residual, rms_relative_residual
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


def _assert_derivatives(obj, x, columns, gradient_atol):
    """Gauss–Newton's identity g = Jᵀr at x (the gradient of an evaluation without the Jacobian comes from the
    model's one-pass contraction, with it from the Jacobian), the energy and residuals of the eigenvalues alone
    (:meth:`Objective.values`), and the gradient and the Jacobian's ``columns`` against central differences
    (step 1e-6); returns the evaluation at x."""
    ev = obj.evaluate(x, jacobian=True)
    plain = obj.evaluate(x)
    assert plain.jacobian is None
    np.testing.assert_allclose(ev.jacobian.T @ ev.residuals, plain.gradient, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(ev.gradient, plain.gradient, rtol=1e-9, atol=1e-14)
    values = obj.values(x)
    assert values.gradient is None and values.jacobian is None
    np.testing.assert_allclose(values.residuals, ev.residuals, rtol=1e-10, atol=1e-14)
    assert values.energy == pytest.approx(ev.energy, rel=1e-10)
    assert values.relative_residual == pytest.approx(ev.relative_residual, rel=1e-8, abs=1e-15)
    h = 1e-6
    for j in columns:
        e = np.zeros_like(x)
        e[j] = h
        fd = (obj.evaluate(x + e).energy - obj.evaluate(x - e).energy) / (2 * h)
        assert fd == pytest.approx(ev.gradient[j], rel=1e-5, abs=gradient_atol)
        fd_r = (obj.evaluate(x + e).residuals - obj.evaluate(x - e).residuals) / (2 * h)
        np.testing.assert_allclose(fd_r, ev.jacobian[:, j], rtol=1e-4, atol=1e-9)
    return ev


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
    _assert_derivatives(obj, x, (0, 1, 5, x.size - 1), gradient_atol=1e-10)


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
    # relative errors 0.1 and 0.05 (λ₀ carries none): RMS √((0.01 + 0.0025)/2)
    assert rms_relative_residual([0, 2.2, 3.8], lam) == pytest.approx(np.sqrt(0.00625))
    with pytest.raises(InvalidArgumentError, match="different shapes"):
        rms_relative_residual([0, 2.2], lam)
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
    ev = _assert_derivatives(obj, x, (0, 7, x.size - 1), gradient_atol=1e-12)
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


# -- identifiability ---------------------------------------------------------------------------------------------

def test_identifiability_singular_values_match_a_finite_difference_jacobian():
    from shspec.inverse.identifiability import identifiability

    model = HarmonicModel(10, 3)
    a = random_centred_coefficients(5, 3, 0.2)
    k = 40
    ident = identifiability(model, a, k)
    free = model.free_parameters(False)
    lam = model.spectrum(a, k).eigenvalues
    h = 1e-6
    fd = np.empty((k - 1, free.size))
    for c, j in enumerate(free):
        e = np.zeros_like(a)
        e[j] = h
        fd[:, c] = ((model.spectrum(a + e, k).eigenvalues - model.spectrum(a - e, k).eigenvalues) / (2 * h))[1:]
    fd /= lam[1:, None]
    # the three rotations are the null space: drop the 3 smallest singular values of the full FD Jacobian
    s_fd = np.linalg.svd(fd, compute_uv=False)[:free.size - 3]
    assert ident.symmetries == 3 and ident.directions == free.size - 3 and not ident.underdetermined
    np.testing.assert_allclose(ident.singular_values, s_fd, rtol=1e-5)
    assert ident.condition == pytest.approx(s_fd[0] / s_fd[-1], rel=1e-4)


def test_identifiability_counts_out_only_the_rotations_an_axisymmetric_rho_has():
    from shspec.inverse.identifiability import identifiability

    model = HarmonicModel(10, 4)
    a = np.zeros(25)
    a[0], a[6], a[12], a[20] = np.sqrt(4 * np.pi), 0.3, 0.1, 0.05  # degrees 2, 3, 4 with m = 0
    ident = identifiability(model, a, 60)
    assert ident.symmetries == 2  # the rotation about z leaves it fixed; the other two move it
    generic = a.copy()
    generic[7] = 0.05
    assert identifiability(model, generic, 60).symmetries == 3


def test_identifiability_reports_underdetermined_and_predicts_the_linear_error():
    from shspec.inverse.identifiability import identifiability
    from shspec.sphere.random import random_centred_coefficients

    model = HarmonicModel(10, 4)
    a = random_centred_coefficients(6, 4, 0.2)
    few = identifiability(model, a, 10)  # 9 informative eigenvalues, 21 - 3 directions
    assert few.underdetermined and few.rank <= 9 and few.condition == np.inf
    assert "cannot determine" in few.statement()
    # a small move along a determined direction is what the residual it causes says
    k = 80
    ident = identifiability(model, a, k)
    free = model.free_parameters(False)
    v = np.zeros_like(a)
    v[free] = np.random.default_rng(7).standard_normal(free.size)
    T = model.symmetry_directions(a)
    v -= T @ np.linalg.lstsq(T, v, rcond=None)[0]  # remove the rotations: the spectrum cannot see them
    q = a + 1e-6 * v / np.linalg.norm(v) * np.linalg.norm(a)
    lam_a, lam_q = model.spectrum(a, k).eigenvalues, model.spectrum(q, k).eigenvalues
    r = np.zeros(k)
    r[1:] = (lam_q[1:] - lam_a[1:]) / lam_a[1:]
    est = identifiability(model, a, k, residuals=r).estimated_error
    assert est == pytest.approx(1e-6, rel=1e-3)
    assert ident.noise_gain > 0 and ident.estimated_error is None


@pytest.mark.parametrize("sigma", [1e-6, 1e-4])
def test_noisy_spectra_are_fitted_to_the_error_the_noise_gain_predicts(sigma):
    """Fit a spectrum with relative noise sigma from the truth: the relative error of rho (rotations projected out)
    is noise_gain * sigma within a factor 3 (the gain is the expected RMS over noise draws)."""
    from shspec.inverse import FitOptions, Target, fit
    from shspec.inverse.identifiability import identifiability
    from shspec.sphere.random import random_centred_coefficients

    model = HarmonicModel(12, 3)
    a = random_centred_coefficients(8, 3, 0.2)
    k = 80
    lam = model.spectrum(a, k).eigenvalues
    noisy = lam * (1 + sigma * np.random.default_rng(9).standard_normal(k))
    noisy[0] = 0.0
    target = Target("noisy", np.sort(noisy), area=4 * np.pi)
    result = fit(target, model, FitOptions(starts=1, max_iter=60, residual_tol=1e-15, energy_tol=1e-12, basin_hops=0),
                 init=a)
    delta = result.best.params - a
    T = model.symmetry_directions(a)
    delta -= T @ np.linalg.lstsq(T, delta, rcond=None)[0]
    observed = np.linalg.norm(delta) / np.linalg.norm(a)
    predicted = identifiability(model, a, k).noise_gain * sigma
    assert predicted / 3 < observed < 3 * predicted


def test_identifiability_by_numeig_equals_one_analysis_per_k():
    """Slicing one spectrum's Jacobian for several K gives what separate spectra of K eigenpairs give."""
    from shspec.inverse.identifiability import identifiability, identifiability_by_numeig
    from shspec.sphere.random import random_centred_coefficients

    model = HarmonicModel(10, 4)
    a = random_centred_coefficients(2, 4, 0.2)
    rows = identifiability_by_numeig(model, a, [40, 12, 70])
    assert [r.numeig for r in rows] == [40, 12, 70]
    for row in rows:
        alone = identifiability(model, a, row.numeig)
        assert row.rank == alone.rank and row.underdetermined == alone.underdetermined
        assert row.noise_gain == pytest.approx(alone.noise_gain, rel=1e-8)
    assert rows[1].underdetermined and not rows[2].underdetermined
    with pytest.raises(InvalidArgumentError):
        identifiability_by_numeig(model, a, [])


def test_plan_numeig_recommends_the_smallest_k_within_the_accuracy():
    from shspec.galerkin.truncation import basis_degree_for
    from shspec.fitting.numeig_plan import candidate_numeigs, plan_numeig

    plan = plan_numeig(4, noise=1e-8, accuracy=1e-6)
    ks = [r.numeig for r in plan.rows]
    assert ks == candidate_numeigs(4) and ks[0] == 31 and 36 in ks and ks[-1] == 100
    ok = [r.numeig for r in plan.rows if not r.underdetermined and r.noise_gain * 1e-8 <= 1e-6]
    assert plan.numeig == ok[0]
    # a looser accuracy never asks for more eigenvalues; an impossible one says so
    assert plan_numeig(4, accuracy=1e-3).numeig <= plan.numeig
    impossible = plan_numeig(4, noise=1e-2, accuracy=1e-9, candidates=[30, 40])
    assert impossible.numeig is None and "no K up to 40" in impossible.statement()
    # the floor of the basis scan: the smallest Lb >= La with (Lb + 1)^2 >= 1.5 K
    for k in (36, 100, 576):
        lb = basis_degree_for(k, 4)
        assert (lb + 1) ** 2 >= 1.5 * k and (lb == 4 or lb ** 2 < 1.5 * k)
    assert plan.analysis_lmax == basis_degree_for(ks[-1], 4)
    assert plan.lmax >= basis_degree_for(plan.numeig, 4) and plan.basis_change <= 1e-6
    assert f"Lb = {plan.lmax}" in plan.statement()
    with pytest.raises(InvalidArgumentError):
        plan_numeig(4, np.ones(7))
    with pytest.raises(InvalidArgumentError):
        plan_numeig(4, noise=0.0)


def test_plan_numeig_with_a_floor_on_k_converges_the_basis_for_that_k():
    from shspec.fitting.numeig_plan import converged_basis_degree, plan_numeig

    plain = plan_numeig(4, noise=1e-8, accuracy=1e-6)
    raised = plan_numeig(4, noise=1e-8, accuracy=1e-6, min_numeig=plain.numeig + 30)
    assert (raised.numeig, raised.identified) == (plain.numeig + 30, plain.numeig)
    reference = random_centred_coefficients(0, 4, 0.2)
    assert (raised.lmax, raised.basis_change) == converged_basis_degree(reference, plain.numeig + 30)
    assert raised.lmax > plain.lmax and [r.to_dict() for r in raised.rows] == [r.to_dict() for r in plain.rows]
    # a floor below the identified K changes nothing; one no candidate reaches is not invented either
    assert plan_numeig(4, noise=1e-8, accuracy=1e-6, min_numeig=10).to_dict() == plain.to_dict()
    assert plan_numeig(4, noise=1e-2, accuracy=1e-9, candidates=[30, 40], min_numeig=60).numeig is None
    with pytest.raises(InvalidArgumentError, match="min_numeig"):
        plan_numeig(4, noise=1e-8, accuracy=1e-6, min_numeig=1.5)


def test_converged_basis_degree_against_a_much_larger_basis():
    """The recommended basis really resolves the K eigenvalues (checked at Lb + 6, which the scan never saw), is the
    smallest that does by its own measure, and is far above the (Lb + 1)^2 >= 1.5 K floor for a rough rho: there the
    floor leaves the eigenvalues more than 1e-4 off."""
    from shspec.galerkin.truncation import basis_degree_for
    from shspec.fitting.numeig_plan import converged_basis_degree

    a = random_centred_coefficients(0, 6, 0.2)
    lb, change = converged_basis_degree(a, 64, tol=1e-6)
    reference = HarmonicModel(lb + 6, 6).eigenvalues(a, 64)[1:]

    def error(degree):
        return np.max(np.abs(HarmonicModel(degree, 6).eigenvalues(a, 64)[1:] / reference - 1))

    assert change <= 1e-6 and error(lb) <= 1e-6
    below = np.max(np.abs(HarmonicModel(lb - 2, 6).eigenvalues(a, 64)[1:]
                          / HarmonicModel(lb - 4, 6).eigenvalues(a, 64)[1:] - 1))
    assert below > 1e-6
    floor = basis_degree_for(64, 6)
    assert lb > floor and error(floor) > 1e-4
    with pytest.raises(InvalidArgumentError):
        converged_basis_degree(a, 64, tol=0.0)


def _null_direction(model, p, k, seed):
    """A unit-RMS direction over the free variables in the null space of the relative Jacobian at p."""
    free = model.free_parameters(False)
    spec = model.spectrum(p, k)
    jac = model.jacobian(spec)[1:, free] / spec.eigenvalues[1:, None]
    if model.transform == "exp":
        jac = jac * p[None, free]
    _, s, vt = np.linalg.svd(jac)
    null = vt[int(np.sum(s > 1e-6 * s[0])):]
    v = np.zeros(model.nparams)
    v[free] = null.T @ np.random.default_rng(seed).standard_normal(null.shape[0])
    return v / np.sqrt(np.mean(v[free] ** 2)), vt[:int(np.sum(s > 1e-6 * s[0]))]


def test_isospectral_points_keep_the_spectrum_and_leave_the_truth_to_second_order():
    from shspec.inverse.identifiability import isospectral_point

    sphere = icosphere(1)
    c = np.exp(sample_harmonic(random_centred_coefficients(3, 3, 1.0), sphere.vertices))
    model = MeshModel(sphere, transform="exp")
    k = 25  # 24 informative eigenvalues for 42 factors: an 18-dimensional set shares them
    v, rows = _null_direction(model, c, k, 1)
    lam = model.spectrum(c, k).eigenvalues
    errors = []
    for delta in (0.0025, 0.005):
        point = isospectral_point(model, c, delta * v, k)
        assert point.converged and point.relative_residual <= 1e-12
        np.testing.assert_allclose(model.spectrum(point.params, k).eigenvalues[1:], lam[1:], rtol=1e-11)
        d = np.log(point.params) - np.log(c)
        assert np.sqrt(np.mean(d * d)) == pytest.approx(delta, rel=0.05)  # the return is of second order
        errors.append(np.linalg.norm(rows @ d))
    # the set is curved: the error over the determined directions is of the order δ², not 0 and not δ
    assert 3.5 < errors[1] / errors[0] < 4.5 and errors[0] > 1e-5  # 5.6e-4 and 2.3e-3 measured
    # a step along a determined direction is undone: the walk comes back to c
    point = isospectral_point(model, c, 0.01 * np.sqrt(42) * rows[0], k)
    assert point.converged and np.max(np.abs(np.log(point.params / c))) < 1e-3


def test_isospectral_points_of_a_harmonic_rho_and_bad_directions():
    from shspec.inverse.identifiability import isospectral_point

    model = HarmonicModel(10, 4)
    a = random_centred_coefficients(6, 4, 0.2)
    k = 10  # 9 informative eigenvalues, 21 free coefficients
    v, _ = _null_direction(model, a, k, 2)
    point = isospectral_point(model, a, 0.01 * v, k)
    assert point.converged
    np.testing.assert_allclose(model.spectrum(point.params, k).eigenvalues[1:],
                               model.spectrum(a, k).eigenvalues[1:], rtol=1e-11)
    assert np.linalg.norm(point.params - a) > 0.005  # it moved: another ρ with these ten eigenvalues
    gauge = np.zeros_like(a)
    gauge[1] = 0.1  # a_1m, fixed by the Möbius centring
    with pytest.raises(InvalidArgumentError, match="gauge fixes"):
        isospectral_point(model, a, gauge, k)
    with pytest.raises(InvalidArgumentError, match=r"direction must have shape \(25,\), got shape \(24,\)"):
        isospectral_point(model, a, np.full(24, 0.1), k)
    with pytest.raises(InvalidArgumentError, match="direction must be finite; entry 0 is nan"):
        isospectral_point(model, a, np.full(25, np.nan), k)


@pytest.mark.parametrize("lmax", [10, 12])
def test_a_converged_fit_estimates_the_error_its_basis_leaves(lmax):
    """A spectrum solved on Lb = 20 and fitted on a smaller Lb: the basis's error is the data's error, which the fit
    absorbs into ρ.  At the fit's minimum the residual's part in the range of the Jacobian vanishes, so only the
    residual standard error can show it: the estimate must cover the aligned error, and not by more than 5x."""
    from shspec import ConformalFactor
    from shspec.inverse import FitOptions, Target, align, fit

    truth = random_centred_coefficients(3, 4, 0.2)
    target = Target("fine", HarmonicModel(20, 4).eigenvalues(truth, 36), truth=ConformalFactor(truth))
    result = fit(target, HarmonicModel(lmax, 4), FitOptions(starts=2, search_basis_tol=None, success_tol=1e-4))
    assert result.best.success and result.best.relative_residual > 1e-8  # the basis's error is seen
    measured = align(result.factor(), truth).relative_error
    estimate = result.identifiability().error_estimate
    assert measured <= estimate <= 5 * measured
