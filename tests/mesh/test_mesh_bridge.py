"""The bridge between vertex values and harmonic coefficients, and the built-in shapes."""

from __future__ import annotations

import numpy as np
import pytest

from shspec.errors import InvalidArgumentError, MeshError
from shspec.sphere.harmonics import flat_index, vector_to_shcoeffs
from shspec.mesh.bridge import fit_harmonic
from shspec.sphere.evaluate import harmonic_matrix, points_to_angles, sample_harmonic
from shspec.mesh.shapes import BLOB_COEFFICIENTS, blob, icosphere, star_surface
from shspec.mesh.validate import validate_mesh


def test_harmonics_match_pyshtools():
    rng = np.random.default_rng(2)
    x = rng.standard_normal((40, 3))
    a = rng.standard_normal(64)
    theta, phi = points_to_angles(x)
    ref = vector_to_shcoeffs(a).expand(lat=90 - np.degrees(theta), lon=np.degrees(phi))
    np.testing.assert_allclose(sample_harmonic(a, x), ref, atol=1e-13)
    # Closed forms: Y_00 = 1/√(4π), Y_1,1 ∝ x, Y_1,-1 ∝ y, Y_1,0 ∝ z (csphase = 1: no sign flip).
    u = x / np.linalg.norm(x, axis=1)[:, None]
    Y = harmonic_matrix(x, 1)
    np.testing.assert_allclose(Y[:, 0], 1 / np.sqrt(4 * np.pi))
    np.testing.assert_allclose(Y[:, [3, 1, 2]], np.sqrt(3 / (4 * np.pi)) * u, atol=1e-15)


def test_round_trip_is_exact_for_band_limited_values():
    sphere = icosphere(4)
    rng = np.random.default_rng(7)
    a = rng.standard_normal(49) / (1 + np.arange(49))
    a[0] = 5.0
    fit = fit_harmonic(sphere, sample_harmonic(a, sphere.vertices), 6)
    np.testing.assert_allclose(fit.coefficients, a, atol=1e-12)
    assert fit.residual < 1e-13
    # Fitting to a higher band limit still recovers them, with zeros above.
    fit = fit_harmonic(sphere, sample_harmonic(a, sphere.vertices), 10)
    np.testing.assert_allclose(fit.coefficients[:49], a, atol=1e-11)
    assert np.abs(fit.coefficients[49:]).max() < 1e-11


def test_quadrature_converges_at_order_h2():
    rng = np.random.default_rng(8)
    a = rng.standard_normal(16)
    errs = []
    for s in (3, 4, 5):
        sphere = icosphere(s)
        fit = fit_harmonic(sphere, sample_harmonic(a, sphere.vertices), 3, method="quadrature")
        errs.append(np.linalg.norm(fit.coefficients - a))
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    np.testing.assert_allclose(orders, 2.0, atol=0.15)


def test_fit_reports_residual_of_out_of_band_data():
    sphere = icosphere(4)
    a = np.zeros(36)
    a[int(flat_index(5, 2))] = 1.0
    f = sample_harmonic(a, sphere.vertices)
    fit = fit_harmonic(sphere, f, 4)
    assert fit.residual > 0.99  # nothing of degree 5 is representable at degree 4


def test_fit_errors():
    sphere = icosphere(2)
    with pytest.raises(MeshError, match="unit sphere"):
        fit_harmonic(sphere.with_vertices(2 * sphere.vertices), np.ones(162), 2)
    with pytest.raises(InvalidArgumentError, match="shape"):
        fit_harmonic(sphere, np.ones(5), 2)
    with pytest.raises(InvalidArgumentError, match="at most half"):
        fit_harmonic(sphere, np.ones(162), 10)
    with pytest.raises(InvalidArgumentError, match="method"):
        fit_harmonic(sphere, np.ones(162), 2, method="spline")
    with pytest.raises(InvalidArgumentError, match="origin"):
        harmonic_matrix(np.zeros((1, 3)), 2)


def test_shapes():
    for s in range(4):
        ico = icosphere(s)
        assert ico.nvertices == 10 * 4 ** s + 2
        validate_mesh(ico)
        np.testing.assert_allclose(np.linalg.norm(ico.vertices, axis=1), 1.0, atol=1e-15)
    u = icosphere(3).vertices
    star = star_surface(3, -2, 0.7, 3)
    validate_mesh(star)
    y = harmonic_matrix(u, 3)[:, int(flat_index(3, -2))]
    np.testing.assert_allclose(np.linalg.norm(star.vertices, axis=1), 1 + 0.7 * np.abs(y), rtol=1e-14)
    b = blob(3)
    validate_mesh(b)
    r = np.linalg.norm(b.vertices, axis=1)
    expected = 1 + sum(c * harmonic_matrix(u, 4)[:, int(flat_index(l, m))] for (l, m), c in BLOB_COEFFICIENTS.items())
    np.testing.assert_allclose(r, expected, rtol=1e-14)
    assert r.min() > 0.44 and b.signed_volume() > 0
    # Asymmetric: its radial function changes under every reflection through a coordinate plane.
    def radius(points):
        Y = harmonic_matrix(points, 4)
        return 1 + sum(c * Y[:, int(flat_index(l, m))] for (l, m), c in BLOB_COEFFICIENTS.items())

    for axis in range(3):
        mirrored = u.copy()
        mirrored[:, axis] *= -1
        assert np.abs(radius(mirrored) - radius(u)).max() > 0.1
    with pytest.raises(InvalidArgumentError, match="amplitude"):
        star_surface(2, 0, -0.1)
    with pytest.raises(InvalidArgumentError, match="subdivisions"):
        icosphere(9)
