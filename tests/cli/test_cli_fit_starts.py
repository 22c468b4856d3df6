"""Where ``shspec fit`` runs its starts by default (a local pool of one process per start and usable core), and its
stop at the first success (``--all-starts`` runs every start)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import shspec.cli.fit as fit_cli
from shspec.cli import main
from shspec.galerkin import HarmonicModel
from shspec.parallel import SerialExecutor, usable_cores
from shspec.sphere.random import random_centred_coefficients


@pytest.fixture
def pools(monkeypatch):
    """The (workers, scheduler) of every executor ``shspec fit`` asks for, on a machine of 3 usable cores; the
    starts run here (no processes are spawned in this test)."""
    asked = []

    def make_executor(workers=None, scheduler=None):
        asked.append((workers, scheduler))
        return SerialExecutor()

    monkeypatch.setattr(fit_cli, "make_executor", make_executor)
    monkeypatch.setattr(fit_cli, "usable_cores", lambda: 3)
    return asked


def test_the_starts_run_on_one_process_per_start_and_core_by_default(pools, tmp_path):
    tiny = ["fit", "--target", "blob", "--numeig", "10", "--lmax", "8", "--lmax-factor", "4", "--max-iter", "1",
            "--basin-hops", "0", "--schedule", "none", "--quiet"]
    cases = [(["--starts", "4"], 3), (["--starts", "2"], 2), (["--starts", "1"], 1),
             (["--starts", "4", "--workers", "1"], 1), (["--starts", "2", "--workers", "5"], 5),
             (["--starts", "4", "--checkpoint-every", "5"], 1)]  # checkpoints inside a start: serial
    for n, (extra, workers) in enumerate(cases):
        assert main([*tiny, *extra, "--out", str(tmp_path / str(n))]) == 0
        assert pools[-1] == (workers, None), extra
    assert 1 <= usable_cores()


def test_a_fit_stops_at_its_first_success_unless_all_starts(pools, tmp_path, capsys):
    # a degree-2 rho from 12 eigenvalues: every start succeeds within 10 iterations
    spectrum = tmp_path / "spectrum.txt"
    np.savetxt(spectrum, HarmonicModel(8, 2).eigenvalues(random_centred_coefficients(1, 2, 0.3), 12))
    args = ["fit", "--target", f"spectrum:{spectrum}", "--lmax", "8", "--lmax-factor", "2", "--numeig", "12",
            "--starts", "3", "--max-iter", "10", "--schedule", "none", "--basin-hops", "0", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "first")]) == 0
    first = json.loads((tmp_path / "first" / "summary.json").read_text())
    assert [s["index"] for s in first["starts"]] == [0] and first["options"]["stop_at_success"] is True
    assert "--all-starts runs all 3" in capsys.readouterr().out
    assert main([*args, "--all-starts", "--out", str(tmp_path / "all")]) == 0
    every = json.loads((tmp_path / "all" / "summary.json").read_text())
    assert [s["index"] for s in every["starts"]] == [0, 1, 2] and every["successes"] == 3
    assert every["options"]["stop_at_success"] is False and "--all-starts" not in capsys.readouterr().out
    assert every["starts"][0]["energy"] == first["starts"][0]["energy"]
