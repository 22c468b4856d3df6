"""Adaptive sphere refinement, field transfer and alignment, and the per-eigenvalue discretization error."""

from __future__ import annotations

import numpy as np
import pytest

from shspec.errors import InvalidArgumentError
from shspec.mesh.cotan import vertex_areas
from shspec.mesh.eigen import mesh_spectrum
from shspec.mesh.refine import (align_vertex_field, eigenvalue_errors, mesh_quality, refine_sphere, subdivide,
                                trusted_numeig)
from shspec.mesh.shapes import icosphere
from shspec.sphere.evaluate import sample_harmonic
from shspec.sphere.mobius import mobius_scale, mobius_translate
from shspec.sphere.random import random_coefficients


def _field(points, seed=4, scale=3.0):
    return scale * sample_harmonic(random_coefficients(np.random.default_rng(seed), 3, 1.0), points)


def test_refinement_transfers_the_field_and_keeps_the_mesh_well_shaped():
    sphere = icosphere(2)
    s = _field(sphere.vertices)
    fine, t = refine_sphere(sphere, s, 400)
    assert fine.nvertices == 400 and t.shape == (400,)
    np.testing.assert_allclose(np.linalg.norm(fine.vertices, axis=1), 1.0, atol=1e-14)
    np.testing.assert_array_equal(fine.vertices[:162], sphere.vertices)  # old vertices stay, with their values
    np.testing.assert_array_equal(t[:162], s)
    # new values interpolate the smooth field: error O(h²) ≪ the field's own variation between neighbours
    exact = _field(fine.vertices)
    assert np.max(np.abs(t[162:] - exact[162:])) < 0.05 * np.ptp(s)
    q0, q = mesh_quality(sphere), mesh_quality(fine)
    assert q.euler == 2 and q.outward
    # Delaunay on the sphere, longest edges split: no slivers (the icosphere has 54°..71°; a graded mesh needs less)
    assert q0.min_angle > 50 and q.min_angle > 20.0 and q.max_angle < 135.0 and q.aspect_max < 2.5
    # the new vertices went where the metric exp(s) is large: the largest-s tenth of the sphere got denser
    top = s > np.quantile(s, 0.9)
    dense = np.argsort(-exact)[:40]
    assert np.mean(vertex_areas(fine)[dense]) < np.mean(vertex_areas(sphere)[top])


def test_subdivision_interpolates_linearly():
    mesh = icosphere(1)
    fine, v = subdivide(mesh, mesh.vertices[:, 0])
    # a linear function is reproduced exactly by linear interpolation at the (unprojected) midpoints
    np.testing.assert_allclose(v, fine.vertices[:, 0], atol=1e-15)
    assert fine.nvertices == 42 + 120 and fine.nfaces == 4 * 80


def test_alignment_recovers_a_rotated_mirrored_field_on_another_mesh():
    a, b = icosphere(3), icosphere(2)
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ np.diag([1.0, 1.0, -1.0])
    R = np.array([[np.cos(0.3), 0, np.sin(0.3)], [0, 1, 0], [-np.sin(0.3), 0, np.cos(0.3)]]) @ R
    s_b = 0.5 * _field(b.vertices, seed=7)
    # the field on mesh a is s_b moved by R: s_a(x) = s(Rᵀ x); centre-neutral (its area measure is centred already?)
    s_a = 0.5 * _field(a.vertices @ R, seed=7)
    out = align_vertex_field(a, s_a, b, s_b, lmax=6)
    assert out.mirrored
    # neither field is centred: the fitted translation takes sphere a's centring back to b's frame
    assert out.rms < 0.02 * np.std(s_b) and out.rms <= out.centred_rms


