"""Issue 34, items 3-5: a fit never silently replaces a checkpoint, every output is written atomically with one
error naming the file, and SIGTERM is handled like Ctrl-C."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import matplotlib.figure
import numpy as np
import pytest

from shspec.cli import main
from shspec.errors import CheckpointError, OutputError
from shspec.galerkin import HarmonicModel
from shspec.inverse import FitOptions, fit
from shspec.fitting import blob_factor, harmonic_target
from shspec.inverse.checkpoint import save_checkpoint
from shspec.inverse.output import write_result

TINY = ["fit", "--target", "blob", "--numeig", "10", "--lmax", "8", "--lmax-factor", "4", "--starts", "1",
        "--max-iter", "3", "--basin-hops", "0", "--schedule", "none", "--quiet"]


@pytest.fixture(scope="module")
def tiny_result():
    target = harmonic_target(blob_factor(), lmax=8, numeig=10)
    return fit(target, HarmonicModel(8, 4), FitOptions(starts=1, max_iter=2, basin_hops=0, schedule=(),
                                                       progress=False))


# item 3 -------------------------------------------------------------------------------------------------------

@pytest.mark.slow
def test_a_fit_into_a_folder_with_a_checkpoint_is_refused_and_says_what_is_there(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(TINY + ["--out", str(out), "--checkpoint-every", "1"]) == 0
    before = (out / "checkpoint.h5").read_bytes()
    capsys.readouterr()
    assert main(TINY + ["--out", str(out), "--checkpoint-every", "1"]) == 1
    err = capsys.readouterr().err
    assert "checkpoint" in err and "1 finished start" in err and "--resume" in err and "--overwrite" in err
    assert (out / "checkpoint.h5").read_bytes() == before
    assert main(TINY + ["--out", str(out), "--overwrite"]) == 0
    assert not (out / "checkpoint.h5").exists()  # discarded, not left behind to be resumed by mistake


def test_the_checkpoint_message_names_the_running_stage_and_history_rows(tmp_path, tiny_result):
    from shspec.inverse.checkpoint import claim_checkpoint, fingerprint
    from shspec.inverse.problem import StartProgress

    path = tmp_path / "checkpoint.h5"
    progress = StartProgress(index=1, stage=2, base=np.zeros(3), state=None, history=[(0.0, 1.0, 2.0)] * 51)
    save_checkpoint(path, fingerprint(FitOptions(), tiny_result.target, tiny_result.model), list(tiny_result.starts),
                    progress, tiny_result.target)
    with pytest.raises(CheckpointError, match="start 1 running at stage 2 with 51 history rows"):
        claim_checkpoint(path, resume=False, overwrite=False)


def test_resume_without_a_checkpoint_is_refused(tmp_path, capsys):
    assert main(TINY + ["--out", str(tmp_path / "none"), "--resume"]) == 1
    err = capsys.readouterr().err
    assert "nothing to resume" in err and "checkpoint.h5" in err
    assert not (tmp_path / "none" / "summary.json").exists()


# item 4 -------------------------------------------------------------------------------------------------------

def _full_disk(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_while_writing_summary_json_keeps_the_old_one(tmp_path, tiny_result, monkeypatch):
    write_result(tiny_result, tmp_path, figures=False)
    old = (tmp_path / "summary.json").read_text()
    monkeypatch.setattr(Path, "write_text", _full_disk)
    with pytest.raises(OutputError) as info:
        write_result(tiny_result, tmp_path, figures=False)
    message = str(info.value)
    assert "summary.json" in message and "disk is full" in message and "are as they were" in message
    assert (tmp_path / "summary.json").read_text() == old
    assert not list(tmp_path.glob("*.tmp"))


def test_a_full_disk_while_writing_a_figure_keeps_the_old_png(tmp_path, tiny_result, monkeypatch):
    write_result(tiny_result, tmp_path)
    old = (tmp_path / "history.png").read_bytes()

    def half_written(self, fname, **kwargs):
        Path(fname).write_bytes(b"\x89PNG partial")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", half_written)
    with pytest.raises(OutputError, match=r"history\.png: the disk is full .*are as they were"):
        write_result(tiny_result, tmp_path)
    assert (tmp_path / "history.png").read_bytes() == old
    assert not list(tmp_path.glob("*.tmp"))


def test_a_failed_hdf5_flush_of_a_checkpoint_is_one_checkpoint_error(tmp_path, tiny_result, monkeypatch):
    path = tmp_path / "checkpoint.h5"
    save_checkpoint(path, {}, list(tiny_result.starts), None, tiny_result.target)
    old = path.read_bytes()

    def flush_failure(self, *args, **kwargs):
        raise RuntimeError("Disable slist on flush dest failure failed (file write failed)")

    monkeypatch.setattr(h5py.Group, "create_group", flush_failure)
    with pytest.raises(CheckpointError, match=r"cannot write .*checkpoint\.h5: .*previous checkpoint\.h5 is intact"):
        save_checkpoint(path, {}, list(tiny_result.starts), None, tiny_result.target)
    assert path.read_bytes() == old


def test_a_read_only_output_folder_is_one_output_error(tmp_path, tiny_result, monkeypatch):
    import tempfile

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    with pytest.raises(OutputError, match=r"result\.h5: the file system is read-only; the outputs of this run were "
                                          "not written"):
        write_result(tiny_result, tmp_path / "ro", figures=False)


# item 5 -------------------------------------------------------------------------------------------------------

def _long_fit(out, workers: str) -> subprocess.Popen:
    """``shspec fit`` running every one of 1000 starts (a long fit) on ``workers``, its stderr a pipe; returned once
    it has said its first line."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1]), "OMP_NUM_THREADS": "1",
           "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    args = [a for a in TINY if a != "--quiet"]
    args[args.index("--starts") + 1] = "1000"
    args[args.index("--max-iter") + 1] = "1000"
    proc = subprocess.Popen([sys.executable, "-m", "shspec", *args, "--all-starts", "--workers", workers, "--out",
                             str(out)], env=env, stderr=subprocess.PIPE, text=True)
    first = proc.stderr.readline()
    assert first.startswith("fitting"), first
    return proc


