"""Functions a reader can hold: none in ``shspec/`` is longer than :data:`MAX_LINES` lines (docstring included), and
none of the command line's, which only parses and prints, longer than :data:`MAX_CLI_LINES`."""

import ast
from pathlib import Path

import shspec

ROOT = Path(shspec.__file__).parent

#: The longest a function may be, from its ``def`` line to its last line.
MAX_LINES = 80

#: The same for the command line (``shspec/cli/``).
MAX_CLI_LINES = 60


def long_functions(root: Path = ROOT, limit: int = MAX_LINES) -> list:
    """``"path:line name (n lines)"`` for every function or method of more than ``limit`` lines under ``root``."""
    found = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    found.append(f"{path.relative_to(root.parent)}:{node.lineno} {node.name} ({n} lines)")
    return found


def test_no_function_is_longer_than_a_reader_can_hold():
    assert long_functions() == []


def test_the_command_line_only_parses_and_prints():
    assert long_functions(ROOT / "cli", MAX_CLI_LINES) == []
    assert len((ROOT / "cli" / "fit.py").read_text().splitlines()) <= 200  # the planning is the library's


def test_the_check_sees_a_long_function(tmp_path):
    (tmp_path / "m.py").write_text("def f():\n" + "    x = 1\n" * 80 + "\n\ndef g():\n    pass\n")
    assert long_functions(tmp_path) == [f"{tmp_path.name}/m.py:1 f (81 lines)"]
