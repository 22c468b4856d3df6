"""``shspec precompute`` and ``python -m precompute``: build, list, verify, rebuild or clean the Gaunt table cache.

One argument definition (:func:`add_arguments`) and one runner (:func:`run`) serve both entry points.

Examples::

    shspec precompute --lmax 30 --lmax-factor 15          # build (or find) the table (30, 15)
    shspec precompute --lmax 30 --lmax-factor 15 --force  # rebuild it even if cached
    shspec precompute list                                # what the cache holds, and where it is
    shspec precompute verify --lmax 30 --lmax-factor 15   # compare random entries with a fresh computation
"""

from __future__ import annotations

import argparse
import sys
import time

from ._common import CACHE_DIR_HELP, whole_number
from ..errors import ShspecError
from ..gaunt.cache import (cache_dir_source, get_table, list_tables, list_temporary_files, load_table,
                           remove_stale_files, verify_table)
from ..gaunt.table import check_limits

DESCRIPTION = ("Precompute the real Gaunt coefficient tables G_ijk = int Y_i Y_j Y_k that shspec's Galerkin mass "
               "matrix M(a) = sum_k a_k G_k needs, for a basis band limit Lb (--lmax) and a band limit La of the "
               "conformal factor rho (--lmax-factor).")

EPILOG = """\
actions:
  build    (default) compute the table for (--lmax, --lmax-factor) unless the cache already covers it
  rebuild  compute it again and replace the cached file (same as build --force)
  list     show every table in the cache with its size, creation time and any problem (checksums verified),
           and the temporary files of unfinished writes
  verify   recompute --samples random entries of a cached table and report the largest difference
  clean    remove the temporary files that killed writers left behind

The cache directory is --cache-dir, else $SHSPEC_CACHE, else the cache/ folder of the shspec checkout the current
directory lies in, else $XDG_CACHE_HOME/shspec (~/.cache/shspec), however shspec is installed; 'list' prints which. Tables are written atomically under a lock: concurrent
builds of one table are safe, and a rebuild keeps the old file until the new one replaces it. A table for larger
limits serves every smaller request. Sizes: (30,15) 3 MiB, (60,30) 88 MiB, (100,50) about 1.1 GiB.
"""


_Formatter = argparse.RawDescriptionHelpFormatter  # the epilog is laid out by hand; defaults are in each help


def _band_limit(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"band limits are >= 0, got {value}")
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of the precompute command, added to ``p``."""
    p.add_argument("action", nargs="?", default="build", choices=["build", "rebuild", "list", "verify", "clean"],
                   help="what to do (default build)")
    p.add_argument("--lmax", type=_band_limit, help="basis band limit Lb (the basis has (Lb+1)^2 functions)")
    p.add_argument("--lmax-factor", type=_band_limit, help="band limit La of rho, at most 2*Lb")
    p.add_argument("--cache-dir", help=CACHE_DIR_HELP)
    p.add_argument("--force", action="store_true", help="rebuild even if a valid table is cached")
    p.add_argument("--samples", type=whole_number(1), default=2000, help="entries to check with 'verify' (default 2000)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def build_parser(prog: str = "python -m precompute") -> argparse.ArgumentParser:
    """The stand-alone parser of ``python -m precompute``."""
    p = argparse.ArgumentParser(prog=prog, description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=_Formatter)
    add_arguments(p)
    return p


def register(sub) -> None:
    """Add ``precompute`` to the shspec command line."""
    p = sub.add_parser("precompute", help="build, list, verify or rebuild the cached Gaunt tables",
                       description=DESCRIPTION, epilog=EPILOG, formatter_class=_Formatter)
    add_arguments(p)
    p.set_defaults(func=run, parser=p)


def _human(nbytes: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if nbytes < 1024 or unit == "GiB":
            return f"{nbytes:.1f} {unit}" if unit != "B" else f"{int(nbytes)} B"
        nbytes /= 1024
    return ""


def _limits(parser, args):
    if args.lmax is None or args.lmax_factor is None:
        parser.error(f"'{args.action}' needs --lmax and --lmax-factor")
    try:
        return check_limits(args.lmax, args.lmax_factor)
    except ShspecError as exc:
        parser.error(str(exc))


def _list(args) -> int:
    directory, source = cache_dir_source(args.cache_dir)
    tables = list_tables(directory, verify=True)
    temps = list_temporary_files(directory)
    print(f"cache: {directory}  ({source}; the rule: --cache-dir, else $SHSPEC_CACHE, else the cache/ folder of the "
          "shspec checkout around the current directory, else ~/.cache/shspec)")
    if not tables:
        print("(no tables)" if directory.is_dir() else "(no tables; the folder does not exist yet)")
    for t in tables:
        note = f"  PROBLEM: {t.problem}" if t.problem else ""
        print(f"  Lb={t.lmax:<4d} La={t.lmax_factor:<4d} {t.count:>12,d} values  {_human(t.nbytes):>10s}  "
              f"{t.created}  {t.path.name}{note}")
    for t in temps:
        state = ("stale: left by a killed writer; 'clean' or the next build of the table removes it" if t.stale
                 else "being written now")
        print(f"  temporary {t.path.name}  {_human(t.nbytes)}  ({state})")
    return 0


def run(args, parser: argparse.ArgumentParser | None = None) -> int:
    """Carry out the parsed precompute command; returns the exit code (errors propagate as ShspecError)."""
    parser = parser or getattr(args, "parser", None) or build_parser()
    if args.action == "list":
        return _list(args)
    if args.action == "clean":
        removed = remove_stale_files(args.cache_dir)
        for t in removed:
            print(f"removed {t.path}  {_human(t.nbytes)}")
        print(f"{len(removed)} stale temporary file(s) removed")
        return 0
    lmax, lmax_factor = _limits(parser, args)
    if args.action == "verify":
        try:
            table = load_table(lmax, lmax_factor, args.cache_dir)
        except FileNotFoundError as exc:
            print(f"{parser.prog}: error: {exc}", file=sys.stderr)
            return 1
        start = time.perf_counter()
        worst = verify_table(table, args.samples)
        ok = worst <= 1e-13
        print(f"{'OK' if ok else 'FAILED'}: {args.samples} random entries of ({lmax},{lmax_factor}) from "
              f"{table.path or 'a larger table'}: max |stored - fresh| = {worst:.2e} "
              f"({time.perf_counter() - start:.1f} s)")
        return 0 if ok else 1
    force = args.force or args.action == "rebuild"
    if not force:
        try:
            table = load_table(lmax, lmax_factor, args.cache_dir)
        except FileNotFoundError:
            pass
        else:
            where = table.path or f"restricted from the cached {tuple(table.metadata['restricted_from'])}"
            print(f"cached: {where}  {table.values.size:,d} values (use --force to rebuild)")
            return 0
    start = time.perf_counter()
    try:
        table = get_table(lmax, lmax_factor, cache_dir=args.cache_dir, force=force, progress=not args.quiet)
    except KeyboardInterrupt:
        print(f"interrupted: the table ({lmax},{lmax_factor}) was not written; the cache is as it was",
              file=sys.stderr)
        return 130
    seconds = time.perf_counter() - start
    print(f"{table.path}  {_human(table.path.stat().st_size)}  {table.values.size:,d} values  "
          f"{seconds:.2f} s  {table.values.size / seconds:.3g} values/s")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m precompute``."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return run(args, parser)
    except (ShspecError, FileNotFoundError, NotADirectoryError) as exc:
        print(f"precompute: error: {exc}", file=sys.stderr)
        return 1
