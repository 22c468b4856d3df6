"""Truncation of a forward solve: estimated, warned about, and named as the cause of a negative cut factor."""

import json
import warnings

import h5py
import numpy as np
import pytest

from shspec import ConformalFactor, spectrum
from shspec.cli import main
from shspec.errors import InvalidArgumentError, NotPositiveError, TruncationWarning
from shspec.galerkin.truncation import tail_bound


def _exact(k):
    l = np.repeat(np.arange(20), 2 * np.arange(20) + 1)[:k]
    return (l * (l + 1)).astype(float)


def test_an_under_resolved_boost_warns_and_a_resolved_one_does_not():
    rho = ConformalFactor.mobius_boost(5.0, 20)
    with pytest.warns(TruncationWarning, match="may be off by"):
        res = spectrum(rho, lmax=20, k=16)
    error = np.max(np.abs(res.eigenvalues[1:] - _exact(16)[1:]) / _exact(16)[1:])
    assert error > 1e-4
    # the estimate is of the right size: above the true error, not by more than a factor 100
    assert error <= res.truncation.total <= 100 * error
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ok = spectrum(ConformalFactor.mobius_boost(2.0, 30), lmax=30, k=16)
    assert ok.truncation.total < 1e-9


def test_the_dropped_degrees_are_bounded_exactly(rng):
    rho = ConformalFactor.mobius_boost(3.0, 24)
    fine, _ = rho.evaluate(200)
    cut, _ = rho.truncated(12).evaluate(200)
    assert np.abs(fine - cut).max() <= tail_bound(rho.coefficients, 12, extrapolate=False)
    res = spectrum(rho, lmax=16, k=9, lmax_factor=12, truncation_tol=None)
    assert res.truncation is None


def test_negative_because_of_truncation_says_so():
    with pytest.raises(NotPositiveError, match="truncation of a positive function"):
        spectrum(ConformalFactor.mobius_boost(20.0, 20), lmax=20, k=10)
    with pytest.raises(NotPositiveError, match="cutting it at La = 6 made it negative"):
        spectrum(ConformalFactor.mobius_boost(5.0, 30), lmax=10, k=10, lmax_factor=6)
    a = np.zeros(4)
    a[0], a[2] = np.sqrt(4 * np.pi), 3.0  # a genuinely negative degree-1 rho: no truncation involved
    with pytest.raises(NotPositiveError) as err:
        spectrum(a, lmax=4, k=4)
    assert "truncation" not in str(err.value) and "cutting" not in str(err.value)


def test_strings_are_refused_with_a_shspec_error():
    with pytest.raises(InvalidArgumentError, match="rho must be"):
        spectrum("abc", lmax=4, k=4)
    with pytest.raises(InvalidArgumentError, match="rho must be"):
        spectrum(["1", "x"], lmax=4, k=4)


@pytest.mark.parametrize("args, message", [
    (["--lmax", "0"], "--lmax must be >= 1, got 0"),
    (["--lmax", "-3"], "--lmax must be >= 1, got -3"),
    (["--lmax", "8", "--lmax-factor", "40"], "2*--lmax = 16"),
    (["--lmax", "1000"], "the limit is 400"),
    (["--out", "x.txt"], "must end in .json or .h5"),
])
def test_forward_band_limits_are_checked_like_the_library(args, message, capsys):
    assert main(["forward", *args]) == 1
    assert message in capsys.readouterr().err


def test_forward_warns_in_one_line_and_saves_its_input(tmp_path, capsys):
    out = tmp_path / "s.h5"
    assert main(["forward", "--rho", "boost:5", "--lmax", "20", "--numeig", "10", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    warned = [line for line in err.splitlines() if "warning" in line]
    assert len(warned) == 1 and "off by" in warned[0] and "Traceback" not in err
    rho = ConformalFactor.mobius_boost(5.0, 20, (0, 0, 1))
    with h5py.File(out, "r") as f:
        np.testing.assert_array_equal(f["rho_coefficients"][...], rho.coefficients)
        assert f.attrs["truncation_error_basis"] > 1e-4
    js = tmp_path / "s.json"
    assert main(["forward", "--lmax", "8", "--numeig", "4", "--out", str(js)]) == 0
    record = json.loads(js.read_text())
    assert len(record["rho_coefficients"]) == 81 and record["truncation_error_factor"] == 0.0


def test_the_warning_names_the_band_limit_to_raise_and_to_what():
    rho = ConformalFactor.mobius_boost(2.0, lmax=30)
    with pytest.warns(TruncationWarning, match=r"between the bases of degree 10 and 12: raise lmax above 12"):
        spectrum(rho, lmax=12, k=25)
    with pytest.warns(TruncationWarning, match=r"cutting rho at degree 8 .* raise lmax_factor from 8 to 30"):
        spectrum(rho, lmax=30, k=25, lmax_factor=8)
