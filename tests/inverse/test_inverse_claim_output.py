"""One fit at a time writes into an output folder (issue 50 item 7), and the folder's checkpoint is what it seems
(item 17)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from shspec.errors import CheckpointError, OutputError
from shspec.inverse.output import OUTPUT_LOCK, claim_output


def _holder(folder) -> subprocess.Popen:
    """Another process holding ``folder`` until its stdin closes; returned once it holds it."""
    code = textwrap.dedent(f"""
        import sys
        from shspec.inverse.output import claim_output
        with claim_output({str(folder)!r}):
            print("held", flush=True)
            sys.stdin.read()
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


@pytest.mark.slow
def test_a_second_fit_into_a_held_folder_is_refused_at_once_naming_the_holder(tmp_path):
    out = tmp_path / "fit"
    proc = _holder(out)
    try:
        with pytest.raises(OutputError, match=rf"another fit is writing into .*fit \(pid {proc.pid} on "):
            with claim_output(out):
                pass
    finally:
        proc.communicate("", timeout=60)
    with claim_output(out) as held:  # free again once the first fit ended
        assert held == out and (out / OUTPUT_LOCK).exists()


@pytest.mark.slow
def test_a_folder_held_by_a_killed_fit_is_free(tmp_path):
    out = tmp_path / "fit"
    proc = _holder(out)
    proc.kill()  # the system releases its lock; its note of who holds it stays behind
    proc.communicate(timeout=60)
    with claim_output(out):
        pass


def test_the_checkpoint_of_a_held_folder_is_checked_under_the_lock(tmp_path):
    out = tmp_path / "fit"
    with pytest.raises(CheckpointError, match="nothing to resume"):
        with claim_output(out, resume=True):
            pass
    (out / "checkpoint.h5").write_bytes(b"an earlier fit's")
    with pytest.raises(CheckpointError, match="earlier fit"):
        with claim_output(out):
            pass
    with claim_output(out, overwrite=True):
        assert not (out / "checkpoint.h5").exists()


def test_a_file_in_the_way_of_the_folder_is_an_output_error(tmp_path):
    (tmp_path / "fit").write_text("x")
    with pytest.raises(OutputError, match="is a file"):
        with claim_output(tmp_path / "fit"):
            pass


@pytest.mark.parametrize("resume, overwrite", [(False, False), (True, False), (False, True)])
def test_a_directory_named_checkpoint_h5_is_named_as_such(tmp_path, resume, overwrite):
    out = tmp_path / "fit"
    (out / "checkpoint.h5").mkdir(parents=True)
    (out / "checkpoint.h5" / "mine.txt").write_text("the user's")
    with pytest.raises(CheckpointError, match=r"checkpoint\.h5 is a directory, not a checkpoint"):
        with claim_output(out, resume=resume, overwrite=overwrite):
            pass
    assert (out / "checkpoint.h5" / "mine.txt").read_text() == "the user's"
    assert os.listdir(out / "checkpoint.h5") == ["mine.txt"]


def test_claim_checkpoint_names_a_directory_in_the_way(tmp_path):
    from shspec.inverse.checkpoint import claim_checkpoint

    (tmp_path / "checkpoint.h5").mkdir()
    for resume in (False, True):  # was "holds the checkpoint of an earlier fit" and "there is no checkpoint"
        with pytest.raises(CheckpointError, match="is a directory, not a checkpoint"):
            claim_checkpoint(tmp_path / "checkpoint.h5", resume=resume, overwrite=False)
