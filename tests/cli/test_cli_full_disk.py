"""Commands writing onto a full or a read-only file system (issue 50): one error naming the problem, exit 1, no
crash, no temporary file, and no output folder that mixes two runs.  Real file systems: a 64 KiB tmpfs and a
read-only one, mounted for the test (it needs the right to mount, which CI's root has; else it is skipped)."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from shspec.mesh import icosphere, save_mesh

_ENV = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2]), "MPLBACKEND": "Agg",
        "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
FIT = ["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "20", "--starts", "1",
       "--max-iter", "5", "--schedule", "2,6", "--quiet"]


@contextlib.contextmanager
def _mounted(path: Path, options: str):
    path.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode().strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", str(path)], check=True)


def _shspec(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "shspec", *args], env=_ENV, capture_output=True, text=True,
                          timeout=300)


def _one_error(done: subprocess.CompletedProcess, words: str) -> None:
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr
    assert words in done.stderr.lower(), done.stderr


@pytest.mark.slow
@pytest.mark.skipif(os.geteuid() != 0, reason="mounting needs root")
def test_a_full_or_read_only_file_system_is_one_error(tmp_path):
    sphere = save_mesh(icosphere(4), tmp_path / "sphere.obj")  # 2562 vertices: larger than the full tmpfs
    np.savetxt(tmp_path / "factors.txt", np.full(2562, 4.0))
    embed = ["embed", str(sphere), str(tmp_path / "factors.txt")]
    with _mounted(tmp_path / "full", "size=64k") as full:
        _one_error(_shspec(*FIT, "--out", str(full / "fit")), "the disk is full")
        assert {p.name for p in (full / "fit").iterdir()} <= {".shspec-fit.lock"}  # nothing half-written
        _one_error(_shspec(*embed, "--out", str(full / "e.obj"), "--summary", str(full / "e.json")), "the disk is full")
        assert list(full.glob("e.*")) == []
        _one_error(_shspec("precompute", "--lmax", "16", "--lmax-factor", "16", "--cache-dir", str(full / "c"),
                           "--quiet"), "free")
        assert list((full / "c").iterdir()) == []
    with _mounted(tmp_path / "ro", "size=1m,ro") as ro:
        _one_error(_shspec(*FIT, "--out", str(ro / "fit")), "read-only")
        _one_error(_shspec("forward", "--out", str(ro / "spectrum.json")), "read-only")
        _one_error(_shspec(*embed, "--out", str(ro / "e.obj"), "--summary", str(tmp_path / "e.json")), "read-only")
        assert not (tmp_path / "e.json").exists()  # the summary alone would describe a mesh that was not written
        _one_error(_shspec("experiment", "sh-convergence", "--quick", "--out", str(ro / "run")), "read-only")