@pytest.mark.slow
def test_sigterm_to_a_fit_without_checkpoints_writes_the_best_state(tmp_path):
    out = tmp_path / "run"
    proc = _long_fit(out, "1")  # one start after the other (a process pool: the next test)
    time.sleep(1.0)  # a moment inside the starts
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and summary["starts"]
    assert (out / "result.h5").is_file()


@pytest.mark.slow
def test_sigterm_to_a_fit_on_a_process_pool_keeps_the_best_states_of_its_running_starts(tmp_path):
    out = tmp_path / "run"
    # SIGTERM to the fit's own process only, as a batch system sends it (Ctrl-C reaches the workers as well, and
    # they leave it to the fit): the workers are interrupted by the fit and send their starts' best states back
    proc = _long_fit(out, "2")
    # the workers run starts once the first has ended (each takes a second or two; EOF if the fit died)
    line = "fitting"
    while line and " done: " not in line:
        line = proc.stderr.readline()
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "waiting up to" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True
    interrupted = [s for s in summary["starts"] if s["status"] == "interrupted"]
    assert interrupted and all(s["iterations"] >= 0 and np.isfinite(s["energy"]) for s in interrupted)
    indices = [s["index"] for s in summary["starts"]]
    assert len(set(indices)) == len(indices)


def test_an_interrupt_between_two_starts_keeps_the_finished_ones(monkeypatch):
    from shspec.inverse.problem import FitProblem

    real = FitProblem.initial

    def interrupted_at_start_1(self, rng, index):
        if index == 1:
            raise KeyboardInterrupt  # SIGTERM, as the CLI turns it, while start 1 is being set up
        return real(self, rng, index)

    monkeypatch.setattr(FitProblem, "initial", interrupted_at_start_1)
    target = harmonic_target(blob_factor(), lmax=8, numeig=10)
    result = fit(target, HarmonicModel(8, 4), FitOptions(starts=3, max_iter=2, basin_hops=0, schedule=(),
                                                         progress=False))
    assert result.interrupted and [r.index for r in result.starts] == [0]
