"""The atomic write helpers: a destination (or a set of them) is either the old file or the complete new one."""

import errno
import os
import stat
from pathlib import Path

import h5py
import numpy as np
import pytest

from shspec.core.atomic import (INCOMPLETE, atomic_hdf5, atomic_output_files, atomic_outputs, atomic_path,
                                atomic_paths, check_complete, temporary_files, umask_mode)
from shspec.errors import InvalidArgumentError, OutputError


def _write(path, value):
    with atomic_hdf5(path) as f:
        f["x"] = np.full(3, value)


def test_replaces_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "a.h5"
    _write(path, 1.0)
    _write(path, 2.0)
    with h5py.File(path, "r") as f:
        np.testing.assert_array_equal(f["x"][...], [2.0, 2.0, 2.0])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.h5"]


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_exception_keeps_the_old_file(tmp_path, error):
    path = tmp_path / "a.h5"
    _write(path, 1.0)
    with pytest.raises(error):
        with atomic_hdf5(path) as f:
            f["x"] = np.zeros(3)
            raise error("stop")
    with h5py.File(path, "r") as f:
        np.testing.assert_array_equal(f["x"][...], [1.0, 1.0, 1.0])
    assert temporary_files(path) == []


def test_mode_follows_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        with atomic_path(tmp_path / "b.txt") as tmp:
            tmp.write_text("hello")
        assert umask_mode(0o644) == 0o640
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "b.txt").stat().st_mode) == 0o640
    assert (tmp_path / "b.txt").read_text() == "hello"


def test_temporary_files_finds_only_its_own(tmp_path):
    (tmp_path / "a.h5.x1y2.tmp").write_text("")
    (tmp_path / "ab.h5.x1y2.tmp").write_text("")
    (tmp_path / "a.h5").write_text("")
    assert [p.name for p in temporary_files(tmp_path / "a.h5")] == ["a.h5.x1y2.tmp"]


def test_files_that_belong_together_are_all_new_or_all_old(tmp_path):
    mesh, summary = tmp_path / "a" / "m.obj", tmp_path / "b" / "s.json"
    mesh.parent.mkdir(), summary.parent.mkdir()
    with atomic_output_files([mesh, summary]) as (m, s):
        m.write_text("old mesh"), s.write_text("old summary")
    # the second file fails after the first is complete: neither changes
    with pytest.raises(OutputError, match=r"cannot write .*s\.json: the disk is full.*none of .* has changed"):
        with atomic_output_files([mesh, summary]) as (m, s):
            m.write_text("new mesh")
            raise OSError(errno.ENOSPC, "No space left on device", str(s))
    assert (mesh.read_text(), summary.read_text()) == ("old mesh", "old summary")
    assert temporary_files(mesh) == temporary_files(summary) == []
    with pytest.raises(ValueError, match="given twice"):
        with atomic_paths([mesh, tmp_path / "a" / ".." / "a" / "m.obj"]):
            pass


def test_a_writer_that_is_atomic_itself_is_named_by_the_destination(tmp_path, monkeypatch):
    """save_mesh writes its temporary file atomically too; its failure names the file the user asked for."""
    from shspec.mesh import icosphere, save_mesh

    def full(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(self))

    monkeypatch.setattr(Path, "write_text", full)
    with pytest.raises(OutputError, match=r"cannot write .*e\.obj: the disk is full .*; nothing was written") as info:
        with atomic_output_files([tmp_path / "e.obj", tmp_path / "e.json"]) as (m, _):
            save_mesh(icosphere(1), m, file_type=".obj")
    assert ".tmp" not in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_files_written_into_the_staging_folder_are_outputs(tmp_path):
    with atomic_outputs(tmp_path) as files:
        (files.folder / "b.txt").write_text("b")
        files.path("a.txt").write_text("a")
    assert sorted(p.name for p in tmp_path.iterdir()) == [".shspec-outputs.json", "a.txt", "b.txt"]
    with atomic_outputs(tmp_path) as files:  # the next run writes only a.txt: b.txt was the earlier run's
        files.path("a.txt").write_text("A")
    assert sorted(p.name for p in tmp_path.iterdir()) == [".shspec-outputs.json", "a.txt"]


def test_outputs_of_a_folder_marked_incomplete_are_refused(tmp_path):
    (tmp_path / "summary.json").write_text("{}")
    check_complete(tmp_path / "summary.json")
    (tmp_path / INCOMPLETE).write_text("stopped")
    for path in (tmp_path, tmp_path / "summary.json"):
        with pytest.raises(InvalidArgumentError, match="marked INCOMPLETE.*two runs"):
            check_complete(path)


def test_a_folder_that_cannot_be_written_is_named_before_the_work(tmp_path):
    from shspec.core.atomic import check_writable

    check_writable(tmp_path / "e.obj")
    assert list(tmp_path.iterdir()) == []  # the probe leaves nothing
    with pytest.raises(OutputError, match=r"cannot write .*missing/e\.obj: .*; nothing was written"):
        check_writable(tmp_path / "missing" / "e.obj")
