"""Starts in parallel and the stop at a success (the race of :mod:`shspec.inverse.race`): the same starts and
numbers as a serial run, whatever order the starts end in, on resume too; every start with
``stop_at_success=False``."""

from __future__ import annotations

import threading
from dataclasses import replace
from concurrent.futures import Executor, Future

import numpy as np
import pytest

from shspec import HarmonicModel
from shspec.inverse import FitOptions, fit
from shspec.fitting import harmonic_target
from shspec.inverse.checkpoint import fingerprint, save_checkpoint
from shspec.inverse.race import ABANDONED, race_outcome
from shspec.sphere.random import random_centred_coefficients


class OrderedExecutor(Executor):
    """Runs its jobs in a thread, once ``count`` were submitted, in the order ``order`` gives their submission
    numbers (e.g. highest first): a start of higher index can end first.  A job cancelled before its turn does not
    run; ``ran`` lists the start indices that did."""

    def __init__(self, count: int, order=reversed):
        self.count, self.order, self.jobs, self.ran = count, order, [], []

    def submit(self, fn, /, *args, **kwargs):
        future = Future()
        self.jobs.append((fn, args, future))
        if len(self.jobs) == self.count:
            threading.Thread(target=self._run, daemon=True).start()
        return future

    def _run(self):
        for fn, args, future in self.order(list(self.jobs)):
            if future.set_running_or_notify_cancel():
                result = fn(*args)
                self.ran.append(result.index)
                future.set_result(result)


@pytest.fixture(scope="module")
def case():
    """A degree-3 ρ from 20 eigenvalues whose starts (seed 5, 10 iterations) fail, succeed, succeed, fail."""
    target = harmonic_target(random_centred_coefficients(2, 3, 0.3), 8, 20)
    model = HarmonicModel(8, 3)
    opts = FitOptions(starts=4, seed=5, max_iter=10, schedule=(), basin_hops=0)
    serial = fit(target, model, opts)
    every = fit(target, model, replace(opts, stop_at_success=False))
    return target, model, opts, serial, every


def _same(a, b):
    assert [r.index for r in a.starts] == [r.index for r in b.starts] and a.solutions == b.solutions
    for x, y in zip(a.starts, b.starts):
        np.testing.assert_array_equal(x.params, y.params)
        np.testing.assert_array_equal(x.history, y.history)
        assert (x.energy, x.success, x.status, x.work) == (y.energy, y.success, y.status, y.work)


def test_a_serial_fit_stops_at_the_race_of_its_first_round_and_all_starts_run_every_one(case):
    target, model, opts, serial, every = case
    assert opts.stop_at_success and opts.race == 2  # the defaults
    assert [r.success for r in every.starts] == [False, True, True, False]  # the case is what it is meant to be
    # start 0 failed after more work than start 1 needed to succeed: on a pool it would have been abandoned at
    # start 1's work, so it is not reported either way
    assert every.starts[0].work > every.starts[1].work > 0
    assert [r.index for r in serial.starts] == [1] and serial.success_count == 1
    _same(serial, replace(every, starts=every.starts[1:2], solutions=[0]))
    # rounds of one start: the first success by index, after every failure before it
    first = fit(target, model, replace(opts, race=1))
    assert [r.index for r in first.starts] == [0, 1]
    for a, b in zip(first.starts, every.starts):
        np.testing.assert_array_equal(a.params, b.params)


def test_the_starts_after_a_success_of_their_round_are_abandoned_at_its_work(case, capsys):
    target, model, opts, serial, every = case
    # one round of four: 0 fails, 1 succeeds, 2 would succeed one iteration later and 3 fail; 2 and 3 run up to
    # 1's work (2 ties it at a higher index) and are abandoned there, one after the other as on a pool
    assert every.starts[1].work < every.starts[2].work < every.starts[3].work
    race = replace(opts, race=4, progress=True)
    here = fit(target, model, race)
    err = capsys.readouterr().err
    for i in (2, 3):
        assert f"start {i} abandoned: start 1 of its round succeeded after work" in err
    assert [r.index for r in here.starts] == [1]
    _same(here, serial)
    pooled = OrderedExecutor(4, order=iter)
    _same(fit(target, model, replace(race, progress=False), executor=pooled), here)
    assert pooled.ran == [0, 1, 2, 3]


def test_the_race_reports_the_failures_that_ended_before_its_winner(case):
    _, _, _, _, every = case
    fail0, win1, win2, fail3 = every.starts
    cheap = replace(fail0, work=win1.work / 2)  # a failure that ended before the success: part of the result
    assert [r.index for r in race_outcome([fail3, win2, win1, cheap], 4)] == [0, 1]
    assert [r.index for r in race_outcome([fail3, win2, win1, fail0], 4)] == [1]
    # a tie in work goes to the lower index; the first round with a success wins whatever its work
    assert [r.index for r in race_outcome([replace(win2, work=win1.work), win1], 4)] == [1]
    assert [r.index for r in race_outcome([replace(win1, work=1e9), fail0, win2, fail3], 2)] == [0, 1]
    # no success: every start, but none abandoned
    abandoned = replace(fail3, status=ABANDONED)
    assert [r.index for r in race_outcome([fail0, abandoned], 2)] == [0]


