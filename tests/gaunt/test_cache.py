"""The table cache: atomic, locked, validated; corrupt or mismatched files are never used silently."""

import multiprocessing
import os
import subprocess
import sys
import warnings

import h5py
import numpy as np
import pytest

from shspec.gaunt.cache import (FORMAT_VERSION, get_table, list_tables, load_table, save_table, table_path,
                                verify_table)
from shspec.errors import (BandLimitError, CacheLocationError, CorruptTableError, OutdatedTableError, ShspecWarning,
                           TableMismatchError)
from shspec.gaunt.build import build_table


@pytest.mark.slow
def test_round_trip_and_metadata(tmp_path):
    table = get_table(10, 6, cache_dir=tmp_path)
    path = table_path(10, 6, tmp_path)
    assert table.path == path and path.exists()
    again = load_table(10, 6, tmp_path)
    np.testing.assert_array_equal(again.values, table.values)
    assert again.metadata["format_version"] == 2 and again.metadata["checksum"].startswith("blake2b:")
    assert [t.path for t in list_tables(tmp_path)] == [path]
    assert not list(tmp_path.glob("*.tmp"))
    assert verify_table(again, 300) < 1e-15


def test_larger_table_serves_smaller(tmp_path):
    get_table(12, 8, cache_dir=tmp_path)
    small = load_table(9, 5, tmp_path)
    np.testing.assert_allclose(small.values, build_table(9, 5).values, rtol=0, atol=2e-15)  # other La: round-off
    assert not table_path(9, 5, tmp_path).exists()
    with pytest.raises(FileNotFoundError):
        load_table(13, 5, tmp_path)
    with pytest.raises(BandLimitError, match="precompute"):
        get_table(13, 5, cache_dir=tmp_path, build=False)




def test_a_covered_table_is_found_again_without_a_scan_until_its_source_changes(tmp_path, monkeypatch):
    import shspec.gaunt.cache as cache

    get_table(12, 8, cache_dir=tmp_path)
    first = load_table(9, 5, tmp_path)

    def no_scan(*args, **kwargs):
        raise AssertionError("the cache directory was scanned again")

    with monkeypatch.context() as patch:
        patch.setattr(cache, "list_tables", no_scan)
        assert load_table(9, 5, tmp_path) is first
    # the source damaged since: never used, and the scan that follows skips it
    path = table_path(12, 8, tmp_path)
    with h5py.File(path, "r+") as f:
        f["values"][5] += 1e-12
    with pytest.warns(UserWarning, match="damaged"), pytest.raises(FileNotFoundError):
        load_table(9, 5, tmp_path)
    # removed, and another table covers it now
    path.unlink()
    get_table(11, 6, cache_dir=tmp_path)
    np.testing.assert_allclose(load_table(9, 5, tmp_path).values, first.values, rtol=0, atol=2e-15)
def _flip_byte(path, where):
    data = bytearray(path.read_bytes())
    data[int(len(data) * where)] ^= 0xFF
    path.write_bytes(bytes(data))


def test_corrupt_values_fail_checksum(tmp_path):
    get_table(10, 6, cache_dir=tmp_path)
    path = table_path(10, 6, tmp_path)
    with h5py.File(path, "r+") as f:
        f["values"][5] += 1e-12
    with pytest.raises(CorruptTableError, match="checksum"):
        load_table(10, 6, tmp_path)


def test_truncated_file_is_detected_and_rebuilt_on_request(tmp_path):
    get_table(10, 6, cache_dir=tmp_path)
    path = table_path(10, 6, tmp_path)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(CorruptTableError, match="truncated|corrupt"):
        get_table(10, 6, cache_dir=tmp_path)
    with pytest.warns(UserWarning, match="rebuilding"):
        table = get_table(10, 6, cache_dir=tmp_path, rebuild_corrupt=True)
    np.testing.assert_array_equal(load_table(10, 6, tmp_path).values, table.values)


def test_random_byte_damage_never_passes(tmp_path):
    get_table(8, 4, cache_dir=tmp_path)
    path = table_path(8, 4, tmp_path)
    pristine = path.read_bytes()
    for where in (0.1, 0.5, 0.8, 0.97):
        path.write_bytes(pristine)
        _flip_byte(path, where)
        try:
            table = load_table(8, 4, tmp_path)
        except (CorruptTableError, TableMismatchError):
            continue
        # a flip in unused padding of the HDF5 file is harmless; then the values must be intact
        np.testing.assert_array_equal(table.values, build_table(8, 4).values)


def _cached_table_of_format(tmp_path, version):
    """A cached (10, 6) table whose file claims the format ``version``."""
    get_table(10, 6, cache_dir=tmp_path)
    with h5py.File(table_path(10, 6, tmp_path), "r+") as f:
        f.attrs["format_version"] = version


