"""Where ``shspec fit`` runs its starts by default (a local pool of one process per start and usable core), and its
stop at the first success (``--all-starts`` runs every start)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import shspec.cli.fit as fit_cli
import shspec.fitting.plan as fit_plan
from shspec.cli import build_parser, main
from shspec.galerkin import HarmonicModel
from shspec.inverse import FitOptions
from shspec.core.parallel import SerialExecutor, usable_cores
from shspec.sphere.random import random_centred_coefficients


@pytest.fixture
def pools(monkeypatch):
    """The (workers, scheduler) of every executor ``shspec fit`` asks for, on a machine of 3 usable cores; the
    starts run here (no processes are spawned in this test)."""
    asked = []

    def make_executor(workers=None, scheduler=None):
        asked.append((workers, scheduler))
        return SerialExecutor()

    monkeypatch.setattr(fit_plan, "make_executor", make_executor)
    monkeypatch.setattr(fit_plan, "usable_cores", lambda: 3)
    return asked


def _spectrum(tmp_path, degree: int, numeig: int):
    """A spectrum file of a random rho (a target without a truth: no alignment to wait for)."""
    path = tmp_path / f"spectrum_{degree}_{numeig}.txt"
    np.savetxt(path, HarmonicModel(8, degree).eigenvalues(random_centred_coefficients(1, degree, 0.3), numeig))
    return path


def test_the_starts_run_on_one_process_per_start_and_core_by_default(pools, tmp_path):
    tiny = ["fit", "--target", f"spectrum:{_spectrum(tmp_path, 4, 10)}", "--numeig", "10", "--lmax", "8",
            "--lmax-factor", "4", "--max-iter", "1", "--basin-hops", "0", "--schedule", "none", "--quiet"]
    assert main([*tiny, "--starts", "4", "--out", str(tmp_path / "default")]) == 0
    assert pools == [(3, None)]  # min(4 starts, 3 cores)
    # checkpoints inside a start need the serial run
    assert main([*tiny, "--starts", "4", "--checkpoint-every", "5", "--out", str(tmp_path / "checkpointed")]) == 0
    assert pools[-1] == (1, None)
    for extra, where in ((["--starts", "2"], (2, None)), (["--starts", "1"], (1, None)),
                         (["--starts", "4", "--workers", "1"], (1, None)),
                         (["--starts", "2", "--workers", "5"], (5, None)),
                         (["--scheduler", "tcp://h:1"], (None, "tcp://h:1"))):
        args = build_parser().parse_args([*tiny, *extra, "--out", str(tmp_path / "x")])
        assert tuple(fit_plan._where(fit_cli._request(args)).values()) == where, extra
    assert 1 <= usable_cores()


def test_a_fit_stops_at_its_first_success_unless_all_starts(pools, tmp_path, capsys):
    # a degree-2 rho from 12 eigenvalues: every start succeeds within 10 iterations
    args = ["fit", "--target", f"spectrum:{_spectrum(tmp_path, 2, 12)}", "--lmax", "8", "--lmax-factor", "2",
            "--numeig", "12", "--starts", "3", "--max-iter", "10", "--schedule", "none", "--basin-hops", "0", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "first")]) == 0
    first = json.loads((tmp_path / "first" / "summary.json").read_text())
    assert [s["index"] for s in first["starts"]] == [0] and first["options"]["stop_at_success"] is True
    assert "of 3 asked, those kept up to the first success; --all-starts runs and keeps all" in capsys.readouterr().out
    assert main([*args, "--all-starts", "--out", str(tmp_path / "all")]) == 0
    every = json.loads((tmp_path / "all" / "summary.json").read_text())
    assert [s["index"] for s in every["starts"]] == [0, 1, 2] and every["successes"] == 3
    assert every["options"]["stop_at_success"] is False and "--all-starts" not in capsys.readouterr().out
    assert every["starts"][0]["energy"] == first["starts"][0]["energy"]
