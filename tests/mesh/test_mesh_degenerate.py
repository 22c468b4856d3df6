"""Issue 34, items 13 and 18 (meshes): degenerate meshes are refused with their own message, and the advice to weld
vertices names where that can be done."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

from shspec.errors import MeshError
from shspec.mesh.cmcf import cmcf
from shspec.mesh.eigen import mesh_spectrum
from shspec.mesh.mesh_files import load_mesh, save_mesh
from shspec.mesh.shapes import icosphere
from shspec.mesh.triangle_mesh import TriangleMesh
from shspec.mesh.validate import validate_mesh

ICO = icosphere(1)


def test_cmcf_of_a_three_vertex_pillow_does_not_report_success():
    pillow = TriangleMesh(np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1]]), [[0, 1, 2], [0, 2, 1]])
    with pytest.raises(MeshError, match="3 vertices; a closed surface needs at least 4"):
        cmcf(pillow)


def test_two_faces_back_to_back_are_refused():
    faces = np.vstack([ICO.faces, ICO.faces[:1, [0, 2, 1]]])
    with pytest.raises(MeshError, match=r"faces 0 and 80 use the same three vertices"):
        validate_mesh(TriangleMesh(ICO.vertices, faces))


@pytest.mark.parametrize("scale, words", [(1e200, "too large"), (1e-200, "too small")])
def test_huge_and_tiny_coordinates_are_named_not_zero_area(scale, words):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow warnings on the way
        with pytest.raises(MeshError, match=words) as info:
            validate_mesh(ICO.with_vertices(ICO.vertices * scale))
    assert "zero area" not in str(info.value)
    with pytest.raises(MeshError, match=words):
        cmcf(ICO.with_vertices(ICO.vertices * scale))


@pytest.mark.parametrize("value, words", [(np.nan, "1 vertices have NaN or inf coordinates"),
                                          (np.inf, "1 vertices have NaN or inf coordinates"),
                                          (1e150, r"coordinates up to 1e\+150 are too large"),
                                          (1e300, r"coordinates up to 1e\+300 are too large")])
def test_mesh_spectrum_names_bad_coordinates_not_zero_areas(value, words):
    """Issue 50, item 14: mesh_spectrum, which checks areas but not the whole mesh, called these "zero area"."""
    v = ICO.vertices.copy()
    v[3, 0] = value
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow or invalid-value warnings on the way
        with pytest.raises(MeshError, match=words) as info:
            mesh_spectrum(TriangleMesh(v, ICO.faces), 5)
    assert "zero area" not in str(info.value)


@pytest.mark.parametrize("suffix, merge", [(".stl", None), (".obj", True), (".ply", None)])
def test_a_nan_vertex_is_named_whatever_the_format(tmp_path, suffix, merge):
    v = ICO.vertices.copy()
    v[3] = np.nan
    path = tmp_path / f"nan{suffix}"
    trimesh.Trimesh(v, ICO.faces, process=False).export(path)
    with pytest.raises(MeshError, match="NaN or inf coordinates") as info:
        load_mesh(path, merge_vertices=merge)
    assert "not closed" not in str(info.value) and "zero area" not in str(info.value)


def test_the_weld_advice_names_only_what_accepts_it(tmp_path):
    soup = trimesh.Trimesh(ICO.vertices[ICO.faces].reshape(-1, 3), np.arange(3 * len(ICO.faces)).reshape(-1, 3),
                           process=False)
    path = tmp_path / "soup.obj"
    soup.export(path)
    with pytest.raises(MeshError, match=r"merge_vertices=True.*shspec cmcf --merge-vertices.*STL") as info:
        load_mesh(path)
    assert "with --merge-vertices" not in str(info.value)
    assert load_mesh(path, merge_vertices=True).nvertices == ICO.nvertices
    save_mesh(ICO, tmp_path / "ico.stl")
    assert load_mesh(tmp_path / "ico.stl").nvertices == ICO.nvertices
