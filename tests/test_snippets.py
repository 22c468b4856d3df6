"""Every snippet of the README and of the documentation's pages runs: python blocks are executed, shell blocks are
run line by line (blocks marked ``text`` are shown, not run).

``pip install`` steps of shell lines are skipped (the test environment is the installed project, which CI builds
from the same command); everything after them runs for real, in a scratch folder that holds a copy of the
repository's ``docs/`` and ``benchmarks/results/`` (the documentation build reads both), so that nothing is written
into the checkout.  The documentation build of the README is the test that the site builds with warnings as errors.
"""

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: The pages whose snippets run: the README and the documentation's own pages (not the experiments' reports).
PAGES = [README, *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "docs" / "guide").glob("*.md"))]
BLOCKS = [(page.relative_to(ROOT).as_posix(), lang, code) for page in PAGES
          for lang, code in re.findall(r"```(\w+)\n(.*?)```", page.read_text(), flags=re.S)]


def _ids(lang):
    return [(f"{page}:{i}", code) for i, (page, kind, code) in enumerate(BLOCKS) if kind == lang]


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    """A scratch folder with the repository's docs and benchmark results, as a user at the repo root has them."""
    work = tmp_path / "main"
    shutil.copytree(ROOT / "docs", work / "docs", ignore=shutil.ignore_patterns("_build", "auto_examples", "api",
                                                                                "generated"))
    shutil.copytree(ROOT / "benchmarks" / "results", work / "benchmarks" / "results")
    monkeypatch.chdir(work)
    return work


def test_quickstart_has_exactly_two_commands():
    section = README.read_text().split("## Quickstart", 1)[1].split("##", 1)[0]
    lang, body = re.findall(r"```(\w+)\n(.*?)```", section, flags=re.S)[0]
    lines = [x for x in body.strip().splitlines() if x.strip()]
    assert lang == "bash" and len(lines) == 2
    assert lines[0].startswith("pip install .") and "shspec" in lines[0].split("&&")[1]
    assert lines[1].startswith('pip install ".[test]"') and "pytest" in lines[1]
    ci = (README.parent / ".ci" / "run").read_text()
    assert lines[1] in ci


@pytest.mark.slow
@pytest.mark.parametrize("name, code", _ids("python"), ids=[name for name, _ in _ids("python")])
def test_python_snippet(name, code, workdir):
    exec(compile(code, f"{name} (python block)", "exec"), {"__name__": "__snippet__"})


def _commands(body):
    for line in body.strip().splitlines():
        line = line.split("  #")[0].strip()
        if not line:
            continue
        for part in line.split("&&"):
            part = part.strip()
            if part.startswith("pip install"):
                continue
            if "pytest" in part:
                continue  # the suite itself: running it inside itself proves nothing
            yield part


@pytest.mark.slow
@pytest.mark.parametrize("name, code", _ids("bash"), ids=[name for name, _ in _ids("bash")])
def test_shell_snippet(name, code, workdir):
    env = dict(os.environ, MPLBACKEND="Agg")
    bindir = Path(sys.executable).parent
    env["PATH"] = f"{bindir}{os.pathsep}{env.get('PATH', '')}"
    for command in _commands(code):
        argv = shlex.split(command)
        if argv[0] == "python":
            argv[0] = sys.executable
        out = subprocess.run(argv, cwd=workdir, env=env, capture_output=True, text=True, timeout=600)
        assert out.returncode == 0, f"{command}\n{out.stdout}\n{out.stderr}"
