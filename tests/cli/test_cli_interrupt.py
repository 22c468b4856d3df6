"""Issue 50, item 13: Ctrl-C in the first seconds of any command (while shspec imports NumPy, SciPy, numba, ...)
printed Python's KeyboardInterrupt traceback; it now gives one line and exit status 130, as later in a command."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: A child that sends itself a real SIGINT when it first imports ``TRIGGER``, then runs the console script's entry
#: point as the installed ``shspec`` script does.
CHILD = """
import importlib, os, signal, sys

class Interrupt:
    def find_spec(self, name, path=None, target=None):
        if name == {trigger!r}:
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
        return None

sys.meta_path.insert(0, Interrupt())
module, _, attr = {entry!r}.partition(":")
sys.argv = ["shspec", "--help"]
sys.exit(getattr(importlib.import_module(module), attr)())
"""


@pytest.mark.parametrize("script, trigger", [("shspec", "h5py"), ("shspec", "shspec.cli.forward"),
                                             ("shspec-precompute", "h5py")])
def test_ctrl_c_during_the_imports_is_one_line_and_status_130(script, trigger):
    """``h5py`` is imported with shspec itself, ``shspec.cli.forward`` while the parser is built."""
    entry = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"][script]
    run = subprocess.run([sys.executable, "-c", CHILD.format(trigger=trigger, entry=entry)], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 130, run.stderr
    assert run.stderr == "shspec: interrupted\n" and run.stdout == ""


@pytest.mark.slow
def test_ctrl_c_while_python_m_shspec_builds_its_parser_is_one_line_and_status_130():
    """``python -m shspec`` imports the package before anything of shspec runs; the commands' modules it imports
    while building the parser are covered."""
    run = subprocess.run([sys.executable, "-c", CHILD.format(trigger="shspec.cli.forward", entry="shspec.cli:main")],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 130, run.stderr
    assert run.stderr == "shspec: interrupted\n" and run.stdout == ""
