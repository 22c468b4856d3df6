"""An experiment's folder is one unit (issue 50): an error, Ctrl-C or a full disk during a run leaves the folder of the
previous run as it was, and a finished run replaces all of it."""

from __future__ import annotations

import errno

import pytest

from shspec.errors import OutputError
from shspec.experiments import EXPERIMENTS, Experiment, Finding, run_experiment


def _files(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.fixture
def toy(monkeypatch):
    """A registered experiment whose run is ``behaviour(config, out)``; returns the setter of that behaviour."""
    state = {}

    def run(config, out, progress):
        return state["behaviour"](config, out)

    monkeypatch.setitem(EXPERIMENTS, "toy", Experiment("toy", "a toy", "nothing", {"n": 1}, {"n": 1}, 0.1, run))
    return lambda behaviour: state.update(behaviour=behaviour)


def _writes(*names):
    def behaviour(config, out):
        for name in names:
            (out / name).write_text(f"{name} of run {config['n']}")
        return Finding(f"wrote {len(names)} files", tables={"t": [{"n": config["n"]}]}, figures=list(names))
    return behaviour


def test_a_failing_run_leaves_the_previous_runs_folder_as_it_was(toy, tmp_path):
    toy(_writes("a.png", "b.png"))
    report = run_experiment("toy", tmp_path / "run", progress=False)
    assert report == tmp_path / "run" / "report.md" and report.is_file()
    before = _files(tmp_path / "run")
    assert {"a.png", "b.png", "t.csv", "config.json", "meta.json", "report.md"} <= set(before)

    def fails(config, out):
        (out / "a.png").write_text("half of a new run")
        raise OSError(errno.ENOSPC, "No space left on device", str(out / "b.png"))

    toy(fails)
    with pytest.raises(OutputError, match=r"cannot write .*run/b\.png: the disk is full.*as they were"):
        run_experiment("toy", tmp_path / "run", progress=False)
    assert _files(tmp_path / "run") == before
    assert sorted(p.name for p in (tmp_path / "run").iterdir() if p.is_dir()) == []  # no staging folder left

    def interrupted(config, out):
        (out / "a.png").write_text("half of a new run")
        raise KeyboardInterrupt

    toy(interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_experiment("toy", tmp_path / "run", progress=False)
    assert _files(tmp_path / "run") == before


def test_a_finished_run_replaces_every_file_of_the_previous_one(toy, tmp_path):
    toy(_writes("a.png", "b.png"))
    run_experiment("toy", tmp_path / "run", progress=False)
    toy(_writes("a.png"))
    run_experiment("toy", tmp_path / "run", progress=False)
    files = _files(tmp_path / "run")
    assert "b.png" not in files and files["a.png"] == b"a.png of run 1"


def test_a_folder_marked_incomplete_is_not_read_back(toy, tmp_path):
    """A run stopped between the renames of its outputs leaves the marker; neither the report of the experiments nor
    a fit's --init reads the folder then."""
    from shspec import HarmonicModel
    from shspec.core.atomic import INCOMPLETE
    from shspec.errors import InvalidArgumentError
    from shspec.fitting import read_initial
    from shspec.report import build_report

    toy(_writes("a.png"))
    run_experiment("toy", tmp_path / "run", progress=False)
    (tmp_path / "run" / "summary.json").write_text('{"cilm": [[[1.0]], [[0.0]]]}')
    assert read_initial(tmp_path / "run" / "summary.json", HarmonicModel(4, 2))[0] > 0
    (tmp_path / "run" / INCOMPLETE).write_text("stopped")
    with pytest.raises(InvalidArgumentError, match="INCOMPLETE"):
        build_report([tmp_path / "run"], tmp_path / "report.html")
    with pytest.raises(InvalidArgumentError, match="INCOMPLETE"):
        read_initial(tmp_path / "run" / "summary.json", HarmonicModel(4, 2))
