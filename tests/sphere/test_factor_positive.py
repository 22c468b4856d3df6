"""The positivity check of a conformal factor is a certified bound, not a sample of grid nodes."""

import numpy as np
import pytest

from shspec.errors import NotPositiveError
from shspec.sphere.factor import ConformalFactor, derivative_bounds
from shspec.sphere.grid import evaluate_on_grid, glq_grid


def _tilted(delta, mean=1.3):
    # mean*(1 - (1+delta) cos θ) exactly: degrees 0 and 1 only
    a = np.zeros(4)
    a[0] = mean * np.sqrt(4 * np.pi)
    a[2] = -mean * (1 + delta) * np.sqrt(4 * np.pi / 3)
    return ConformalFactor(a, name="tilted")


def test_negative_between_grid_nodes_is_caught():
    rho = _tilted(1e-4)  # negative only within ~0.8 deg of the north pole, inside the first grid ring
    values, _ = rho.evaluate()
    assert values.min() > 0  # the old check looked only here
    with pytest.raises(NotPositiveError, match="not positive") as err:
        rho.check_positive()
    assert "colatitude 0.0" in str(err.value)
    # found by refining the grid, then polished; with the grid capped, by the search between the nodes
    with pytest.raises(NotPositiveError, match="not positive") as err:
        rho.check_positive(max_grid_lmax=64)
    assert "colatitude 0.0" in str(err.value)


def test_small_positive_minimum_is_accepted_and_bounded_from_below():
    rho = _tilted(-1e-3)  # min = 1.3e-3 at the north pole, exactly
    low = rho.check_positive()
    assert 0 < low.lower_bound <= 1.3e-3 <= low.value + 1e-15


def test_derivative_bounds_hold_and_are_sharp_for_degree_one(rng):
    # |∇ρ| by pyshtools on a fine grid against G; H against second differences along great circles
    from shspec.sphere.harmonics import vector_to_cilm, vector_to_shcoeffs
    import pyshtools

    a = rng.standard_normal(13 ** 2)
    gmax, hmax = derivative_bounds(a)
    grad = vector_to_shcoeffs(a).gradient(lmax=80)
    assert np.sqrt(grad.theta.data ** 2 + grad.phi.data ** 2).max() <= gmax
    cilm = vector_to_cilm(a)
    p = rng.standard_normal((200, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    t = np.cross(p, rng.standard_normal((200, 3)))
    t /= np.linalg.norm(t, axis=1)[:, None]
    h = 1e-3

    def f(x):
        return pyshtools.expand.MakeGridPoint(cilm, np.degrees(np.arcsin(x[:, 2])),
                                              np.degrees(np.arctan2(x[:, 1], x[:, 0])), norm=4, csphase=1)

    second = (f(p * np.cos(h) + t * np.sin(h)) - 2 * f(p) + f(p * np.cos(h) - t * np.sin(h))) / h ** 2
    assert np.abs(second).max() <= hmax
    one = np.zeros(4)
    one[1:] = rng.standard_normal(3)
    # ρ = a_1·Y_1 = sqrt(3/4π) n·x: |∇ρ| and |∇²ρ| = |ρ| both peak at sqrt(3/4π)|a_1|
    g1, h1 = derivative_bounds(one)
    assert g1 == pytest.approx(np.sqrt(3 / (4 * np.pi)) * np.linalg.norm(one), rel=1e-14)
    assert h1 == pytest.approx(g1, rel=1e-14)


@pytest.mark.parametrize("la", [6, 15])
def test_verdict_matches_a_very_fine_grid(rng, la):
    l = np.repeat(np.arange(la + 1), 2 * np.arange(la + 1) + 1)
    fine = glq_grid(600)
    for trial in range(6):
        a = rng.standard_normal(l.size) / (1.0 + l) ** 1.5
        a[0] = 0.0
        low = evaluate_on_grid(a, fine).min()
        # shift the mean so that the minimum is just above or just below zero, by 2 % of the range
        a[0] = (-low + (0.02 if trial % 2 else -0.02) * abs(low)) * np.sqrt(4 * np.pi)
        rho = ConformalFactor(a)
        fine_min = evaluate_on_grid(a, fine).min()
        if fine_min < 0:
            with pytest.raises(NotPositiveError):
                rho.check_positive()
        else:
            found = rho.check_positive()
            # the minimum itself: the fine grid's lowest node polished (a node of another grid can be below it)
            true_min = rho.minimum(600).value
            assert true_min <= fine_min
            assert found.lower_bound <= true_min <= found.value + 1e-12
