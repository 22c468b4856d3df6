"""``shspec topology``, ``shspec mesh-spectrum`` over many meshes (serial, process pool, Dask) and the fit guard."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import trimesh

from shspec.cli import main
from shspec.errors import InvalidArgumentError
from shspec.mesh.mesh_files import save_mesh
from shspec.mesh.shapes import blob, icosphere
from shspec.mesh.triangle_mesh import TriangleMesh
from shspec.core.parallel import SerialExecutor, make_executor
from shspec.spectral.batch import TABLE_NAME, run_batch


def _torus_mesh(vertices=400):
    n = int(np.sqrt(vertices / 2))
    m = trimesh.creation.torus(1.0, 0.5, major_sections=vertices // n, minor_sections=n)
    return TriangleMesh(m.vertices, m.faces)


@pytest.fixture
def mesh_dir(tmp_path):
    folder = tmp_path / "meshes"
    folder.mkdir()
    save_mesh(blob(2), folder / "blob.obj")
    save_mesh(icosphere(2), folder / "ico.ply")
    save_mesh(_torus_mesh(), folder / "torus.off")
    return folder


def _sphere_file(tmp_path, k=300):
    l = np.arange(20)
    path = tmp_path / "sphere.txt"
    np.savetxt(path, np.repeat(l * (l + 1.0), 2 * l + 1)[:k], header="round sphere")
    return path


def _flat_torus_file(tmp_path, k=300):
    r = 40
    m, n = np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1))
    path = tmp_path / "flat.txt"
    np.savetxt(path, np.sort(4 * np.pi ** 2 * (m.ravel() ** 2 + n.ravel() ** 2))[:k])
    return path


def test_batch_equals_one_by_one(mesh_dir, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["mesh-spectrum", str(mesh_dir), "--out", str(out), "--numeig", "30", "--descriptors",
                 "--topology", "--quiet"]) == 0
    capsys.readouterr()
    rows = list(csv.DictReader(open(out / TABLE_NAME)))
    assert [r["name"] for r in rows] == ["blob", "ico", "torus"]
    for row, path in zip(rows, sorted(mesh_dir.iterdir())):
        assert main(["mesh-spectrum", str(path), "--numeig", "30", "--json"]) == 0
        single = json.loads(capsys.readouterr().out)["eigenvalues"]
        batch = np.loadtxt(out / f"{path.stem}.eigenvalues.txt")
        np.testing.assert_allclose(batch, single, rtol=1e-15, atol=1e-12)
        assert int(row["numeig"]) == batch.size
        for suffix in (".shapedna.txt", ".heat_trace.txt", ".hks.txt", ".topology.json"):
            assert (out / f"{path.stem}{suffix}").is_file()
        assert json.loads((out / f"{path.stem}.topology.json").read_text())["numeig"] == batch.size
    assert {"euler_characteristic", "genus", "confident"} <= rows[0].keys()


def test_single_mesh_options_need_out(mesh_dir, capsys):
    assert main(["mesh-spectrum", str(mesh_dir / "blob.obj"), str(mesh_dir / "ico.ply")]) == 1
    assert "need --out" in capsys.readouterr().err


def _eigenvalues(results):
    return {r.name: r.eigenvalues for r in results}


@pytest.mark.slow
def test_process_pool_equals_serial(mesh_dir, tmp_path):
    serial = _eigenvalues(run_batch([mesh_dir], tmp_path / "a", 20, progress=False))
    with make_executor(workers=2) as ex:
        pooled = _eigenvalues(run_batch([mesh_dir], tmp_path / "b", 20, executor=ex, progress=False))
    assert serial.keys() == pooled.keys()
    for name in serial:
        # one BLAS thread in the workers, several here: the same numbers up to the order of the roundings
        np.testing.assert_allclose(pooled[name], serial[name], rtol=1e-12, atol=1e-12)


def test_dask_cluster_equals_serial(mesh_dir, tmp_path):
    distributed = pytest.importorskip("distributed")
    serial = _eigenvalues(run_batch([mesh_dir / "torus.off"], tmp_path / "a", 20, progress=False))
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cl:
        with make_executor(scheduler=cl.scheduler_address) as ex:
            remote = _eigenvalues(run_batch([mesh_dir / "torus.off"], tmp_path / "b", 20, executor=ex,
                                            progress=False))
    np.testing.assert_allclose(remote["torus"], serial["torus"], rtol=1e-12, atol=1e-12)


def test_make_executor_arguments():
    assert isinstance(make_executor(), SerialExecutor) and isinstance(make_executor(workers=1), SerialExecutor)
    for bad in (0, -2, 1.5, True):
        with pytest.raises(InvalidArgumentError, match="workers"):
            make_executor(workers=bad)
    with pytest.raises(InvalidArgumentError, match="not both"):
        make_executor(workers=2, scheduler="tcp://localhost:8786")
    with pytest.raises(InvalidArgumentError, match="scheduler"):
        make_executor(scheduler=" ")
    with SerialExecutor() as ex:
        assert ex.submit(divmod, 7, 2).result() == (3, 1)
        with pytest.raises(ZeroDivisionError):
            ex.submit(divmod, 1, 0).result()


def test_batch_input_errors(mesh_dir, tmp_path):
    (tmp_path / "other").mkdir()
    save_mesh(blob(1), tmp_path / "other" / "blob.obj")
    with pytest.raises(InvalidArgumentError, match="share the name"):
        run_batch([mesh_dir, tmp_path / "other"], tmp_path / "out", 5)
    with pytest.raises(InvalidArgumentError, match="no such file"):
        run_batch([tmp_path / "missing.obj"], tmp_path / "out", 5)


def test_topology_of_a_spectrum_file(tmp_path, capsys):
    assert main(["topology", "--target", f"spectrum:{_sphere_file(tmp_path)}", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["genus"] == 0 and d["confident"] and abs(d["euler_characteristic"] - 2) < 0.05
    assert d["area"] == pytest.approx(4 * np.pi, rel=1e-3) and d["numeig"] == 300
    assert {"euler_characteristic_error", "area_error", "window"} <= d.keys()
    assert main(["topology", "--target", f"spectrum:{_flat_torus_file(tmp_path)}", "--numeig", "200"]) == 0
    text = capsys.readouterr().out
    assert "genus 1; the nearest other integer is" in text and "eigenvalues used: 200" in text


def test_topology_of_a_mesh(tmp_path, capsys):
    path = save_mesh(_torus_mesh(1500), tmp_path / "torus.obj")
    assert main(["topology", "--target", f"mesh:{path}", "--numeig", "200", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["genus"] == 1 and d["confident"] and d["area_known"]
    assert main(["topology", "--target", "torus.obj"]) == 1
    assert "unknown target" in capsys.readouterr().err


@pytest.mark.slow
def test_fit_refuses_a_torus_spectrum(tmp_path, capsys):
    torus = _flat_torus_file(tmp_path)
    args = ["fit", "--target", f"spectrum:{torus}", "--out", str(tmp_path / "fit"), "--quiet", "--lmax", "4",
            "--lmax-factor", "2", "--workers", "1"]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "genus 1, not 0" in err and "Euler characteristic" in err
    # With the override (or on a sphere's spectrum) the guard lets the fit go on; whatever the fit then says
    # about this tiny basis, it is not the guard's refusal.
    main(args + ["--allow-any-genus"])
    assert "not 0" not in capsys.readouterr().err
    main(["fit", "--target", f"spectrum:{_sphere_file(tmp_path)}", *args[3:]])
    assert "not 0" not in capsys.readouterr().err


def test_a_batch_that_fails_on_a_mesh_leaves_the_previous_batchs_folder(mesh_dir, tmp_path):
    """A batch's files are one unit (issue 50): a mesh that fails after others were written left them beside the
    previous batch's table."""
    run_batch([mesh_dir], tmp_path / "out", 10, progress=False)
    before = {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()}
    (mesh_dir / "torus.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")  # not closed
    with pytest.raises(InvalidArgumentError):
        run_batch([mesh_dir], tmp_path / "out", 12, progress=False)
    assert {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()} == before
    run_batch([mesh_dir / "blob.obj"], tmp_path / "out", 12, progress=False)  # a smaller batch replaces it all
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [".shspec-outputs.json", "blob.eigenvalues.txt",
                                                                    TABLE_NAME]
