"""The race's board and bounds (:mod:`shspec.inverse.race`): what a running start reads, exactly, and when it
must stop."""

from __future__ import annotations

import os

import pytest

from shspec.errors import InvalidArgumentError
from shspec.inverse import race as race_module
from shspec.inverse.race import RaceBoard, RaceBound, RaceLost


@pytest.fixture(autouse=True)
def no_poll_delay(monkeypatch):
    monkeypatch.setattr(race_module, "POLL_SECONDS", 0.0)


def test_a_bound_reads_the_best_success_of_its_round_exactly():
    work = 0.1 + 0.2  # not the decimal it prints as: the board must carry it to the bit
    with RaceBoard() as board:
        first, second, third = (RaceBound(i, None, board.path(0)) for i in (0, 2, 3))
        first.check(1e12)  # nothing posted: no bound
        board.post(0, work, 2)
        first.check(work)  # a tie goes to the lower index
        with pytest.raises(RaceLost, match="start 2 of its round succeeded after work 0.3"):
            first.check(work + 1e-16)
        second.check(work)  # the winner itself is not beaten by its own post
        with pytest.raises(RaceLost):
            third.check(work)
        board.post(0, 1.0, 1)  # a worse success does not replace the best
        third.check(work - 1e-16)
        assert RaceBound(3, None, board.path(1)).best is None


def test_a_bound_keeps_what_it_knew_and_takes_a_better_post():
    with RaceBoard() as board:
        bound = RaceBound(0, (5.0, 1), board.path(0))
        with pytest.raises(RaceLost):
            bound.check(6.0)
        board.post(0, 2.0, 3)
        with pytest.raises(RaceLost, match="start 3"):
            bound.check(2.5)


def test_a_closed_round_stops_its_starts_at_once():
    with RaceBoard() as board:
        bound = RaceBound(4, None, board.path(2))
        bound.check(0.0)
        board.close(2)
        with pytest.raises(RaceLost, match="a start of an earlier round succeeded"):
            bound.check(0.0)
        folder = os.path.dirname(board.path(0))
    assert not os.path.exists(folder)


def test_a_board_refuses_a_negative_round():
    with RaceBoard() as board, pytest.raises(InvalidArgumentError, match="race round"):
        board.path(-1)


def test_a_race_needs_rounds_of_at_least_one_start():
    from shspec.inverse.race import race_round

    assert race_round(5, 2) == 2
    with pytest.raises(InvalidArgumentError, match="race width"):
        race_round(3, 0)