def test_wrong_version_and_limits(tmp_path):
    _cached_table_of_format(tmp_path, 99)
    with pytest.raises(TableMismatchError, match="format version 99"):
        load_table(10, 6, tmp_path)
    get_table(8, 4, cache_dir=tmp_path)
    os.replace(table_path(8, 4, tmp_path), table_path(9, 4, tmp_path))
    with pytest.raises(TableMismatchError, match="holds the table \\(8,4\\)"):
        load_table(9, 4, tmp_path)


def test_a_table_of_an_older_format_is_rebuilt_with_a_warning(tmp_path):
    _cached_table_of_format(tmp_path, 1)
    with pytest.raises(OutdatedTableError, match="older shspec \\(format version 1"):
        load_table(10, 6, tmp_path)
    with pytest.raises(OutdatedTableError):
        get_table(10, 6, cache_dir=tmp_path, build=False)  # never rebuilt where building is not allowed
    with pytest.warns(ShspecWarning, match="rebuilding the Gaunt table"):
        table = get_table(10, 6, cache_dir=tmp_path)
    np.testing.assert_array_equal(table.values, build_table(10, 6).values)
    assert load_table(10, 6, tmp_path).metadata["format_version"] == FORMAT_VERSION


def test_unusable_cache_locations(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(CacheLocationError, match="is a file"):
        get_table(4, 2, cache_dir=afile)
    with pytest.raises(CacheLocationError):
        get_table(4, 2, cache_dir="/proc/shspec-cannot-exist")


def _build_in_child(directory, queue):
    table = get_table(16, 8, cache_dir=directory)
    queue.put(float(table.values.sum()))


@pytest.mark.slow
def test_concurrent_builds_end_with_one_valid_file(tmp_path):
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    procs = [ctx.Process(target=_build_in_child, args=(str(tmp_path), queue)) for _ in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(timeout=300)
    assert all(p.exitcode == 0 for p in procs)
    sums = [queue.get(timeout=5) for _ in procs]
    assert sums[0] == sums[1]
    files = sorted(x.name for x in tmp_path.iterdir())
    assert files == ["gaunt_Lb16_La8.h5", "gaunt_Lb16_La8.h5.lock"]
    np.testing.assert_array_equal(load_table(16, 8, tmp_path).values, build_table(16, 8).values)


def test_save_refuses_a_file_as_directory(tmp_path):
    afile = tmp_path / "f"
    afile.write_text("")
    with pytest.raises(CacheLocationError):
        save_table(build_table(3, 2), afile)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        save_table(build_table(3, 2), tmp_path)


def _killed_during_save(directory):
    # SIGKILL at the moment the complete temporary file would be renamed: what kill -9 during a save leaves
    import signal

    os.replace = lambda *a: os.kill(os.getpid(), signal.SIGKILL)
    get_table(6, 3, cache_dir=directory)


@pytest.mark.slow
def test_killed_writer_leaves_a_temporary_file_that_is_listed_and_removed(tmp_path):
    from shspec.gaunt.cache import list_temporary_files

    ctx = multiprocessing.get_context("spawn")
    proc = ctx.Process(target=_killed_during_save, args=(str(tmp_path),))
    proc.start()
    proc.join(timeout=300)
    assert proc.exitcode == -9
    orphans = list(tmp_path.glob("gaunt_Lb6_La3.h5.*.tmp"))
    assert len(orphans) == 1
    listed = list_temporary_files(tmp_path)
    assert [(t.path, t.stale) for t in listed] == [(orphans[0], True)]
    get_table(6, 3, cache_dir=tmp_path)
    assert not list(tmp_path.glob("*.tmp"))


def test_force_rebuild_keeps_the_old_table_until_the_new_one_is_complete(tmp_path, monkeypatch):
    import shspec.gaunt.cache as cache

    get_table(6, 3, cache_dir=tmp_path)
    before = table_path(6, 3, tmp_path).read_bytes()

    def interrupted(*args, **kwargs):
        # the old table must still be there, and valid, while the new one is being built
        assert load_table(6, 3, tmp_path).values.size > 0
        raise KeyboardInterrupt

    monkeypatch.setattr(cache, "build_table", interrupted)
    with pytest.raises(KeyboardInterrupt):
        get_table(6, 3, cache_dir=tmp_path, force=True)
    assert table_path(6, 3, tmp_path).read_bytes() == before
    assert not list(tmp_path.glob("*.tmp"))


def test_tables_are_readable_by_others_under_the_usual_umask(tmp_path):
    import stat

    old = os.umask(0o022)
    try:
        get_table(4, 2, cache_dir=tmp_path)
    finally:
        os.umask(old)
    assert stat.S_IMODE(table_path(4, 2, tmp_path).stat().st_mode) == 0o644


def test_list_notes_a_corrupt_table_and_refuses_a_file(tmp_path):
    get_table(6, 3, cache_dir=tmp_path)
    path = table_path(6, 3, tmp_path)
    with h5py.File(path, "r+") as f:
        f["values"][5] += 1e-12
    assert list_tables(tmp_path)[0].problem is None  # the attributes alone look fine
    assert "checksum" in list_tables(tmp_path, verify=True)[0].problem
    afile = tmp_path / "afile"
    afile.write_text("")
    with pytest.raises(CacheLocationError, match="is a file"):
        list_tables(afile)


def test_one_cache_rule_whatever_the_checkout(tmp_path, monkeypatch):
    from shspec.gaunt.cache import cache_dir, cache_dir_source

    monkeypatch.delenv("SHSPEC_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.chdir(tmp_path)  # outside any checkout
    assert cache_dir() == tmp_path / "shspec"
    assert cache_dir_source() == (tmp_path / "shspec", "user cache")
    monkeypatch.setenv("SHSPEC_CACHE", str(tmp_path / "x"))
    assert cache_dir_source() == (tmp_path / "x", "$SHSPEC_CACHE")
    assert cache_dir_source(tmp_path / "y") == (tmp_path / "y", "--cache-dir")


def test_a_checkout_uses_its_cache_folder_from_any_subfolder(tmp_path, monkeypatch):
    from shspec.gaunt.cache import cache_dir_source

    monkeypatch.delenv("SHSPEC_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "user"))
    checkout = tmp_path / "repo"
    (checkout / "cache").mkdir(parents=True)
    (checkout / "docs" / "deep").mkdir(parents=True)
    (checkout / "pyproject.toml").write_text('[project]\nname = "shspec"\n')
    monkeypatch.chdir(checkout / "docs" / "deep")
    assert cache_dir_source() == (checkout / "cache", f"checkout {checkout}")
    other = tmp_path / "other"
    (other / "cache").mkdir(parents=True)
    (other / "pyproject.toml").write_text('[project]\nname = "something-else"\n')
    monkeypatch.chdir(other)
    assert cache_dir_source() == (tmp_path / "user" / "shspec", "user cache")


@pytest.mark.slow
def test_a_file_size_limit_is_named_before_the_build(tmp_path):
    """Issue 50, item 10: ``ulimit -f`` below the table's file made h5py's flush fail with a RuntimeError, a raw
    traceback from ``shspec precompute`` (and from ``shspec forward`` when it built a table); now the limit is
    checked with the disk space, before the build."""
    get_table(8, 8, cache_dir=tmp_path / "warm")  # numba's cache written here, not by the child under its limit
    limit = table_path(8, 8, tmp_path / "warm").stat().st_size - 1  # above the values alone: the header counts
    limited = tmp_path / "limited"
    child = ("import resource, sys\n"
             f"resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))\n"
             "from shspec.cli import main\n"
             f"sys.exit(main(['precompute', '--lmax', '8', '--lmax-factor', '8', '--cache-dir', {str(limited)!r}, "
             "'--quiet']))\n")
    run = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, timeout=300)
    assert run.returncode == 1, run.stderr
    [line] = run.stderr.strip().splitlines()
    assert line.startswith("shspec precompute: error: the Gaunt table (8,8) needs a file of ") and "ulimit -f" in line
    assert sorted(p.name for p in limited.iterdir()) == []


def test_a_write_that_h5py_fails_with_a_runtime_error_is_a_cache_error(tmp_path, monkeypatch):
    """h5py reports a failed write (here EFBIG) as a RuntimeError with the errno in its text."""
    def fail(*args, **kwargs):
        raise RuntimeError("Can't decrement id ref count (file write failed: errno = 27, error message = "
                           "'File too large')")

    monkeypatch.setattr(h5py.File, "create_dataset", fail)
    with pytest.raises(CacheLocationError, match=r"cannot write .*gaunt_Lb3_La2.h5: the file would exceed the "
                                                 r"largest file this process may write \(ulimit -f\); nothing"):
        get_table(3, 2, cache_dir=tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gaunt_Lb3_La2.h5.lock"]


def test_a_dangling_link_in_the_cache_is_listed_as_such_and_replaced_by_a_build(tmp_path):
    """Issue 50, item 12: a link to nowhere made ``list`` (and every load that scans the cache) raise
    FileNotFoundError."""
    link = table_path(4, 4, tmp_path)
    link.symlink_to(tmp_path / "nonexistent")
    [info] = list_tables(tmp_path, verify=True)
    assert info.problem == f"a symbolic link to {tmp_path / 'nonexistent'}, which does not exist"
    with pytest.raises(FileNotFoundError, match="no cached Gaunt table covers"):
        load_table(3, 2, tmp_path)
    table = get_table(4, 4, cache_dir=tmp_path)  # the link points nowhere: the build takes its place
    assert not link.is_symlink() and table.path == link
    assert list_tables(tmp_path)[0].problem is None
