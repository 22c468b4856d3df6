"""``shspec fit`` under a file-size limit (issue 50 items 6 and 9): no crash, no temporary file, no folder mixing two
fits; one OutputError naming the file."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

FIT = ["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "20", "--starts", "1",
       "--max-iter", "5", "--schedule", "2,6", "--quiet"]
_ENV = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2]), "MPLBACKEND": "Agg",
        "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}

pytestmark = pytest.mark.skipif(shutil.which("prlimit") is None, reason="needs prlimit (util-linux)")


def _shspec(*args, fsize: int | None = None) -> subprocess.CompletedProcess:
    limit = [] if fsize is None else ["prlimit", f"--fsize={fsize}"]
    return subprocess.run([*limit, sys.executable, "-m", "shspec", *args], env=_ENV, capture_output=True, text=True,
                          timeout=300)


def _files(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def previous(tmp_path_factory):
    """A complete fit's folder (and the Gaunt table it needs, in the session's cache, written without a limit)."""
    out = tmp_path_factory.mktemp("previous") / "fit"
    done = _shspec(*FIT, "--out", str(out))
    assert done.returncode == 0, done.stderr
    return out


@pytest.mark.slow
def test_a_result_file_over_the_size_limit_is_one_output_error_not_a_crash(previous, tmp_path):
    out = tmp_path / "fit"
    done = _shspec(*FIT, "--out", str(out), fsize=8192)
    assert done.returncode == 1, done.stderr  # was 139, a segmentation fault inside HDF5
    assert "Exception ignored" not in done.stderr and "Traceback" not in done.stderr
    assert "cannot write" in done.stderr and "result.h5" in done.stderr and "ulimit -f" in done.stderr
    assert set(_files(out)) <= {".shspec-fit.lock"}  # no result.h5.*.tmp: only the (released) lock of the fit


@pytest.mark.slow
def test_a_fit_over_the_size_limit_leaves_the_previous_fits_folder_as_it_was(previous, tmp_path):
    out = tmp_path / "fit"
    shutil.copytree(previous, out)
    before = _files(out)
    # result.h5 and summary.json fit under the limit, the figures do not: they were the new fit's beside the old
    # factors.png
    done = _shspec(*FIT, "--seed", "1", "--out", str(out), fsize=40_000)
    assert done.returncode == 1, done.stderr
    assert "cannot write" in done.stderr and ".png" in done.stderr and "as they were" in done.stderr
    assert _files(out) == before


@pytest.mark.slow
def test_an_embedding_over_the_size_limit_leaves_the_previous_mesh_and_summary(tmp_path):
    from shspec.mesh import icosphere, save_mesh

    sphere = save_mesh(icosphere(2), tmp_path / "sphere.obj")
    (tmp_path / "factors.txt").write_text("4\n" * 162)
    out = tmp_path / "out"
    out.mkdir()
    embed = ["embed", str(sphere), str(tmp_path / "factors.txt"), "--out", str(out / "e.obj"), "--summary",
             str(out / "e.json")]
    assert _shspec(*embed).returncode == 0
    before = _files(out)
    (tmp_path / "factors.txt").write_text("9\n" * 162)
    # the summary fits under the limit, the mesh does not: it was the new summary beside the old mesh
    done = _shspec(*embed, fsize=4096)
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr and "cannot write" in done.stderr and "e.obj" in done.stderr
    assert _files(out) == before  # no temporary file either


@pytest.mark.slow
def test_an_experiment_over_the_size_limit_leaves_the_previous_runs_folder(tmp_path):
    previous = tmp_path / "run"  # what an earlier run left (its contents do not matter, only that they stay)
    previous.mkdir()
    for name in ("config.json", "meta.json", "report.md", "convergence.png", ".shspec-outputs.json"):
        (previous / name).write_text(f"{name} of an earlier run")
    before = _files(previous)
    # the Gaunt table the quick study needs, written without a limit
    assert _shspec("precompute", "--lmax", "16", "--lmax-factor", "6", "--quiet").returncode == 0
    # config.json fits under the limit, the figures do not: it was the new config beside the old figures
    done = _shspec("experiment", "sh-convergence", "--quick", "--out", str(previous), fsize=8192)
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr and "cannot write" in done.stderr and ".png" in done.stderr
    assert _files(previous) == before
