"""The race of a fit's starts: which successful start is the answer, decided by work, not by the clock.

With :attr:`~shspec.inverse.FitOptions.stop_at_success` the starts run in rounds of
:attr:`~shspec.inverse.FitOptions.race` (start i in round i // race).  The answer is a success of the first round
that has one: the start of that round that succeeded after the least *work*, the lower index on a tie.  A start's
work adds up its optimizer iterations and the eigenvalue solves of its hops' moves, each weighted by the
:meth:`~shspec.spectral_model.SpectralModel.solve_cost` of its stage.  It grows with the start's time but does not
depend on the machine, its load or the order the starts ran in, so the answer is the same one after the other, on a
pool or resumed.

Once a start of a round has succeeded, the others of that round can only win with less work: a start whose work
passes the best success's of its round is abandoned (:class:`RaceLost`) and left out of the result.  On a pool the
round thus ends about when its first success comes in, instead of when its slowest start ends (a failing start's
last round of hops ran 186 s at degree 8).  One after the other, the starts of a round after a success run up to
its work.

The starts learn their round's best success from a file (:class:`RaceBoard`) that they read every
:data:`POLL_SECONDS`; the starts of rounds after the first with a success read there that they can stop at once.  A
start whose process cannot read the file (a Dask worker on another machine) runs to its end, which changes the
time, never the result.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from pathlib import Path

from ..core.checks import check_int
from ..errors import InvalidArgumentError

__all__ = ["ABANDONED", "POLL_SECONDS", "RaceLost", "RaceBound", "RaceBoard", "race_round", "won_round",
           "best_success", "race_outcome"]

#: Status of a start abandoned by the race.
ABANDONED = "abandoned"

#: Seconds between two reads of the race's file by a running start (when it reads it changes the time, never the
#: result).
POLL_SECONDS = 0.5


class RaceLost(Exception):
    """Raised in a start whose work passed the best success of its round: it can no longer be the answer."""


def race_round(index: int, width: int) -> int:
    """The round of start ``index`` (≥ 0) in a race of rounds of ``width`` (≥ 1) starts."""
    return check_int(index, "start index", minimum=0) // check_int(width, "race width", minimum=1)


def won_round(finished: list, width: int) -> float:
    """The lowest race round (of ``width`` starts) with a successful start among ``finished``
    (:class:`~shspec.inverse.results.StartResult`), or inf."""
    return min((race_round(r.index, width) for r in finished if r.success), default=math.inf)


def best_success(finished: list, index: int, width: int) -> tuple[float, int] | None:
    """(work, index) of the best success among ``finished`` (:class:`~shspec.inverse.results.StartResult`) in the
    round of start ``index``, or None."""
    keys = [(r.work, r.index) for r in finished
            if r.success and race_round(r.index, width) == race_round(index, width)]
    return min(keys, default=None)


def race_outcome(finished: list, width: int) -> list:
    """The starts a fit with ``stop_at_success`` reports, of those ``finished``: every start of the rounds before the
    first round with a success (all failed), and of that round its best success and the starts that ended, failed,
    with less work (work, then index); with no success, every start.  Abandoned starts are never reported.  The same
    list, by index, whatever order the starts ended in and wherever they were stopped."""
    rnd = won_round(finished, width)
    best = None if rnd == math.inf else best_success(finished, rnd * width, width)
    kept = [r for r in finished if r.status != ABANDONED and (race_round(r.index, width) < rnd or (
        race_round(r.index, width) == rnd and (r.work, r.index) <= best))]
    return sorted(kept, key=lambda r: r.index)


class RaceBound:
    """What a running start knows of the best success of its round: ``known`` ((work, index), or None) and, on a
    pool, the file ``path`` of its round on a :class:`RaceBoard`, read every :data:`POLL_SECONDS`.

    :meth:`check` raises :class:`RaceLost` once the start's (work, index) passes the best success."""

    def __init__(self, index: int, known: tuple[float, int] | None = None, path: str | None = None):
        self.index, self.best, self.path = int(index), known, path
        self._read_at = -math.inf

    def check(self, work: float) -> None:
        if self.path is not None and time.monotonic() - self._read_at >= POLL_SECONDS:
            self._read_at = time.monotonic()
            posted = _read_post(self.path)
            if posted is not None and (self.best is None or posted < self.best):
                self.best = posted
        if self.best is not None and (work, self.index) > self.best:
            if self.best[1] < 0:
                raise RaceLost("a start of an earlier round succeeded")
            raise RaceLost(f"start {self.best[1]} of its round succeeded after work {self.best[0]:.6g}, which this "
                           f"one has reached ({work:.6g}) without success")


def _read_post(path: str) -> tuple[float, int] | None:
    try:
        work, index = Path(path).read_text().split()
        return float.fromhex(work), int(index)
    except (OSError, ValueError):  # not posted yet (or another machine's path): no bound, only a longer run
        return None


class RaceBoard:
    """The fit's side of the race on a pool: a temporary folder with one file per round, holding its best success so
    far, which the round's running starts read (:class:`RaceBound`).  A context manager; the folder is removed on
    exit."""

    def __init__(self):
        self._dir = tempfile.TemporaryDirectory(prefix="shspec-race-")
        self._best: dict[int, tuple[float, int]] = {}

    def __enter__(self) -> "RaceBoard":
        return self

    def __exit__(self, *exc) -> None:
        self._dir.cleanup()

    def path(self, rnd: int) -> str:
        """The file of round ``rnd``."""
        if rnd < 0:
            raise InvalidArgumentError(f"a race round is a non-negative integer, got {rnd}")
        return os.path.join(self._dir.name, f"round-{rnd}")

    def close(self, rnd: int) -> None:
        """An earlier round than ``rnd`` has a success: the running starts of round ``rnd`` are no longer needed and
        end at their next read of the board (a process pool cannot cancel a running task)."""
        self.post(rnd, -math.inf, -1)

    def post(self, rnd: int, work: float, index: int) -> None:
        """A start of round ``rnd`` succeeded after ``work``: post it if it beats the round's best.  Written to a
        temporary file and renamed, so a reader sees the old post or the new one, whole; the work is written
        exactly (hexadecimal), so a start compares with the very number that decides the race."""
        if rnd in self._best and self._best[rnd] <= (work, index):
            return
        self._best[rnd] = (work, index)
        tmp = self.path(rnd) + ".tmp"
        Path(tmp).write_text(f"{float(work).hex()} {int(index)}")
        os.replace(tmp, self.path(rnd))
