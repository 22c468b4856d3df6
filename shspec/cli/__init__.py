"""The ``shspec`` command line: a thin layer over the library, one module per group of subcommands.

Each module listed in ``_COMMAND_MODULES`` has a ``register(subparsers)`` function that adds its subcommands and sets
``func`` on them; ``func(args)`` returns the process exit code.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import ShspecError

_COMMAND_MODULES = ["shspec.cli.forward", "shspec.cli.mesh", "shspec.cli.experiment", "shspec.cli.fit", "shspec.cli.embed",
                    "shspec.cli.topology"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="shspec",
        description="Laplace-Beltrami spectra of genus-0 surfaces g = rho*g0, in the spherical-harmonic basis "
        "and on triangle meshes. Run 'shspec COMMAND --help' for each command.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in _COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            continue
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except ShspecError as exc:
        print(f"shspec {args.command}: error: {exc}", file=sys.stderr)
        return 1