def test_starts_ending_in_reverse_order_give_the_serial_result(case):
    target, model, opts, serial, every = case
    backwards = OrderedExecutor(4)
    _same(fit(target, model, opts, executor=backwards), serial)
    # 3 and 2 ended before 1 succeeded: run, and left out of the result as the serial run never ran them
    assert backwards.ran == [3, 2, 1, 0]
    everything = OrderedExecutor(4)
    _same(fit(target, model, replace(opts, stop_at_success=False), executor=everything), every)
    assert sorted(everything.ran) == [0, 1, 2, 3]


def test_a_success_that_waits_for_an_earlier_start_says_so(case, capsys):
    target, model, opts, serial, _ = case
    # start 1 succeeds while start 0, of its round, has not run: 0 runs up to 1's work and is abandoned there
    _same(fit(target, model, replace(opts, progress=True), executor=OrderedExecutor(4)), serial)
    err = capsys.readouterr().err
    assert "start(s) 0 of its round go on only while they have done less" in err
    assert "start 0 abandoned: start 1 of its round succeeded after work" in err
    # in rounds of one start, 0 is an earlier round: the fit waits for it, and says why and how to stop waiting
    first = replace(opts, progress=True, race=1)
    _same(fit(target, model, first, executor=OrderedExecutor(4)), fit(target, model, replace(first, progress=False)))
    err = capsys.readouterr().err
    assert "start 1 succeeded; waiting for start(s) 0 of earlier rounds" in err
    assert "Ctrl-C takes start 1's result now" in err


def test_the_pending_starts_after_a_success_are_cancelled(case):
    target, model, opts, serial, _ = case
    forwards = OrderedExecutor(4, order=iter)
    _same(fit(target, model, opts, executor=forwards), serial)
    assert forwards.ran == [0, 1]  # 2 and 3 never ran


def test_a_resumed_fit_that_stops_at_its_first_success_equals_the_uninterrupted_one(case, tmp_path, interrupt_fit):
    target, model, opts, serial, every = case
    # a checkpoint of a parallel run in which starts 0, 2 and 3 ended before 1: only 1 is left, and it succeeds
    path = tmp_path / "ck.h5"
    fp = fingerprint(opts, target, model)
    save_checkpoint(path, fp, [every.starts[i] for i in (0, 2, 3)], None, target)
    checkpointed = replace(opts, checkpoint_path=str(path))
    backwards = OrderedExecutor(1)
    _same(fit(target, model, checkpointed, resume=True, executor=backwards), serial)
    assert backwards.ran == [1]
    # the same checkpoint continued here, one start after the other; and with every start
    _same(fit(target, model, checkpointed, resume=True), serial)
    _same(fit(target, model, replace(checkpointed, stop_at_success=False), resume=True), every)

    # interrupted inside start 1 (its state checkpointed every 2 iterations), resumed on an executor: start 1
    # continues there from its state and the fit ends as the uninterrupted one
    path.unlink()
    inside = replace(checkpointed, checkpoint_every=2)
    restore = interrupt_fit(every.starts[0].iterations + 5)
    partial = fit(target, model, inside)
    restore()
    assert partial.interrupted and [(r.index, r.status) for r in partial.starts][-1] == (1, "interrupted")
    _same(fit(target, model, inside, resume=True, executor=OrderedExecutor(3)), serial)


@pytest.mark.slow
def test_a_process_pool_stops_at_the_first_success_and_its_workers_end(case):
    from shspec.core.parallel import make_executor, stop_executor

    target, model, opts, serial, _ = case
    pool = make_executor(workers=2)
    try:
        pooled = fit(target, model, opts, executor=pool)
        processes = list(pool._processes.values())
    finally:
        stop_executor(pool)
    _same(pooled, serial)
    assert not any(p.is_alive() for p in processes)


def test_a_start_the_race_abandoned_runs_again_on_resume(case, tmp_path):
    target, model, opts, serial, every = case
    # start 1 abandoned in a race of other rounds: its record says nothing about its own round, so it runs again
    path = tmp_path / "ck.h5"
    fp = fingerprint(opts, target, model)
    lost = replace(every.starts[1], status=ABANDONED, success=False, work=every.starts[1].work / 2)
    save_checkpoint(path, fp, [lost, every.starts[2]], None, target)
    _same(fit(target, model, replace(opts, checkpoint_path=str(path)), resume=True), serial)
