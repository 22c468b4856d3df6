"""The snippets of docs/inverse.md (the inverse solver's README section) run as written."""

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[1] / "docs" / "inverse.md"
BLOCKS = re.findall(r"```(\w+)\n(.*?)```", DOC.read_text(), flags=re.S)


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_snippet_runs(index, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    lang, body = BLOCKS[index]
    if lang == "python":
        exec(compile(body, f"docs/inverse.md block {index}", "exec"), {"__name__": "__doc_snippet__"})
        return
    for line in body.strip().splitlines():
        argv = shlex.split(line)
        assert argv[0] == "shspec"
        done = subprocess.run([sys.executable, "-m", "shspec", *argv[1:]], cwd=tmp_path, capture_output=True,
                              text=True, timeout=600)
        assert done.returncode == 0, done.stderr
    assert (tmp_path / "shspec-fit" / "summary.json").exists()
