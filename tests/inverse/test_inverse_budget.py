"""The start budget: a start without success ends at a fixed amount of work, the same on every run, and the next
start runs; where the default sets one."""

from __future__ import annotations

import numpy as np
import pytest

from shspec import HarmonicModel
from shspec.errors import InvalidArgumentError
from shspec.fitting import harmonic_target
from shspec.inverse import FitOptions, Stage, fit
from shspec.inverse.problem import BUDGET, FitProblem
from shspec.inverse.schedule import DEFAULT_START_BUDGET
from shspec.sphere.random import random_centred_coefficients


@pytest.fixture(scope="module")
def target():
    return harmonic_target(random_centred_coefficients(3, 4, 0.2), 12, 40)


def test_a_start_ends_at_its_budget_and_the_next_one_runs(target):
    model = HarmonicModel(12, 4)
    options = FitOptions(starts=3, start_budget=20, progress=False)
    problem = FitProblem(model, target, options)
    result = fit(target, model, options)
    assert [s.status for s in result.starts] == [BUDGET] * 3 and not any(s.success for s in result.starts)
    for start in result.starts:  # ended at the first iteration that reached the budget
        assert problem.work_budget <= start.work < problem.work_budget + problem.objective(0, start.params).cost * 4
    again = fit(target, model, options)
    for a, b in zip(result.starts, again.starts):
        np.testing.assert_array_equal(a.params, b.params)
        assert a.work == b.work
    free = fit(target, model, FitOptions(starts=1, start_budget=0, progress=False))
    assert free.starts[0].status != BUDGET and free.starts[0].work > result.starts[0].work


def test_the_budget_counts_iterations_of_the_search_stage():
    model = HarmonicModel(20, 4)
    target = harmonic_target(random_centred_coefficients(3, 4, 0.2), 20, 40)
    problem = FitProblem(model, target, FitOptions(start_budget=100, progress=False))
    s = problem.search
    assert problem.stages[s].hops and problem.bases[s] is not None  # the last stage, searched on a smaller basis
    search = model.restrict(problem.level(s), problem.bases[s])
    assert problem.work_budget == 100 * search.solve_cost(target.numeig)


@pytest.mark.parametrize(("la", "options", "init", "budget"), [
    (8, FitOptions(), False, DEFAULT_START_BUDGET),
    (6, FitOptions(), False, None),
    (10, FitOptions(), False, None),
    (8, FitOptions(schedule=(Stage(8, 40), Stage(8))), False, None),
    (8, FitOptions(), True, None),
    (8, FitOptions(start_budget=0), False, None),
    (8, FitOptions(), "noise", None),
])
def test_the_default_budget_is_that_of_the_parity_ramp_only(la, options, init, budget):
    model = HarmonicModel(12, la)
    target = harmonic_target(random_centred_coefficients(3, la, 0.2), 12, 60)
    if init == "noise":  # a target with errors keeps the degree ramp, without a budget
        target, init = target.with_noise(1e-6), False
    start = model.random_start(np.random.default_rng(0), 0.2, target.area_estimate()) if init else None
    problem = FitProblem(model, target, options, init=start)
    if budget is None:
        assert problem.work_budget is None
    else:
        s = problem.search if problem.search is not None else len(problem.stages) - 1
        cost = model.restrict(problem.level(s), problem.bases[s]).solve_cost(target.numeig)
        assert problem.work_budget == budget * cost


@pytest.mark.parametrize("bad", [-1, 1.5, "100"])
def test_a_budget_is_a_count(bad):
    with pytest.raises(InvalidArgumentError, match="start_budget"):
        FitOptions(start_budget=bad)