@pytest.mark.slow
def test_alignment_undoes_a_moebius_map_of_the_surface():
    """The same surface on a Möbius-moved sphere mesh: its factors change by the inverse area scale of the map.
    Moving the vertices without that change (the centring did so once) leaves an error of the size of log|dφ|²."""
    b = icosphere(3)
    s_b = _field(b.vertices, seed=5, scale=1.0)
    c = np.array([0.35, -0.2, 0.1])
    R = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    a = b.with_vertices(mobius_translate(b.vertices, c) @ R.T)
    s_a = s_b - 2.0 * np.log(mobius_scale(b.vertices, c))
    out = align_vertex_field(a, s_a, b, s_b)
    size = np.std(2.0 * np.log(mobius_scale(b.vertices, c)))
    assert size > 0.5
    # what stays is the linear interpolation on a moved mesh of 642 vertices
    assert out.rms < 0.03 * size and not out.mirrored
    # values[j] = s_a at R x_j of the moved mesh, and a's vertices are R·φ_c(b's)
    np.testing.assert_allclose(out.rotation, R, atol=0.02)


@pytest.mark.slow
def test_alignment_of_a_field_that_misses_area_fits_the_moebius_map():
    """A sharp peak resampled on a coarse mesh loses most of its area, so the coarse field is centred elsewhere than
    the fine one although it is the same function: the fitted translation finds it again."""
    fine, coarse = icosphere(4), icosphere(2)
    peak = np.array([0.0, 0.6, 0.8])
    def field(x):
        return 6.0 * np.exp(-(1.0 - x @ peak) / 0.01) + 0.3 * x[:, 0]
    out = align_vertex_field(coarse, field(coarse.vertices), fine, field(fine.vertices))
    assert out.rms < 0.5 * out.centred_rms
    assert np.linalg.norm(out.translation) > 0.05


def test_eigenvalue_errors_against_the_subdivision_and_auto_numeig():
    mesh = icosphere(2)
    lam, err = eigenvalue_errors(mesh, 30)
    fine = mesh_spectrum(subdivide(mesh)[0], 30, whole_multiplets=False).eigenvalues
    np.testing.assert_allclose(err[1:], np.abs(lam[1:] - fine[1:]) / lam[1:], rtol=1e-8)
    # higher eigenvalues are resolved worse: the error grows with the degree l (l(l+1) clusters)
    assert err[25] > err[1] > 0
    K = trusted_numeig(err, 0.5 * (err[1:9].max() + err[9:16].min()))
    assert 9 <= K < 16
    assert np.all(err[1:K] <= 0.5 * (err[1:9].max() + err[9:16].min())) and err[K] > err[1:K].max()
    with pytest.raises(InvalidArgumentError, match="first eigenvalue"):
        trusted_numeig(err, 1e-30)


def test_interpolation_on_another_sphere_mesh_is_linear_on_faces():
    from shspec.mesh.refine import _Interpolant

    a = icosphere(2)
    _interpolate = lambda mesh, values, points: _Interpolant(mesh)(mesh.vertices, values, points)
    pts = icosphere(3).vertices
    # values x + 2y − z at the vertices: on each face the interpolant at a direction is Σ b_k f(p_k), b the
    # barycentric coordinates of the ray's crossing point, which is itself a linear function: f(crossing)
    vals = a.vertices @ np.array([1.0, 2.0, -1.0])
    out = _interpolate(a, vals, pts)
    # the crossing point is pts scaled by 1/(n̂·pts) of its face: f(crossing) = f(pts) × that scale
    assert np.all(np.abs(out) <= np.abs(pts @ np.array([1.0, 2.0, -1.0])) * 1.0 + 1e-12)
    np.testing.assert_allclose(_interpolate(a, vals, a.vertices), vals, atol=1e-12)
    ratio = out / (pts @ np.array([1.0, 2.0, -1.0]))
    ok = np.abs(pts @ np.array([1.0, 2.0, -1.0])) > 0.1
    assert np.all((ratio[ok] > 0.95) & (ratio[ok] <= 1.0 + 1e-12))  # the chord lies inside the sphere
