"""The benchmark runner lists every benchmark and starts each one (its ``--help``: a full run is a measurement, not a
test).  Benchmarks are not tests: nothing here times anything."""

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
def test_every_benchmark_starts_through_the_runner():
    # each start imports shspec and its peers (5-7 s of CPU): two at a time, one per core
    for pair in (SCRIPTS[i:i + 2] for i in range(0, len(SCRIPTS), 2)):
        runs = {name: subprocess.Popen([sys.executable, "-m", "benchmarks", "run", name, "--help"], cwd=ROOT,
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for name in pair}
        for name, run in runs.items():
            stdout, stderr = run.communicate(timeout=300)
            assert run.returncode == 0, (name, stderr)
            assert "usage" in stdout and "no new record" in stderr, name  # --help writes nothing
