"""The console scripts ``shspec`` and ``shspec-precompute``: :func:`shspec.cli.main` and
:func:`shspec.cli.precompute.main`, with a Ctrl-C during their imports handled as one during a command is (a
one-line message and exit status 130).

Importing the command line takes seconds (NumPy, SciPy, numba, h5py, pyshtools, matplotlib, every command's
module); a Ctrl-C in that time raised ``KeyboardInterrupt`` outside every handler of :mod:`shspec.cli`, and Python
printed its traceback, or dropped it ("Exception ignored") where it landed in a callback of the import machinery, and
the command went on.  Until the imports are done, SIGINT (and SIGTERM, which the commands treat alike) end the
process at once instead: nothing has been written yet.  This package lies outside ``shspec`` because importing
anything inside it runs ``shspec/__init__.py``, and with it those imports, first.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import signal
import sys

__all__ = ["main", "precompute"]


def _interrupted(signum, frame):
    print("shspec: interrupted", file=sys.stderr, flush=True)
    os._exit(130)


@contextlib.contextmanager
def _interrupts_end_the_process():
    """Within the block SIGINT and SIGTERM end the process at once (module notes); the handlers are restored after."""
    previous = {sig: signal.signal(sig, _interrupted) for sig in (signal.SIGINT, signal.SIGTERM)
                if signal.getsignal(sig) is not signal.SIG_IGN}  # an ignored signal (nohup, a background job) stays so
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def main(argv: list[str] | None = None) -> int:
    """``shspec``: run the command line with ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    with _interrupts_end_the_process():
        cli = importlib.import_module("shspec.cli")
        for name in cli.COMMAND_MODULES:  # what building the parser imports
            importlib.import_module(name)
    return cli.main(argv)


def precompute(argv: list[str] | None = None) -> int:
    """``shspec-precompute`` (what ``python -m precompute`` runs): the Gaunt table cache's command line."""
    with _interrupts_end_the_process():
        command = importlib.import_module("shspec.cli.precompute")
    return command.main(argv)
