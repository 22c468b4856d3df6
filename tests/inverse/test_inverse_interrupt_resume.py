"""An interrupted fit (Ctrl-C, SIGTERM) resumes to the uninterrupted one, history and iteration counts included
(issue 50 item 4): the checkpoint written on the interrupt holds the start's last resume point, not a state inside
the hops whose rows the resume then recorded twice."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from shspec import HarmonicModel
from shspec.inverse import FitOptions, Stage, fit
from shspec.fitting.targets import blob_factor, harmonic_target


def _cold(monkeypatch):
    # a resumed optimizer solves its first point cold where the uninterrupted one had warm-started the solve, equal
    # to ~1e-15 (shspec.inverse.optimize), which a stalling LM may tell apart; cold solves make the two comparable
    # bit for bit, which is what these tests are about
    monkeypatch.setattr(HarmonicModel, "_warm_usable", lambda *args: False)


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """Two starts of a degree-3 fit of the degree-6 blob, which cannot reach a zero residual: both run the hops of
    their first stage and those after the last, and are interrupted in each; and the uninterrupted fit."""
    target = harmonic_target(blob_factor(), lmax=8, numeig=20)
    opts = FitOptions(starts=2, seed=1, max_iter=30, schedule=(Stage(2, max_iter=30, hops=True), Stage(3)),
                      basin_hops=2, hop_tries=6, stop_at_success=False, stage_basis_tol=None, search_basis_tol=None,
                      checkpoint_every=3, checkpoint_path=str(tmp_path_factory.mktemp("whole") / "ck.h5"))
    model = HarmonicModel(8, 3)
    with pytest.MonkeyPatch.context() as monkeypatch:
        _cold(monkeypatch)
        return target, model, opts, fit(target, model, opts)


def _same(a, b):
    for x, y in zip(a.starts, b.starts, strict=True):
        assert (x.iterations, x.status, x.work) == (y.iterations, y.status, y.work)
        np.testing.assert_array_equal(x.history, y.history)
        np.testing.assert_array_equal(x.params, y.params)


@pytest.mark.slow
@pytest.mark.parametrize("at", [10, 45, 81, 87])  # in a stage, its hops and the final hops
def test_a_fit_interrupted_anywhere_resumes_to_the_uninterrupted_one(case, tmp_path, monkeypatch, interrupt_fit, at):
    target, model, opts, whole = case
    _cold(monkeypatch)
    opts = dataclasses.replace(opts, checkpoint_path=str(tmp_path / "ck.h5"))
    restore = interrupt_fit(at)  # what Ctrl-C or SIGTERM (as the CLI turns it) raises
    assert fit(target, model, opts).interrupted
    restore()
    _same(fit(target, model, opts, resume=True), whole)
