"""Argument types and help texts shared by several subcommands, so that one option reads the same everywhere."""

from __future__ import annotations

import argparse

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
