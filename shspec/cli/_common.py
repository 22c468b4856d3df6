"""Argument types and help texts shared by several subcommands, so that one option reads the same everywhere."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..errors import InvalidArgumentError

#: Help of every ``--cache-dir``: the order in which :func:`shspec.gaunt.cache.cache_dir_source` looks.
CACHE_DIR_HELP = ("Gaunt table cache (default: $SHSPEC_CACHE if set; else the cache/ folder of a shspec source "
                  "checkout at or above the current folder; else $XDG_CACHE_HOME/shspec or ~/.cache/shspec; "
                  "'shspec precompute list' prints the one in use)")


def whole_number(minimum: int, why: str = ""):
    """An argparse type: an integer >= ``minimum`` (argparse names the option; ``why`` says what the bound means)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}{f' ({why})' if why else ''}, got {value}")
        return value

    return parse


def load_numbers(path, what: str) -> np.ndarray:
    """The numbers of a text file (``numpy.loadtxt``, '#' comments), at least one: an input file of a command.

    ``numpy.loadtxt`` warns "input contained no data" on a file with nothing but comments and returns an empty
    array, which the checks downstream then misname (a coefficient count that is "not a square", a sphere that is
    "not the unit sphere"); such a file is named here instead.

    Raises
    ------
    InvalidArgumentError
        The file cannot be read, holds something that is not a number, or holds no number.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
        if any(line.split("#", 1)[0].strip() for line in text.splitlines()):
            return np.loadtxt(path, ndmin=1)
    except (OSError, ValueError) as exc:  # UnicodeDecodeError is a ValueError
        raise InvalidArgumentError(f"cannot read {what} from {path}: {exc}") from None
    raise InvalidArgumentError(f"{path} holds no numbers (it is empty or only comments); {what} are expected, one "
                               "per line")
