"""The benchmark runner lists every benchmark and starts each one (its ``--help``: a full run is a measurement, not a
test).  Benchmarks are not tests: nothing here times anything."""

import runpy
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(p.stem for p in [*(ROOT / "benchmarks").glob("bench_*.py"), ROOT / "benchmarks" / "wigner_accuracy.py"])


def _runner(*args):
    return subprocess.run([sys.executable, "-m", "benchmarks", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)


@pytest.mark.slow
def test_list_names_every_benchmark_with_what_it_measures():
    out = _runner("list")
    assert out.returncode == 0, out.stderr
    listed = {line.split()[0]: line.split(None, 1)[1] for line in out.stdout.splitlines()}
    assert sorted(listed) == SCRIPTS
    assert all(len(text) > 20 for text in listed.values())


@pytest.mark.slow
def test_an_unknown_name_is_refused_with_the_known_ones():
    out = _runner("run", "bench_nothing")
    assert out.returncode == 2 and "bench_forward" in out.stderr


@pytest.mark.slow
def test_a_benchmark_starts_through_the_runner_and_writes_no_record_for_its_help():
    out = _runner("run", "bench_tables", "--help")
    assert out.returncode == 0, out.stderr
    assert "usage" in out.stdout and "no new record" in out.stderr  # --help writes nothing


@pytest.mark.slow
@pytest.mark.parametrize("name", SCRIPTS)
def test_every_benchmark_parses_its_options(name, monkeypatch, capsys):
    # in this process, where shspec and the peers are imported once, not in two new processes per benchmark
    folder = ROOT / "benchmarks"
    monkeypatch.setattr(sys, "path", [str(folder), *sys.path])  # as for a script run by name
    monkeypatch.setattr(sys, "argv", [name, "--help"])
    try:
        with pytest.raises(SystemExit) as exited:
            runpy.run_path(str(folder / f"{name}.py"), run_name="__main__")
    finally:  # the scripts' own modules (common, bench_forward, ...) are not left for other tests to import
        for module in [m for m, mod in sys.modules.items() if str(getattr(mod, "__file__", "")).startswith(str(folder))]:
            del sys.modules[module]
    assert exited.value.code == 0
    assert "usage" in capsys.readouterr().out
