"""Checkpoints and result files: integrity (a damaged file is refused by name), order of starts, resumed times."""

from __future__ import annotations

import dataclasses

import h5py
import numpy as np
import pytest

from shspec import HarmonicModel
from shspec.errors import CheckpointError
from shspec.inverse import FitOptions, FitResult, Stage, StartResult, fit, load_result_summary, save_result
from shspec.fitting import blob_factor, harmonic_target


@pytest.fixture(scope="module")
def small():
    return harmonic_target(blob_factor(), 8, 20), HarmonicModel(8, 6)


def _interrupted_checkpoint(small, tmp_path, interrupt_fit, at=11):
    target, model = small
    opts = FitOptions(starts=2, seed=3, max_iter=4, schedule=(Stage(4), Stage(6)), basin_hops=0,
                      checkpoint_every=2, checkpoint_path=str(tmp_path / "ck.h5"))
    restore = interrupt_fit(at)
    partial = fit(target, model, opts)
    restore()
    assert partial.interrupted
    return target, model, opts, partial


def test_a_flipped_byte_in_a_checkpoint_is_refused_by_name(small, tmp_path, interrupt_fit):
    target, model, opts, _ = _interrupted_checkpoint(small, tmp_path, interrupt_fit)
    with h5py.File(opts.checkpoint_path, "r+") as f:
        x = f["current/state/x"]
        x[0] = np.nextafter(x[0], np.inf)  # one ulp: a silently different resumed fit before checksums
    with pytest.raises(CheckpointError, match="ck.h5.*checksum"):
        fit(target, model, opts, resume=True)


def test_a_damaged_checkpoint_is_a_checkpoint_error_not_a_traceback(small, tmp_path, interrupt_fit):
    target, model, opts, _ = _interrupted_checkpoint(small, tmp_path, interrupt_fit)
    with h5py.File(opts.checkpoint_path, "r+") as f:
        del f["current/base"]
        f["current/base"] = np.zeros(3)  # a shortened field
    with pytest.raises(CheckpointError, match="ck.h5"):
        fit(target, model, opts, resume=True)
    with open(opts.checkpoint_path, "r+b") as fh:  # truncated file
        fh.truncate(200)
    with pytest.raises(CheckpointError, match="ck.h5"):
        fit(target, model, opts, resume=True)


def test_resumed_fit_counts_the_time_of_every_process(small, tmp_path, interrupt_fit):
    target, model, opts, partial = _interrupted_checkpoint(small, tmp_path, interrupt_fit)
    done_before = {r.index: r.seconds for r in partial.starts if r.status != "interrupted"}
    assert done_before  # the first start finished in the first process
    resumed = fit(target, model, opts, resume=True)
    assert resumed.seconds == pytest.approx(sum(r.seconds for r in resumed.starts), rel=1e-12)
    for r in resumed.starts:
        if r.index in done_before:
            assert r.seconds == done_before[r.index]  # read back from the checkpoint, not re-timed
    assert resumed.seconds > sum(done_before.values())


def test_result_file_lists_starts_in_index_order_and_checks_itself(small, tmp_path):
    target, model = small
    starts = [StartResult(i, np.full(49, float(i)), float(i), 0.0, 0, 0.0, "x", np.zeros((1, 3)), np.zeros(20))
              for i in range(12)]
    result = FitResult(starts=starts, solutions=[0], target=target, options=FitOptions(), model=model, seconds=0.0)
    path = save_result(tmp_path / "r.h5", result)
    summary = load_result_summary(path)
    assert [s.index for s in summary["starts"]] == list(range(12))  # "10" sorts before "2" as HDF5 names
    assert summary["model"] == model.describe()
    with h5py.File(path, "r+") as f:
        f["solution"][3] += 1.0
    with pytest.raises(CheckpointError, match="r.h5.*checksum"):
        load_result_summary(path)


def test_a_target_moved_by_ulps_still_resumes(small, tmp_path, monkeypatch, interrupt_fit):
    # the blob target is computed: a rebuilt cache table used to move it by a few ulps, and the hash of its bytes
    # in the fingerprint then called the checkpoint "of another fit"
    target, model, opts, _ = _interrupted_checkpoint(small, tmp_path, interrupt_fit)
    moved = dataclasses.replace(target, eigenvalues=np.nextafter(target.eigenvalues, np.inf))
    chosen = []  # the stage and search bases depend on the target's size only: chosen once, not again for its copy
    basis = HarmonicModel.stage_basis
    monkeypatch.setattr(HarmonicModel, "stage_basis", lambda self, *a: chosen.append(a) or basis(self, *a))
    resumed = fit(moved, model, opts, resume=True)
    monkeypatch.setattr(HarmonicModel, "stage_basis", basis)
    assert sorted(chosen) == [(4, 20, opts.stage_basis_tol), (6, 20, opts.search_basis_tol)]
    assert not resumed.interrupted and len(resumed.starts) == opts.starts
    # it goes on with the checkpoint's target, and ends where the uninterrupted fit ends
    assert np.array_equal(resumed.target.eigenvalues, target.eigenvalues)
    whole = fit(target, model, dataclasses.replace(opts, checkpoint_path=str(tmp_path / "whole.h5")))
    for a, b in zip(resumed.starts, whole.starts):
        assert np.array_equal(a.params, b.params) and a.energy == b.energy


def test_another_target_is_still_refused(small, tmp_path, interrupt_fit):
    target, model, opts, _ = _interrupted_checkpoint(small, tmp_path, interrupt_fit)
    other = dataclasses.replace(target, eigenvalues=target.eigenvalues * (1 + 1e-9))
    with pytest.raises(CheckpointError, match="another target spectrum"):
        fit(other, model, opts, resume=True)
    fewer = dataclasses.replace(target, eigenvalues=target.eigenvalues[:-1])
    with pytest.raises(CheckpointError, match="another fit"):
        fit(fewer, model, opts, resume=True)
