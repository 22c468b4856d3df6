"""``python -m precompute``: the Gaunt table cache's command line (the same as ``shspec precompute``).

A thin shell: the arguments and the work are in :mod:`shspec.cli.precompute`, over :mod:`shspec.gaunt`.
"""

from __future__ import annotations

import sys

from shspec.cli.precompute import build_parser, main

__all__ = ["build_parser", "main"]

if __name__ == "__main__":
    sys.exit(main())
