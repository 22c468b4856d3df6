"""A checkpoint stays resumable when its computed target moved by round-off (issue 34 item 2)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from shspec import HarmonicModel
from shspec.errors import CheckpointError
from shspec.inverse import FitOptions, Stage, blob_factor, fit, harmonic_target
from shspec.inverse import optimize as optimize_module


def _interrupted(tmp_path, monkeypatch):
    target, model = harmonic_target(blob_factor(), 8, 20), HarmonicModel(8, 6)
    opts = FitOptions(starts=1, seed=3, max_iter=4, schedule=(Stage(4), Stage(6)), basin_hops=0,
                      checkpoint_every=2, checkpoint_path=str(tmp_path / "ck.h5"))
    cls = optimize_module._CLASSES["lm"]
    original, calls = cls.step, {"n": 0}

    def step(self):
        calls["n"] += 1
        if calls["n"] == 5:
            raise KeyboardInterrupt
        original(self)

    monkeypatch.setattr(cls, "step", step)
    assert fit(target, model, opts).interrupted
    monkeypatch.setattr(cls, "step", original)
    return target, model, opts


def test_a_target_moved_by_ulps_still_resumes(tmp_path, monkeypatch):
    # the blob target is computed: a rebuilt cache table used to move it by a few ulps, and the hash of its bytes
    # in the fingerprint then called the checkpoint "of another fit"
    target, model, opts = _interrupted(tmp_path, monkeypatch)
    moved = dataclasses.replace(target, eigenvalues=np.nextafter(target.eigenvalues, np.inf))
    resumed = fit(moved, model, opts, resume=True)
    assert not resumed.interrupted and len(resumed.starts) == 1
    # it goes on with the checkpoint's target, and ends where the uninterrupted fit ends
    assert np.array_equal(resumed.target.eigenvalues, target.eigenvalues)
    whole = fit(target, model, dataclasses.replace(opts, checkpoint_path=str(tmp_path / "whole.h5")))
    assert np.array_equal(resumed.best.params, whole.best.params) and resumed.best.energy == whole.best.energy


def test_another_target_is_still_refused(tmp_path, monkeypatch):
    target, model, opts = _interrupted(tmp_path, monkeypatch)
    other = dataclasses.replace(target, eigenvalues=target.eigenvalues * (1 + 1e-9))
    with pytest.raises(CheckpointError, match="another target spectrum"):
        fit(other, model, opts, resume=True)
    fewer = dataclasses.replace(target, eigenvalues=target.eigenvalues[:-1])
    with pytest.raises(CheckpointError, match="another fit"):
        fit(fewer, model, opts, resume=True)
