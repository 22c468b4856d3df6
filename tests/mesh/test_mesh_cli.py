"""The mesh subcommands of the shspec command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from shspec.cli import main
from shspec.mesh.eigen import mesh_spectrum
from shspec.mesh.mesh_files import load_mesh, save_mesh
from shspec.mesh.shapes import blob, icosphere
from shspec.mesh.triangle_mesh import TriangleMesh


@pytest.fixture
def blob_file(tmp_path) -> Path:
    return save_mesh(blob(2), tmp_path / "blob.obj")


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_mesh_spectrum_json(blob_file, capsys, mass):
    assert main(["mesh-spectrum", str(blob_file), "--numeig", "7", "--mass", mass, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    expected = mesh_spectrum(load_mesh(blob_file), 7, mass).eigenvalues
    np.testing.assert_allclose(out["eigenvalues"], expected, rtol=1e-12, atol=1e-12)


def test_mesh_spectrum_text_and_bad_mesh(blob_file, tmp_path, capsys):
    assert main(["mesh-spectrum", str(blob_file), "--numeig", "3"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 3 and lines[0].split()[0] == "0"
    ico = icosphere(1)
    holed = save_mesh(TriangleMesh(ico.vertices, ico.faces[1:]), tmp_path / "holed.off")
    assert main(["mesh-spectrum", str(holed)]) == 1
    assert "1 boundary loop" in capsys.readouterr().err


def test_cmcf_writes_outputs(blob_file, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["cmcf", str(blob_file), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["flips"] == 0 and summary["success"] is True
    from shspec.mesh.cmcf import CMCFOptions

    # the inputs that made it, not only the input file
    assert (summary["tol"], summary["max_iter"], summary["center"]) == (CMCFOptions.tol, CMCFOptions.max_iter, True)
    assert {"roundness", "iterations", "time", "flips"} <= summary.keys()
    sphere = load_mesh(out / "sphere.obj")
    np.testing.assert_allclose(np.linalg.norm(sphere.vertices, axis=1), 1.0, atol=1e-12)
    factors = np.loadtxt(out / "factors.txt")
    assert factors.shape == (sphere.nvertices,) and np.all(factors > 0)
    assert (out / "factors.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cmcf_that_cannot_write_a_figure_leaves_the_previous_run_whole(blob_file, tmp_path, capsys, monkeypatch):
    # issue 50 item 6: sphere.obj, factors.txt and summary.json were the new run's beside the old factors.png
    import errno

    import matplotlib.figure

    out = tmp_path / "flow"
    assert main(["cmcf", str(blob_file), "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def too_large(self, *args, **kwargs):
        raise OSError(errno.EFBIG, "File too large")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", too_large)
    assert main(["cmcf", str(blob_file), "--out", str(out), "--tol", "1e-3"]) == 1
    assert "factors.png" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
