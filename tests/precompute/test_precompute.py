"""The precompute command line: a build, list, verify and rebuild run as a user would run it (a new process); the checks
of its messages call the same `main` in this process."""

import os
import subprocess
import sys

import pytest


def run(*args, cache=None):
    env = dict(os.environ)
    if cache is not None:
        env["SHSPEC_CACHE"] = str(cache)
    return subprocess.run([sys.executable, "-m", "precompute", *args], capture_output=True, text=True, env=env,
                          timeout=300)


@pytest.fixture
def here(monkeypatch, capsys):
    """``run`` in this process (the same ``main`` as ``python -m precompute``, without 2-3 s of start-up each), for
    the checks of messages."""
    from precompute.__main__ import main

    def run_here(*args, cache=None):
        if cache is not None:
            monkeypatch.setenv("SHSPEC_CACHE", str(cache))
        try:
            code = main(list(args))
        except SystemExit as exc:  # argparse's errors and --help
            code = exc.code
        out = capsys.readouterr()
        return subprocess.CompletedProcess(args, code, out.out, out.err)
    return run_here


@pytest.mark.slow
def test_build_list_verify_rebuild(tmp_path):
    out = run("--lmax", "12", "--lmax-factor", "6", "--quiet", cache=tmp_path)
    assert out.returncode == 0, out.stderr
    line = out.stdout.strip().splitlines()[-1]
    assert "gaunt_Lb12_La6.h5" in line and "values/s" in line and "KiB" in line
    again = run("--lmax", "10", "--lmax-factor", "6", cache=tmp_path)
    assert again.returncode == 0 and "cached" in again.stdout and "restricted" in again.stdout
    listing = run("list", cache=tmp_path)
    assert "Lb=12" in listing.stdout and "La=6" in listing.stdout
    verify = run("verify", "--lmax", "12", "--lmax-factor", "6", "--samples", "200", cache=tmp_path)
    assert verify.returncode == 0 and verify.stdout.startswith("OK")
    rebuild = run("rebuild", "--lmax", "12", "--lmax-factor", "6", "--quiet", cache=tmp_path)
    assert rebuild.returncode == 0 and "values/s" in rebuild.stdout


@pytest.mark.parametrize("args, message", [
    (["--lmax", "-3", "--lmax-factor", "2"], "band limits are >= 0"),
    (["--lmax", "10", "--lmax-factor", "30"], "2*lmax"),
    (["--lmax", "100000", "--lmax-factor", "3"], "absurdly large"),
    (["--lmax", "ten", "--lmax-factor", "3"], "whole number"),
    (["build"], "needs --lmax and --lmax-factor"),
])
def test_nonsense_arguments(args, message, tmp_path, here):
    out = here(*args, cache=tmp_path)
    assert out.returncode == 2
    assert message in out.stderr


def test_cache_dir_that_is_a_file(tmp_path, here):
    afile = tmp_path / "afile"
    afile.write_text("")
    out = here("--lmax", "4", "--lmax-factor", "2", "--cache-dir", str(afile))
    assert out.returncode == 1 and "is a file" in out.stderr


def test_verify_without_table(tmp_path, here):
    out = here("verify", "--lmax", "4", "--lmax-factor", "2", cache=tmp_path)
    assert out.returncode == 1 and "no cached Gaunt table" in out.stderr


def test_help_explains(here):
    out = here("--help")
    assert out.returncode == 0
    for word in ("--lmax", "--lmax-factor", "--cache-dir", "--force", "verify", "SHSPEC_CACHE"):
        assert word in out.stdout


def test_interrupted_rebuild_keeps_the_table_and_prints_one_line(tmp_path, monkeypatch, capsys):
    import shspec.gaunt.cache as cache
    from precompute.__main__ import main

    assert main(["--lmax", "6", "--lmax-factor", "3", "--quiet", "--cache-dir", str(tmp_path)]) == 0
    before = cache.table_path(6, 3, tmp_path).read_bytes()
    capsys.readouterr()

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(cache, "build_table", interrupted)
    code = main(["--lmax", "6", "--lmax-factor", "3", "--force", "--quiet", "--cache-dir", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 130 and len(err.strip().splitlines()) == 1 and "interrupted" in err
    assert cache.table_path(6, 3, tmp_path).read_bytes() == before


def test_list_shows_rule_stale_temporary_and_refuses_a_file(tmp_path, here):
    (tmp_path / "gaunt_Lb6_La3.h5.abcd1234.tmp").write_bytes(b"\0" * 100)
    out = here("list", cache=tmp_path)
    assert out.returncode == 0
    assert "SHSPEC_CACHE" in out.stdout and "gaunt_Lb6_La3.h5.abcd1234.tmp" in out.stdout and "stale" in out.stdout
    clean = here("clean", cache=tmp_path)
    assert clean.returncode == 0 and not list(tmp_path.glob("*.tmp"))
    afile = tmp_path / "afile"
    afile.write_text("")
    out = here("list", "--cache-dir", str(afile))
    assert out.returncode == 1 and "is a file" in out.stderr


def test_shspec_precompute_is_the_same_command(tmp_path):
    from shspec.cli import main

    assert main(["precompute", "--lmax", "4", "--lmax-factor", "2", "--quiet", "--cache-dir", str(tmp_path)]) == 0
    assert (tmp_path / "gaunt_Lb4_La2.h5").exists()
