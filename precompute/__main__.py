"""``python -m precompute``: build, list, verify or rebuild the Gaunt tables in shspec's cache.

Examples::

    python -m precompute --lmax 30 --lmax-factor 15          # build (or find) the table (30, 15)
    python -m precompute --lmax 30 --lmax-factor 15 --force  # rebuild it even if cached
    python -m precompute list                                # what the cache holds
    python -m precompute verify --lmax 30 --lmax-factor 15   # compare random entries with a fresh computation
"""

from __future__ import annotations

import argparse
import sys
import time

from shspec.gaunt.cache import cache_dir, ensure_cache_dir, get_table, list_tables, load_table, table_path, verify_table
from shspec.errors import ShspecError
from shspec.gaunt.table import check_limits

_EPILOG = """\
actions:
  build    (default) compute the table for (--lmax, --lmax-factor) unless the cache already covers it
  rebuild  compute it again and replace the cached file (same as build --force)
  list     show every table in the cache with its size, creation time and any problem
  verify   recompute --samples random entries of a cached table and report the largest difference

The cache directory is --cache-dir, else $SHSPEC_CACHE, else the checkout's cache/ folder (~/.cache/shspec when
installed). Tables are written atomically under a lock, so concurrent builds of one table are safe. A table for
larger limits serves every smaller request. Sizes: (30,15) 3 MiB, (60,30) 88 MiB, (100,50) about 1.1 GiB.
"""


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"band limits are >= 0, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m precompute",
        description="Precompute the real Gaunt coefficient tables G_ijk = int Y_i Y_j Y_k that shspec's Galerkin "
        "mass matrix M(a) = sum_k a_k G_k needs, for a basis band limit Lb (--lmax) and a band limit La of the "
        "conformal factor rho (--lmax-factor).",
        epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("action", nargs="?", default="build", choices=["build", "rebuild", "list", "verify"],
                   help="what to do (default: build)")
    p.add_argument("--lmax", type=_positive_int, help="basis band limit Lb (the basis has (Lb+1)^2 functions)")
    p.add_argument("--lmax-factor", type=_positive_int, help="band limit La of rho, at most 2*Lb")
    p.add_argument("--cache-dir", help="cache directory (default: $SHSPEC_CACHE or the project's cache/)")
    p.add_argument("--force", action="store_true", help="rebuild even if a valid table is cached")
    p.add_argument("--samples", type=_positive_int, default=2000, help="entries to check with 'verify' (2000)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


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


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.action == "list":
            tables = list_tables(args.cache_dir)
            print(f"cache: {cache_dir(args.cache_dir)}")
            if not tables:
                print("(no tables)")
            for t in tables:
                note = f"  PROBLEM: {t.problem}" if t.problem else ""
                print(f"  Lb={t.lmax:<4d} La={t.lmax_factor:<4d} {t.count:>12,d} values  {_human(t.nbytes):>10s}  "
                      f"{t.created}  {t.path.name}{note}")
            return 0
        lmax, lmax_factor = _limits(parser, args)
        if args.action == "verify":
            table = load_table(lmax, lmax_factor, args.cache_dir)
            start = time.perf_counter()
            worst = verify_table(table, args.samples)
            ok = worst <= 1e-13
            print(f"{'OK' if ok else 'FAILED'}: {args.samples} random entries of ({lmax},{lmax_factor}) from "
                  f"{table.path or 'a larger table'}: max |stored - fresh| = {worst:.2e} "
                  f"({time.perf_counter() - start:.1f} s)")
            return 0 if ok else 1
        if not (args.force or args.action == "rebuild"):
            try:
                table = load_table(lmax, lmax_factor, args.cache_dir)
            except FileNotFoundError:
                pass
            else:
                where = table.path or f"restricted from the cached {tuple(table.metadata['restricted_from'])}"
                print(f"cached: {where}  {table.values.size:,d} values (use --force to rebuild)")
                return 0
        else:
            ensure_cache_dir(cache_dir(args.cache_dir))
            table_path(lmax, lmax_factor, args.cache_dir).unlink(missing_ok=True)
        start = time.perf_counter()
        table = get_table(lmax, lmax_factor, cache_dir=args.cache_dir, progress=not args.quiet)
        seconds = time.perf_counter() - start
        print(f"{table.path}  {_human(table.path.stat().st_size)}  {table.values.size:,d} values  "
              f"{seconds:.2f} s  {table.values.size / seconds:.3g} values/s")
        return 0
    except ShspecError as exc:
        print(f"precompute: error: {exc}", file=sys.stderr)
        return 1
    except (FileNotFoundError, NotADirectoryError) as exc:
        print(f"precompute: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
