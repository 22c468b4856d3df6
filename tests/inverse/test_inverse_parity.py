"""Even stages (odd degrees held at 0) and the parity ramp: the schedule's syntax, what an even stage moves, how the
odd degrees are released, and that an even ρ is recovered exactly by even stages alone."""

from __future__ import annotations

import numpy as np
import pytest

from shspec import HarmonicModel, LogHarmonicModel
from shspec.errors import InvalidArgumentError
from shspec.fitting import harmonic_target
from shspec.inverse import FitOptions, Stage, align, default_schedule, fit, parity_ramp, parse_schedule
from shspec.inverse.problem import FitProblem
from shspec.sphere.harmonics import degrees
from shspec.sphere.random import random_centred_coefficients


def test_schedule_text_marks_even_stages():
    stages = parse_schedule("8:36e, 8:64eh, 8:100h, 8")
    assert [(s.numeig, s.even, s.hops) for s in stages] == [(36, True, False), (64, True, True), (100, False, True),
                                                            (None, False, False)]
    for bad in ("8:36x", "8:36he", "e"):
        with pytest.raises(InvalidArgumentError, match="schedule entry"):
            parse_schedule(bad)
    with pytest.raises(InvalidArgumentError, match="Stage.even"):
        Stage(8, 36, even=1)


def test_parity_ramp_fits_the_even_degrees_on_a_ramp_then_every_degree():
    stages = parity_ramp(202, 8)
    assert [(s.lmax_factor, s.numeig, s.even) for s in stages] == [
        (8, 36, True), (8, 64, True), (8, 100, True), (8, 144, True), (8, 196, True), (8, 202, True),
        (8, 202, False)]
    assert not any(s.hops for s in stages) and all(s.max_iter is None for s in stages)


@pytest.mark.parametrize(("la", "even_first"), [(6, False), (8, True), (9, True), (10, False)])
def test_default_schedule_is_the_parity_ramp_at_degrees_8_and_9(la, even_first):
    stages = default_schedule(HarmonicModel(la, la), 150)
    assert stages[0].even is even_first
    assert not stages[-1].even
    # a target with errors (a mesh's, a measured spectrum) keeps the degree ramp: the parity ramp was measured on
    # exact spectra
    assert not default_schedule(HarmonicModel(la, la), 150, exact=False)[0].even


def _odd(la):
    return (degrees(la) % 2 == 1) & (degrees(la) >= 3)


def test_an_even_stage_holds_the_odd_degrees_at_zero_and_recovers_an_even_rho():
    la = 4
    truth = random_centred_coefficients(3, la, 0.2)
    truth[_odd(la)] = 0.0
    target = harmonic_target(truth, 16, 60)
    result = fit(target, HarmonicModel(16, la), FitOptions(starts=2, schedule=parse_schedule("4:36e,4e"),
                                                           progress=False, stop_at_success=False))
    for start in result.starts:  # random starts have odd degrees; the even stages zero them and never move them
        assert np.all(start.params[_odd(la)] == 0.0)
    assert result.best.relative_residual <= 1e-10
    assert align(result.factor(), truth).relative_error <= 1e-8


@pytest.mark.parametrize("model", [HarmonicModel(10, 4), LogHarmonicModel(10, 4)], ids=["harmonic", "log"])
def test_the_stage_after_an_even_one_perturbs_the_odd_degrees_only(model):
    target = harmonic_target(random_centred_coefficients(3, 4, 0.2), 10, 30)
    problem = FitProblem(model, target, FitOptions(schedule=parse_schedule("4:25e,4:30"), progress=False))
    even = model.random_start(np.random.default_rng(0), 0.2, target.area_estimate(), 4)
    even[_odd(4)] = 0.0
    after = problem.enter_stage(1, even, np.random.default_rng(1))
    assert np.all(after[_odd(4)] != 0.0) and np.all(np.abs(after[_odd(4)]) < 0.05)
    np.testing.assert_array_equal(after[~_odd(4)], even[~_odd(4)])
    again = problem.enter_stage(1, even, np.random.default_rng(1))
    np.testing.assert_array_equal(after, again)  # seeded: a resumed start repeats it
    # a stage after a stage that was not even changes nothing of the kind
    plain = FitProblem(model, target, FitOptions(schedule=parse_schedule("4:25,4:30"), progress=False))
    np.testing.assert_array_equal(plain.enter_stage(1, even, np.random.default_rng(1)), even)


def test_hops_of_an_even_stage_skip_the_moves_of_odd_blocks_only():
    model = HarmonicModel(10, 4)
    target = harmonic_target(random_centred_coefficients(3, 4, 0.2), 10, 30)
    problem = FitProblem(model, target, FitOptions(schedule=parse_schedule("4:25e,4:30"), progress=False))
    params = random_centred_coefficients(5, 4, 0.2)
    params[_odd(4)] = 0.0
    moves = model.escape_moves(params, 4)
    kept = problem.stage_moves(0, params, moves)
    assert 0 < len(kept) < len(moves)
    changed = lambda q: set(degrees(4)[q != params])  # noqa: E731
    assert all(changed(q) & {2, 4} for q in kept)
    assert problem.stage_moves(1, params, moves) == moves


def test_an_even_stage_needs_a_model_with_parity():
    from shspec.mesh.model import MeshModel
    from shspec.mesh.shapes import icosphere

    target = harmonic_target(random_centred_coefficients(3, 4, 0.2), 10, 30)
    with pytest.raises(InvalidArgumentError, match="no parity"):
        FitProblem(MeshModel(icosphere(1)), target, FitOptions(schedule=(Stage(numeig=20, even=True),)))
