"""Targets: the built-in blob, spectrum files, Weyl's area estimate, the command-line syntax."""

from __future__ import annotations

import json

import numpy as np
import pytest

from shspec.errors import InvalidArgumentError
from shspec.sphere.rotate import mirror_coefficients, power_spectrum
from shspec.inverse.schedule import Stage, parse_schedule
from shspec.inverse.schedule import numeig_ramp
from shspec.fitting.targets import (Target, blob_factor, estimate_area, parse_target, read_spectrum)


def test_blob_is_centred_positive_asymmetric():
    b = blob_factor()
    assert b.lmax == 6 and np.all(b.coefficients[1:4] == 0)
    assert b.area == pytest.approx(4 * np.pi)
    assert 0.5 < b.minimum().value < 1.0
    # No mirror symmetry z -> -z and odd degrees present: the fit must break parity.
    assert not np.allclose(mirror_coefficients(b.coefficients), b.coefficients)
    assert power_spectrum(b.coefficients)[3] > 0


def test_estimate_area_on_spheres():
    l = np.arange(12)
    lam = np.repeat(l * (l + 1.0), 2 * l + 1)
    assert estimate_area(lam) == pytest.approx(4 * np.pi, rel=2e-2)
    assert estimate_area(lam / 3.0) == pytest.approx(12 * np.pi, rel=2e-2)


@pytest.mark.parametrize("scale", [1e-200, 1e-14, 1e14, 2e14, 1e17, 1e200])
def test_the_area_estimate_scales_with_the_spectrum(scale):
    # λ scales as 1/area; at λ ~ 1e14 lstsq's cut of small singular values dropped Weyl's constant term, and a fit's
    # random start (drawn at the estimated area) changed with the spectrum's scale
    l = np.arange(12)
    lam = np.repeat(l * (l + 1.0), 2 * l + 1)
    assert estimate_area(lam * scale) * scale == pytest.approx(estimate_area(lam), rel=1e-12)


@pytest.mark.parametrize("fmt", ["txt", "txt0", "npy", "json", "jsondict"])
def test_read_spectrum_formats(tmp_path, fmt):
    lam = np.array([2.0, 2.0, 2.0, 6.0])
    path = tmp_path / ("s." + fmt.rstrip("0").replace("jsondict", "json"))
    if fmt == "txt":
        path.write_text("# eigenvalues\n" + "\n".join(map(str, lam)) + "\n")
    elif fmt == "txt0":
        path.write_text("\n".join(map(str, [0.0, *lam])))
    elif fmt == "npy":
        np.save(path, lam)
    elif fmt == "json":
        path.write_text(json.dumps(lam.tolist()))
    else:
        path.write_text(json.dumps({"eigenvalues": lam.tolist()}))
    np.testing.assert_array_equal(read_spectrum(path), [0.0, *lam])
    t = parse_target(f"spectrum:{path}", lmax=4, numeig=5, lmax_factor=2)
    assert t.area is None and t.source == "spectrum" and type(t) is Target


def test_bad_targets(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("one\ntwo\n")
    with pytest.raises(InvalidArgumentError):
        read_spectrum(bad)
    for text in ("cube", "star:3,3", "star:a,b,c", "mesh:", 3):
        with pytest.raises(InvalidArgumentError):
            parse_target(text, lmax=4, numeig=5, lmax_factor=2)
    with pytest.raises(InvalidArgumentError):
        Target("x", np.array([1.0, 2.0]))  # no λ₀ = 0
    with pytest.raises(InvalidArgumentError):
        Target("x", np.array([0.0, 3.0, 2.0]))  # not ascending


def test_schedule_syntax():
    assert parse_schedule("2,4, 8") == (Stage(2), Stage(4), Stage(8))
    assert parse_schedule("6:16,6:120") == (Stage(6, 16), Stage(6, 120))
    assert parse_schedule("2:16, 6:64h,6") == (Stage(2, 16), Stage(6, 64, hops=True), Stage(6))
    for text in ("", "2;4", "2:3:4", "a", "6:64x", "h", "6h:64"):
        with pytest.raises(InvalidArgumentError):
            parse_schedule(text)
    assert [s.numeig for s in numeig_ramp(120)] == [16, 36, 64, 100, 120]


def test_read_spectrum_takes_the_last_column_and_names_bad_values(tmp_path):
    import warnings

    from shspec.fitting import parse_target, read_spectrum

    two = tmp_path / "two.txt"  # what `shspec mesh-spectrum M > two.txt` prints: index and eigenvalue
    two.write_text("    0  0\n    1  2.5\n    2  2.5\n    3  7\n")
    np.testing.assert_array_equal(read_spectrum(two), [0.0, 2.5, 2.5, 7.0])
    nan = tmp_path / "nan.txt"
    nan.write_text("0\n1\nnan\n3\n")
    with pytest.raises(InvalidArgumentError, match=r"nan.txt: eigenvalue 2 is nan"):
        read_spectrum(nan)
    empty = tmp_path / "empty.txt"
    empty.write_text("# nothing\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's "empty input file" warning must not leak
        with pytest.raises(InvalidArgumentError, match="empty.txt holds no eigenvalues"):
            read_spectrum(empty)
    unsorted = tmp_path / "unsorted.txt"
    unsorted.write_text("0\n2\n6\n5\n")
    with pytest.raises(InvalidArgumentError, match=r"unsorted.txt is not ascending: eigenvalue 3 \(5\)"):
        read_spectrum(unsorted)
    # --numeig is honoured for spectrum files: the first K eigenvalues, lambda_0 included
    target = parse_target(f"spectrum:{two}", lmax=8, numeig=3, lmax_factor=4)
    np.testing.assert_array_equal(target.eigenvalues, [0.0, 2.5, 2.5])
