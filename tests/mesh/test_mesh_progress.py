"""Issue 34, item 20: long work on a large mesh prints its size and shows progress (topology, fit --model mesh)."""

from __future__ import annotations

import pytest

import shspec.mesh.progress as progress
from shspec.cli import main
from shspec.errors import ResourceLimitError
from shspec.mesh.cmcf import cmcf
from shspec.mesh.eigen import mesh_spectrum
from shspec.mesh.mesh_files import save_mesh
from shspec.mesh.shapes import blob, icosphere


@pytest.fixture
def small_is_large(monkeypatch):
    """Every mesh counts as large, so that a test mesh of a few hundred vertices shows what a 163k one would."""
    monkeypatch.setattr(progress, "LARGE_MESH", 10)


def test_topology_of_a_large_mesh_prints_its_size_and_progress(tmp_path, small_is_large, capsys):
    path = tmp_path / "ico.obj"
    save_mesh(icosphere(4), path)
    assert main(["topology", "--target", f"mesh:{path}", "--numeig", "40"]) == 0
    err = capsys.readouterr().err
    assert "cotan eigenpairs of a 2562-vertex mesh: K = 40" in err and "allocated" in err and " s on one core" in err
    assert "eigenpairs (Krylov basis)" in err  # the tqdm bar
    assert main(["topology", "--target", f"mesh:{path}", "--numeig", "40", "--quiet"]) == 0
    assert "eigenpairs" not in capsys.readouterr().err


def test_cmcf_shows_its_steps_unless_silenced(small_is_large, capsys):
    mesh = blob(2)
    cmcf(mesh)  # a library call shows them too: a large mesh's cMCF takes a minute
    err = capsys.readouterr().err
    assert f"cMCF of a {mesh.nvertices}-vertex mesh" in err and "roundness" in err
    with progress.mesh_progress(False):
        cmcf(mesh)
    assert capsys.readouterr().err == ""


def test_a_basis_larger_than_the_memory_is_refused_before_it_is_allocated(small_is_large, monkeypatch):
    monkeypatch.setattr(progress, "available_memory", lambda: 1000)
    with progress.mesh_progress(), pytest.raises(ResourceLimitError, match="of memory is available"):
        mesh_spectrum(icosphere(4), 40)


@pytest.mark.slow
def test_fit_with_a_large_mesh_target_prints_its_size_and_progress(tmp_path, small_is_large, capsys):
    path = tmp_path / "blob.obj"
    save_mesh(blob(2), path)
    assert main(["fit", "--target", f"mesh:{path}", "--model", "mesh", "--numeig", "10", "--starts", "1",
                 "--max-iter", "2", "--schedule", "none", "--basin-hops", "0", "--allow-any-genus",
                 "--out", str(tmp_path / "f")]) == 0
    err = capsys.readouterr().err
    assert "cMCF of a" in err and "roundness" in err
