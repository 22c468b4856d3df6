"""Mesh loading, saving and validation: each kind of bad mesh raises MeshError naming its problem."""

from __future__ import annotations


import numpy as np
import pytest
import trimesh

from shspec.errors import InvalidArgumentError, MeshError
from shspec.mesh.mesh_files import load_mesh, save_mesh
from shspec.mesh.shapes import icosphere
from shspec.mesh.triangle_mesh import TriangleMesh
from shspec.mesh.validate import validate_mesh



@pytest.fixture
def ico():
    return icosphere(2)


@pytest.mark.parametrize("name", ["bunny_600", "spot_600", "blub_600", "bunny_1200"])
def test_shared_meshes_load_and_validate(shared_meshes, name):
    mesh = load_mesh(shared_meshes / f"{name}.obj")
    assert mesh.nfaces == 2 * mesh.nvertices - 4
    assert mesh.signed_volume() > 0


def test_load_keeps_vertex_order(shared_meshes):
    mesh = load_mesh(shared_meshes / "spot_600.obj")
    first = next(line for line in (shared_meshes / "spot_600.obj").read_text().splitlines() if line.startswith("v "))
    np.testing.assert_array_equal(mesh.vertices[0], np.array(first.split()[1:], dtype=float))


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".off", ".stl"])
def test_save_load_round_trip(tmp_path, suffix):
    mesh = icosphere(2)
    back = load_mesh(save_mesh(mesh, tmp_path / f"m{suffix}"))
    assert back.nvertices == mesh.nvertices and back.nfaces == mesh.nfaces
    # STL has no shared vertices (they are merged on load, reordered) and stores float32.
    if suffix == ".stl":
        np.testing.assert_allclose(np.sort(back.vertices, axis=0), np.sort(mesh.vertices, axis=0), atol=1e-6)
    else:
        np.testing.assert_allclose(back.vertices, mesh.vertices, rtol=0, atol=1e-6 if suffix != ".obj" else 0)
        np.testing.assert_array_equal(back.faces, mesh.faces)


def test_io_errors(tmp_path):
    with pytest.raises(MeshError, match="no such file"):
        load_mesh(tmp_path / "missing.obj")
    with pytest.raises(InvalidArgumentError, match="unsupported mesh format"):
        load_mesh(tmp_path / "mesh.xyz")
    bad = tmp_path / "empty.obj"
    bad.write_text("# nothing\n")
    with pytest.raises(MeshError):
        load_mesh(bad)


def test_holes_counts_boundary_loops(ico):
    # Two faces far apart: two separate holes.
    centroids = ico.vertices[ico.faces].mean(axis=1)
    far = int(np.argmin(centroids @ centroids[0]))
    keep = np.setdiff1d(np.arange(ico.nfaces), [0, far])
    with pytest.raises(MeshError, match="6 boundary edges forming 2 boundary loops"):
        validate_mesh(TriangleMesh(ico.vertices, ico.faces[keep]))


def test_torus_reports_genus():
    t = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3)
    with pytest.raises(MeshError, match=r"\(genus 1\)"):
        validate_mesh(TriangleMesh(t.vertices, t.faces))


def test_non_manifold_edge(ico):
    a, b = ico.faces[0, 0], ico.faces[0, 1]
    v = np.vstack([ico.vertices, [[0.0, 0.0, 0.0]]])
    f = np.vstack([ico.faces, [[a, b, v.shape[0] - 1]]])
    with pytest.raises(MeshError, match=rf"edge \({min(a, b)}, {max(a, b)}\) with 3 faces"):
        validate_mesh(TriangleMesh(v, f))


def test_two_components(ico):
    v = np.vstack([ico.vertices, ico.vertices + [3.0, 0.0, 0.0]])
    f = np.vstack([ico.faces, ico.faces + ico.nvertices])
    with pytest.raises(MeshError, match="2 connected components"):
        validate_mesh(TriangleMesh(v, f))


def test_pinched_vertex(ico):
    # A translated copy whose vertex j (opposite to vertex 0) lands on vertex 0 of the first sphere, and is merged
    # with it: one component, closed, every edge manifold, but vertex 0 joins two fans.
    n = ico.nvertices
    j = int(np.argmin(np.linalg.norm(ico.vertices + ico.vertices[0], axis=1)))
    v = np.vstack([ico.vertices, np.delete(ico.vertices + 2 * ico.vertices[0], j, axis=0)])
    f2 = ico.faces.copy()
    glued = f2 == j
    f2[f2 > j] -= 1
    f2 += n
    f2[glued] = 0
    with pytest.raises(MeshError, match="vertex 0 joins 2 separate fans"):
        validate_mesh(TriangleMesh(v, np.vstack([ico.faces, f2])))


def test_zero_area_face(ico):
    v = ico.vertices.copy()
    a, b, c = ico.faces[5]
    v[c] = 0.5 * (v[a] + v[b])
    with pytest.raises(MeshError, match="zero area"):
        validate_mesh(TriangleMesh(v, ico.faces))


def test_nan_coordinates(ico):
    v = ico.vertices.copy()
    v[7, 1] = np.nan
    with pytest.raises(MeshError, match="NaN or inf coordinates \\(first: vertex 7\\)"):
        validate_mesh(TriangleMesh(v, ico.faces))


def test_inconsistent_orientation(ico):
    f = ico.faces.copy()
    f[3] = f[3, ::-1]
    with pytest.raises(MeshError, match="not consistently oriented"):
        validate_mesh(TriangleMesh(ico.vertices, f))


def test_repeated_index_and_unreferenced_vertex(ico):
    f = ico.faces.copy()
    f[2, 1] = f[2, 0]
    with pytest.raises(MeshError, match="repeat a vertex"):
        validate_mesh(TriangleMesh(ico.vertices, f))
    with pytest.raises(MeshError, match="belong to no face"):
        validate_mesh(TriangleMesh(np.vstack([ico.vertices, [[5.0, 5, 5]]]), ico.faces))


def test_shape_errors():
    with pytest.raises(MeshError, match="shape"):
        TriangleMesh(np.zeros((4, 2)), [[0, 1, 2]])
    with pytest.raises(MeshError, match="outside"):
        TriangleMesh(np.zeros((3, 3)), [[0, 1, 3]])


def test_vertex_soup_obj_gets_a_hint_and_welds(tmp_path):
    from shspec.errors import MeshError
    from shspec.mesh.mesh_files import load_mesh
    from shspec.mesh.shapes import icosphere

    mesh = icosphere(1)
    soup = mesh.vertices[mesh.faces.ravel()]
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in soup]
    lines += [f"f {3 * i + 1} {3 * i + 2} {3 * i + 3}" for i in range(len(mesh.faces))]
    path = tmp_path / "soup.obj"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MeshError, match=r"(?s)boundary.*repeat the position.*--merge-vertices"):
        load_mesh(path)
    welded = load_mesh(path, merge_vertices=True)
    assert welded.nvertices == mesh.nvertices and welded.faces.shape == mesh.faces.shape
