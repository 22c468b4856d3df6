"""The atomic HDF5 write helper: the destination is either the old file or the complete new one."""

import os
import stat

import h5py
import numpy as np
import pytest

from shspec.core.atomic import atomic_hdf5, atomic_path, temporary_files, umask_mode


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
