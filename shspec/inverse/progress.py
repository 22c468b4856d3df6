"""One progress display for a whole fit, on stderr: a tqdm bar over the stages of all starts, with the start and
stage under way, its iteration and residual, the starts done and how many succeeded, the elapsed time and an
estimate of what remains; above it, one line per finished stage, hop and start.

The bar is drawn on a terminal only; elsewhere (a log file, CI) only the lines are written.  The remaining time is
tqdm's rate extrapolation over the stages finished so far: the stages of a degree ramp grow, so it is an estimate
that improves as the fit goes.  Starts run by an executor report when they end (their workers stay silent).
"""

from __future__ import annotations

import sys

from tqdm import tqdm

__all__ = ["FitDisplay"]


class FitDisplay:
    """The progress of a fit of ``starts`` starts through ``stages`` stages each.

    Parameters
    ----------
    starts, stages : int
        Starts to run and stages per start (the bar counts stages).
    enabled : bool
        Show anything at all (``FitOptions.progress``; ``shspec fit --quiet`` turns it off).
    done : int
        Starts already finished (a resumed fit).
    file : text stream
        Where to write (default: stderr).
    """

    def __init__(self, starts: int, stages: int, enabled: bool, *, done: int = 0, file=None):
        self.file = sys.stderr if file is None else file
        self.enabled = bool(enabled)
        self.starts, self.stages, self.done, self.successes = starts, stages, done, 0
        tty = self.enabled and hasattr(self.file, "isatty") and self.file.isatty()
        self.bar = tqdm(total=starts * stages, initial=done * stages, unit="stage", file=self.file, leave=False,
                        disable=not tty, dynamic_ncols=True, desc=self._desc(),
                        bar_format="{desc} {bar} {elapsed} elapsed, ~{remaining} left{postfix}")

    def _desc(self) -> str:
        return f"fit: {self.done}/{self.starts} starts done, {self.successes} succeeded"

    def iteration(self, start: int, stage: int, iteration: int, residual: float) -> None:
        """Where the running start is (redrawn at most ten times a second)."""
        self.bar.set_postfix_str(f"| start {start}, stage {stage + 1}/{self.stages}, iteration {iteration}, "
                                 f"max rel. residual {residual:.2e}", refresh=False)
        self.bar.update(0)

    def message(self, text: str) -> None:
        """A line above the bar (a finished stage, a hop, a start)."""
        if self.enabled:
            self.bar.write(text, file=self.file)

    def stage_done(self) -> None:
        self.bar.update(1)

    def start_done(self, result) -> None:
        """A start ended (:class:`~shspec.inverse.results.StartResult`): count it, and its success."""
        self.done += 1
        self.successes += bool(result.success)
        self.bar.n = self.done * self.stages  # a start that ended early (success in its hops) skips its stages
        self.bar.set_description_str(self._desc(), refresh=False)
        self.bar.refresh()
        self.message(f"  start {result.index} done: {result.status}, max rel. residual "
                     f"{result.relative_residual:.3e}, {result.seconds:.0f} s ({self.done}/{self.starts}, "
                     f"{self.successes} succeeded)")

    def close(self) -> None:
        self.bar.close()
