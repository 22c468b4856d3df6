"""A resume never changes what a result means (issue 50 item 1): a checkpoint is refused, saying what differs, when
the target's values or errors or area, an option that changes a start, the model or the starting point differ."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from shspec import HarmonicModel
from shspec.errors import CheckpointError
from shspec.inverse import FitOptions, Stage, fit
from shspec.fitting.targets import blob_factor, harmonic_target
from shspec.inverse.checkpoint import _IGNORED

#: A changed, valid value of every option that is part of the fingerprint (a new option must be added here).
_CHANGED = {
    "optimizer": "lbfgs", "weights": "absolute", "reg": 1e-6, "area": "fit", "schedule": (Stage(2, max_iter=3),),
    "stage_basis_tol": 1e-4, "search_basis_tol": 1e-5, "seed": 4, "start_amplitude": 0.1, "max_iter": 5,
    "residual_tol": 1e-12, "step_tol": 1e-14, "energy_tol": 1e-5, "lbfgs_memory": 10, "lm_damping": 1e-2,
    "lm_acceleration": False, "basin_hops": 1, "hop_iter": 10, "hop_extend": 40, "hop_grid": False,
    "hop_tries": 100, "orient_blocks": True, "distinct_tol": 1e-3, "success_tol": 1e-9, "start_budget": 10,
}


@pytest.fixture(scope="module")
def noisy():
    return harmonic_target(blob_factor(), lmax=8, numeig=20).with_noise(1e-3), HarmonicModel(8, 2)


@pytest.fixture
def interrupted(noisy, tmp_path, interrupt_fit):
    """A fit of start 0 stopped at its third iteration, its checkpoint written every iteration."""
    target, model = noisy
    opts = FitOptions(starts=1, seed=3, max_iter=4, schedule=(Stage(2),), basin_hops=0, stage_basis_tol=None,
                      search_basis_tol=None, checkpoint_every=1, checkpoint_path=str(tmp_path / "ck.h5"))
    restore = interrupt_fit(3)
    partial = fit(target, model, opts)
    restore()
    assert partial.interrupted
    return target, model, opts


def test_every_option_of_the_fingerprint_has_a_changed_value_here():
    names = {f.name for f in dataclasses.fields(FitOptions)} - set(_IGNORED)
    assert names == set(_CHANGED)


@pytest.mark.parametrize("name", sorted(_CHANGED))
def test_a_resume_with_another_option_is_refused_and_names_it(interrupted, name):
    target, model, opts = interrupted
    with pytest.raises(CheckpointError, match=f"another fit: option {name} "):
        fit(target, model, dataclasses.replace(opts, **{name: _CHANGED[name]}), resume=True)


def test_a_resume_with_other_target_errors_is_refused(interrupted):
    target, model, opts = interrupted
    with pytest.raises(CheckpointError, match="other target errors"):  # --noise 1e-3, then --resume --noise 0.3
        fit(target.with_noise(0.3), model, opts, resume=True)
    with pytest.raises(CheckpointError, match="target errors 'given' → 'none"):
        fit(dataclasses.replace(target, errors=None), model, opts, resume=True)


def test_a_resume_with_another_area_or_spectrum_is_refused(interrupted):
    target, model, opts = interrupted
    with pytest.raises(CheckpointError, match="another target area"):
        fit(dataclasses.replace(target, area=target.area * 1.01), model, opts, resume=True)
    with pytest.raises(CheckpointError, match="target area 'known' → 'estimated'"):
        fit(dataclasses.replace(target, area=None), model, opts, resume=True)
    with pytest.raises(CheckpointError, match="another target spectrum"):
        fit(dataclasses.replace(target, eigenvalues=target.eigenvalues * 1.001), model, opts, resume=True)
    with pytest.raises(CheckpointError, match="target eigenvalues 20 → 19"):
        fit(target.first(19), model, opts, resume=True)


def test_a_resume_with_another_model_or_starting_point_is_refused(interrupted):
    target, model, opts = interrupted
    with pytest.raises(CheckpointError, match="model 'harmonic Lb=8 La=2' → 'harmonic Lb=8 La=3'"):
        fit(target, HarmonicModel(8, 3), opts, resume=True)
    with pytest.raises(CheckpointError, match="model 'harmonic Lb=8 La=2' → 'harmonic Lb=10 La=2'"):
        fit(target, HarmonicModel(10, 2), opts, resume=True)
    init = model.random_start(np.random.default_rng(1), 0.2, target.area, 2)
    with pytest.raises(CheckpointError, match="starting point 'none' → 'given"):
        fit(target, model, opts, resume=True, init=init)


def test_a_finished_checkpoint_with_other_errors_is_refused_not_returned(noisy, tmp_path):
    target, model = noisy
    opts = FitOptions(starts=1, seed=3, max_iter=2, schedule=(Stage(2),), basin_hops=0, stage_basis_tol=None,
                      search_basis_tol=None, checkpoint_every=1, checkpoint_path=str(tmp_path / "ck.h5"))
    done = fit(target, model, opts)
    assert not done.interrupted
    with pytest.raises(CheckpointError, match="other target errors"):
        fit(target.with_noise(0.3), model, opts, resume=True)
    # the same fit resumed is the finished one
    again = fit(target, model, opts, resume=True)
    np.testing.assert_array_equal(again.best.params, done.best.params)


def test_the_same_fit_resumes_to_the_uninterrupted_result(interrupted, tmp_path):
    target, model, opts = interrupted
    resumed = fit(target, model, opts, resume=True)
    whole = fit(target, model, dataclasses.replace(opts, checkpoint_path=str(tmp_path / "whole.h5")))
    np.testing.assert_array_equal(resumed.best.params, whole.best.params)
    np.testing.assert_array_equal(resumed.best.history, whole.best.history)
