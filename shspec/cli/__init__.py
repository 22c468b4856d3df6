"""The ``shspec`` command line: a thin layer over the library, one module per group of subcommands.

Each module listed in ``COMMAND_MODULES`` has a ``register(subparsers)`` function that adds its subcommands and sets
``func`` on them; ``func(args)`` returns the process exit code.

SIGTERM (what ``kill``, a batch scheduler or a container stop sends) is handled like Ctrl-C: it raises
``KeyboardInterrupt`` in the command, so a fit writes its finished starts and best state and every command leaves
its outputs whole, instead of the process dying with nothing written.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import signal
import sys
import threading
import warnings

from .. import __version__
from ..errors import ShspecError, ShspecWarning
from ..mesh.progress import mesh_progress

COMMAND_MODULES = ["shspec.cli.forward", "shspec.cli.mesh", "shspec.cli.experiment", "shspec.cli.fit", "shspec.cli.embed",
                    "shspec.cli.identifiability", "shspec.cli.precompute", "shspec.cli.topology"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="shspec",
        description="Laplace-Beltrami spectra of genus-0 surfaces g = rho*g0, in the spherical-harmonic basis "
        "and on triangle meshes. Run 'shspec COMMAND --help' for each command.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def _terminate(signum, frame):
    raise KeyboardInterrupt


@contextlib.contextmanager
def _sigterm_as_interrupt():
    """Within the block, SIGTERM raises KeyboardInterrupt (module notes); the previous handler is restored after."""
    if threading.current_thread() is not threading.main_thread():  # only the main thread may set handlers
        yield
        return
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextlib.contextmanager
def _warnings_as_lines(command: str):
    """Warnings as one line each on stderr, as a command's errors are: shspec's own as their message; others (a
    library's, or a RuntimeWarning of shspec's) with their category and the place that issued them, without Python's
    echo of that source line, which says nothing to a user of the command line."""
    default = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        what = (f"{message}" if issubclass(category, ShspecWarning) else
                f"{category.__name__}: {message} ({filename}:{lineno})")
        print(f"shspec {command}: warning: {what}", file=sys.stderr if file is None else file)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = default


def main(argv: list[str] | None = None) -> int:
    try:
        parser = build_parser()  # imports every command's module: a second or more
    except KeyboardInterrupt:
        print("shspec: interrupted", file=sys.stderr)
        return 130
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 2
    try:
        # --quiet silences the mesh path's sizes and bars too (shown by default, in Python as here)
        with (_sigterm_as_interrupt(), _warnings_as_lines(args.command),
              mesh_progress(not getattr(args, "quiet", False))):
            return int(args.func(args) or 0)
    except ShspecError as exc:
        print(f"shspec {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except BrokenPipeError:
        # the reader went away (``shspec forward | head``): nothing left to say, and nobody to say it to
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        # files are written atomically, so an interrupt leaves no half-written output behind
        print(f"shspec {args.command}: interrupted", file=sys.stderr)
        return 130
