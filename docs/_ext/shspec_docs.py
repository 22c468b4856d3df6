"""Pages generated at build time, so that they cannot drift from what they describe.

* ``generated/cli.rst``: the ``--help`` of every ``shspec`` command, from the parsers themselves;
* ``generated/benchmark_tables.rst``: a table per ``benchmarks/results/*.json`` file, with the machine, load and
  commit of its run and every scalar it recorded.

The docstrings are written for a reader of the source, with mathematics in plain text: |x| is an absolute value,
not an RST substitution, and λ*_i a target eigenvalue, not emphasis.  :func:`escape_math` escapes those characters
outside literals before autodoc parses them.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1]
RESULTS = DOCS.parent / "benchmarks" / "results"


def _indent(text: str, n: int = 3) -> str:
    return "\n".join((" " * n + line) if line else "" for line in text.splitlines())


def write_cli(out: Path) -> None:
    from shspec.cli import build_parser

    os.environ["COLUMNS"] = "100"
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    lines = ["Command-line reference", "======================", "",
             "Generated from the parsers at build time: each section is exactly what ``shspec COMMAND --help``",
             "prints.", "", ".. code-block:: text", "", _indent(parser.format_help()), ""]
    for name, command in sub.choices.items():
        lines += [f"shspec {name}", "-" * (len(name) + 7), "", ".. code-block:: text", "",
                  _indent(command.format_help()), ""]
    _write(out, "\n".join(lines))


def _leaves(value, prefix=""):
    """(path, value) of the scalar leaves of a JSON value; lists of numbers longer than 8 are summarized."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _leaves(item, f"{prefix}.{key}" if prefix else str(key))
    elif isinstance(value, list):
        if all(isinstance(x, (int, float)) for x in value) and len(value) <= 8:
            yield prefix, ", ".join(_fmt(x) for x in value)
        elif all(isinstance(x, (int, float)) for x in value):
            yield prefix, f"{len(value)} numbers, {_fmt(min(value))} … {_fmt(max(value))}"
        else:
            for i, item in enumerate(value):
                yield from _leaves(item, f"{prefix}[{i}]")
    else:
        yield prefix, _fmt(value)


def _fmt(x) -> str:
    if isinstance(x, float):
        return f"{x:.4g}"
    return str(x).replace("\n", " ")


def _cell(text: str) -> str:
    # a word ending in "_" (libscipy_openblas64_) is a reference to reStructuredText
    return text.replace("|", "/").replace("*", r"\*").replace("`", "'").replace("_", r"\_")


def write_benchmarks(out: Path) -> None:
    lines = ["Benchmark records", "=================", "",
             "Generated at build time from ``benchmarks/results/*.json``: for every record the machine, its load",
             "and the commit it measured, then every number it holds. A time is only as good as the load beside it.",
             ""]
    for path in sorted(RESULTS.glob("*.json")):
        data = json.loads(path.read_text())
        machine = data.get("machine", {})
        title = path.stem
        lines += [title, "-" * len(title), ""]
        facts = [("date", machine.get("date_utc") or data.get("date", "")),
                 ("cpu", machine.get("cpu", "")), ("commit", str(machine.get("git_commit", ""))[:10]),
                 ("load before", _fmt(data.get("load_before", machine.get("load_average_1_5_15", machine.get(
                     "loadavg", ""))))),
                 ("load after", _fmt(data.get("load_after", "")))]
        lines += [" · ".join(f"{k}: {v}" for k, v in facts if v not in ("", "None", None)), ""]
        rows = [(k, v) for k, v in _leaves({k: v for k, v in data.items()
                                            if k not in ("machine", "load_before", "load_after")})]
        if rows:
            lines += [".. list-table::", "   :header-rows: 1", "   :widths: 60 40", "",
                      "   * - quantity", "     - value"]
            for key, value in rows[:400]:
                lines += [f"   * - ``{key}``" if key else "   * - (value)", f"     - {_cell(value)}"]
            if len(rows) > 400:
                lines += ["   * - …", f"     - {len(rows) - 400} more values in the file"]
        lines.append("")
    _write(out, "\n".join(lines))


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text() != text:  # unchanged pages keep their time stamp: no rebuild
        path.write_text(text)


#: Inline literals, roles with their targets and hyperlinks: left as they are.
_KEEP = re.compile(r"``.+?``|:[\w:]+:`[^`]+`|`[^`]+`_?")


def _escape(text: str) -> str:
    out, pos = [], 0
    for match in _KEEP.finditer(text):
        out.append(re.sub(r"(?<!\\)([|*])", r"\\\1", text[pos:match.start()]))
        out.append(match.group(0))
        pos = match.end()
    out.append(re.sub(r"(?<!\\)([|*])", r"\\\1", text[pos:]))
    return "".join(out)


def escape_math(app, what, name, obj, options, lines) -> None:
    """Escape | and * in docstring prose (not in literals, roles, tables or ``**kwargs``-style parameter names),
    after numpydoc has turned its sections into fields."""
    for i, line in enumerate(lines):
        stripped = line.strip()
        grid_row = stripped.startswith("|") and stripped.endswith("|") and stripped.count("|") > 2
        if grid_row or stripped.startswith(("+-", "+=", "==", "* ", "- ")) or stripped.startswith("*") and " : " in line:
            continue
        if "**" in line and ("**kwargs" in line or "**" in stripped[:2]):
            continue
        lines[i] = _escape(line)


def own_members_only(app, what, name, obj, skip, options):
    """Skip what a module imports from other packages (scipy's cKDTree in :mod:`shspec.mesh.refine`, ...)."""
    module = getattr(obj, "__module__", None)
    if isinstance(module, str) and not module.startswith("shspec") and what == "module":
        return True
    return None


def _generate(app) -> None:
    write_cli(DOCS / "generated" / "cli.rst")
    write_benchmarks(DOCS / "generated" / "benchmark_tables.rst")


def setup(app):
    app.connect("builder-inited", _generate)
    app.connect("autodoc-process-docstring", escape_math, priority=600)  # after numpydoc's own pass
    app.connect("autodoc-skip-member", own_members_only)
    return {"version": "1", "parallel_read_safe": True}
