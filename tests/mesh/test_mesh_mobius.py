"""Möbius translations and centering, for spherical meshes and for harmonic conformal factors."""

from __future__ import annotations

import numpy as np
import pyshtools
import pytest

from shspec.errors import InvalidArgumentError, MeshError, NotPositiveError
from shspec.sphere.harmonics import cilm_to_vector
from shspec.mesh.cotan import vertex_areas
from shspec.mesh.mobius import center_mesh
from shspec.sphere.mobius import center_harmonic, mobius_scale, mobius_translate
from shspec.mesh.shapes import icosphere


def _unit(rng, n):
    x = rng.standard_normal((n, 3))
    return x / np.linalg.norm(x, axis=1)[:, None]


def test_translation_properties():
    rng = np.random.default_rng(1)
    x = _unit(rng, 20)
    c = np.array([0.3, -0.2, 0.5])
    y = mobius_translate(x, c)
    np.testing.assert_allclose(np.linalg.norm(y, axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(mobius_translate(y, -c), x, atol=1e-14)
    # |dφ| by finite differences along a tangent direction.
    t = np.cross(x, rng.standard_normal(3))
    t /= np.linalg.norm(t, axis=1)[:, None]
    h = 1e-6
    xp = (x + h * t) / np.linalg.norm(x + h * t, axis=1)[:, None]
    xm = (x - h * t) / np.linalg.norm(x - h * t, axis=1)[:, None]
    fd = np.linalg.norm(mobius_translate(xp, c) - mobius_translate(xm, c), axis=1) / np.linalg.norm(xp - xm, axis=1)
    np.testing.assert_allclose(fd, mobius_scale(x, c), rtol=1e-7)
    with pytest.raises(InvalidArgumentError, match=r"\|c\| < 1"):
        mobius_translate(x, [1.0, 0, 0])


def test_center_mesh_undoes_a_boost():
    ico = icosphere(3)
    w = vertex_areas(ico)
    boosted = ico.with_vertices(mobius_translate(ico.vertices, [0.4, -0.3, 0.2]))
    res = center_mesh(boosted, w)
    assert np.linalg.norm(res.center) <= 1e-12 and res.iterations <= 8
    # The weights are the original (uniform-ish) areas at the boosted positions: centering moves them back to
    # the icosphere up to a rotation, so the icosphere's vertex-area distribution is restored.
    np.testing.assert_allclose(w @ res.sphere.vertices, 0.0, atol=1e-12)
    np.testing.assert_allclose(vertex_areas(res.sphere), w, rtol=1e-3)


def test_center_mesh_errors():
    ico = icosphere(1)
    with pytest.raises(MeshError, match="unit sphere"):
        center_mesh(ico.with_vertices(2 * ico.vertices), np.ones(ico.nvertices))
    w = np.ones(ico.nvertices)
    w[3] = 0
    with pytest.raises(NotPositiveError, match="vertex 3"):
        center_mesh(ico, w)


def _boosted_sphere_coefficients(k, lmax, grid=96):
    """Coefficients of ρ_k(θ) = k² / (cos²(θ/2) + k² sin²(θ/2))², an isometric copy of the round sphere."""
    zero, w = pyshtools.expand.SHGLQ(grid)
    lat, lon = pyshtools.expand.GLQGridCoord(grid)
    th = np.radians(90 - lat)[:, None] * np.ones(lon.size)
    rho = k ** 2 / (np.cos(th / 2) ** 2 + k ** 2 * np.sin(th / 2) ** 2) ** 2
    return cilm_to_vector(pyshtools.expand.SHExpandGLQ(rho, w, zero, norm=4, csphase=1), lmax)


@pytest.mark.slow
def test_center_harmonic_recovers_the_round_sphere():
    # Its coefficients decay like ((k − 1)/(k + 1))^l: at k = 1.3, degree 20 holds it to ~1e-17.
    a = _boosted_sphere_coefficients(1.3, 20)
    assert abs(a[2]) > 0.3  # a_10 is large before centering
    res = center_harmonic(a)
    assert res.residual <= 1e-12
    # The centred factor is the round metric, ρ = 1: a_00 = √(4π), the rest zero.
    assert res.coefficients[0] == pytest.approx(np.sqrt(4 * np.pi), rel=1e-12)
    assert np.abs(res.coefficients[1:]).max() < 1e-11
    assert res.truncation < 1e-11


def test_center_harmonic_keeps_area_and_refuses_negative():
    rng = np.random.default_rng(4)
    a = np.zeros(16)
    a[0] = np.sqrt(4 * np.pi)
    a[1:] = 0.08 * rng.standard_normal(15)
    res = center_harmonic(a, lmax=12)
    assert res.residual <= 1e-12 and res.truncation < 1e-2
    # A Möbius map preserves the total area ∫ρ dΩ = √(4π) a_00.
    assert res.coefficients[0] == pytest.approx(a[0], rel=1e-12)
    with pytest.raises(NotPositiveError):
        center_harmonic(np.r_[0.1, 1.0, 0.0, 0.0])
