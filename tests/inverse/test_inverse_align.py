"""Alignment up to O(3): rotations and reflections are found to rounding; power spectra are invariant."""

from __future__ import annotations

import numpy as np
import pytest

from shspec import ConformalFactor
from shspec.errors import InvalidArgumentError
from shspec.inverse.align import align
from shspec.sphere.rotate import mirror_coefficients, power_spectrum, rotate_coefficients


def _centred(seed, la=5):
    rng = np.random.default_rng(seed)
    a = 0.1 * rng.standard_normal((la + 1) ** 2)
    a[0] = np.sqrt(4 * np.pi)
    a[1:4] = 0.0
    return a


def test_rotation_matches_pyshtools_and_keeps_power():
    a = _centred(1)
    b = rotate_coefficients(a, [0.3, 1.1, -2.0])
    ref = ConformalFactor(a).to_shcoeffs().rotate(0.3, 1.1, -2.0, degrees=False, body=False).coeffs
    from shspec.sphere.harmonics import cilm_to_vector

    np.testing.assert_allclose(b, cilm_to_vector(ref), atol=1e-13)
    np.testing.assert_allclose(power_spectrum(b), power_spectrum(a), rtol=1e-12)
    np.testing.assert_allclose(power_spectrum(mirror_coefficients(a)), power_spectrum(a), rtol=1e-15)


def test_mirror_is_z_reflection():
    a = _centred(2)
    f, g = ConformalFactor(a), ConformalFactor(mirror_coefficients(a))
    vf, _ = f.evaluate(16)
    vg, _ = g.evaluate(16)
    # The GLQ latitudes are symmetric about the equator, so z -> -z reverses the rows.
    np.testing.assert_allclose(vg, vf[::-1], atol=1e-12)


@pytest.mark.parametrize("mirrored", [False, True])
def test_align_recovers_rotations_and_reflections(mirrored):
    a = _centred(3)
    b = rotate_coefficients(a, [2.3, 0.7, -1.0])
    if mirrored:
        b = mirror_coefficients(b)
    result = align(a, b)
    assert result.mirrored == mirrored
    assert result.relative_error < 1e-10
    assert result.power_error < 1e-12


def test_align_reports_a_real_difference():
    a, b = _centred(4), _centred(5)
    result = align(a, b)
    assert result.relative_error > 1e-2
    assert result.power.shape == (6, 2)


def test_align_centres_uncentred_factors():
    a = _centred(6, 4)
    boosted = a.copy()
    boosted[2] = 0.3  # a_10: off centre
    result = align(boosted, a)
    assert np.max(np.abs(result.reference[1:4])) < 1e-10
    assert np.max(np.abs(result.aligned[1:4])) < 1e-10


def test_align_rejects_zero():
    with pytest.raises(InvalidArgumentError):
        align(np.zeros(4), _centred(7, 1), center=False)
    with pytest.raises(InvalidArgumentError):
        rotate_coefficients(_centred(7), [1.0, 2.0])
