"""Surfaces of any genus: marching-cubes ring chains, their Euler characteristic, and validation without genus 0."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from shspec.errors import InvalidArgumentError, MeshError
from shspec.mesh.implicit import euler_characteristic, implicit_surface, ring_chain
from shspec.mesh.mesh_files import load_mesh, save_mesh
from shspec.mesh.shapes import icosphere
from shspec.mesh.triangle_mesh import TriangleMesh
from shspec.mesh.validate import validate_mesh


@pytest.mark.parametrize("centers", [[[0, 0]], [[0, 0], [2.2, 0]], [[0, 0], [2.25, 0], [2.25, 2.25]]])
def test_ring_chain_has_genus_len_centers(centers):
    mesh = validate_mesh(ring_chain(centers, spacing=0.15), genus0=False)
    genus = len(centers)
    assert euler_characteristic(mesh) == 2 - 2 * genus
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    assert tm.euler_number == 2 - 2 * genus and tm.is_watertight and tm.is_winding_consistent
    assert mesh.signed_volume() > 0


def test_relaxed_vertices_lie_on_the_surface():
    # A sphere of radius 1.3 as a level set: every vertex on it, the area close to 4π·1.69.
    mesh = implicit_surface(lambda x: np.linalg.norm(x, axis=1) - 1.3, [[-1.6] * 3, [1.6] * 3], 0.1)
    np.testing.assert_allclose(np.linalg.norm(mesh.vertices, axis=1), 1.3, atol=1e-10)
    assert mesh.area() == pytest.approx(4 * np.pi * 1.69, rel=5e-3)
    assert euler_characteristic(mesh) == 2


def test_implicit_surface_errors():
    with pytest.raises(MeshError, match="inside the box"):
        implicit_surface(lambda x: np.linalg.norm(x, axis=1) - 2.0, [[-1] * 3, [1] * 3], 0.1)
    with pytest.raises(InvalidArgumentError, match="spacing"):
        implicit_surface(lambda x: x[:, 0], [[-1] * 3, [1] * 3], -0.1)
    with pytest.raises(InvalidArgumentError, match="minor < major"):
        ring_chain([[0, 0]], major=1.0, minor=1.5)


def test_genus_check_is_optional(tmp_path):
    torus = ring_chain([[0, 0]], spacing=0.15)
    with pytest.raises(MeshError, match="genus 1"):
        validate_mesh(torus)
    assert validate_mesh(torus, genus0=False) is torus
    path = save_mesh(torus, tmp_path / "torus.obj")
    with pytest.raises(MeshError, match="genus 1"):
        load_mesh(path)
    assert load_mesh(path, require_genus0=False).nvertices == torus.nvertices
    # the other checks stay on: a hole is still refused
    ico = icosphere(1)
    with pytest.raises(MeshError, match="boundary"):
        validate_mesh(TriangleMesh(ico.vertices, ico.faces[1:]), genus0=False)
