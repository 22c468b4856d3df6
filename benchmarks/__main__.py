"""Run shspec's benchmarks by name: ``python -m benchmarks list`` | ``python -m benchmarks run NAME [ARGS...]``.

Every benchmark is a script in this folder that writes ``results/NAME.json``.  The runner starts it in a fresh
process with one BLAS, OpenMP and numba thread (the measurements compare single-threaded paths side by side), and
after it ends adds a ``run`` record to its JSON: the machine, the commit, the load average before and after, the
arguments and the wall time, so that every record says where and under what load it was taken.  Arguments after
the name go to the script (``--help`` shows its own).
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from common import git_commit, load_average, machine_info  # noqa: E402

#: Environment of a run: one thread everywhere, so that ratios compare like with like.
SINGLE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                 "NUMBA_NUM_THREADS": "1", "MPLBACKEND": "Agg"}


def benchmarks() -> dict:
    """Name -> (script path, first line of its docstring), for every benchmark script here."""
    out = {}
    for path in sorted([*HERE.glob("bench_*.py"), HERE / "wigner_accuracy.py"]):
        doc = ast.get_docstring(ast.parse(path.read_text())) or ""
        out[path.stem] = (path, doc.splitlines()[0] if doc else "")
    return out


def run(name: str, args: list[str]) -> int:
    known = benchmarks()
    if name not in known:
        print(f"no benchmark named {name!r}; known: {', '.join(known)}", file=sys.stderr)
        return 2
    script, _ = known[name]
    result = HERE / "results" / f"{name}.json"
    before_mtime = result.stat().st_mtime if result.exists() else None
    load_before, t0 = load_average(), time.perf_counter()
    code = subprocess.call([sys.executable, str(script), *args], env={**os.environ, **SINGLE_THREAD})
    record = {"benchmark": name, "arguments": args, "exit_code": code, "wall_seconds": time.perf_counter() - t0,
              "load_before": load_before, "load_after": load_average(), "commit": git_commit(),
              "machine": machine_info()}
    if result.exists() and result.stat().st_mtime != before_mtime:
        data = json.loads(result.read_text())
        data["run"] = record
        tmp = result.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(data, indent=1, default=str) + "\n")
        tmp.replace(result)
        print(f"{name}: wrote {result} ({record['wall_seconds']:.0f} s, load {load_before} -> "
              f"{record['load_after']})")
    else:
        print(f"{name}: exit code {code}; no new record in {result}", file=sys.stderr)
    return code


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="action", required=True)
    sub.add_parser("list", help="name every benchmark and what it measures")
    go = sub.add_parser("run", help="run one benchmark (arguments after its name go to it)")
    go.add_argument("name")
    go.add_argument("args", nargs=argparse.REMAINDER)
    ns = parser.parse_args(argv)
    if ns.action == "list":
        for name, (_, line) in benchmarks().items():
            print(f"{name:18s} {line}")
        return 0
    return run(ns.name, ns.args)


if __name__ == "__main__":
    sys.exit(main())
