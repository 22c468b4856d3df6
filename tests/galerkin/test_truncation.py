"""Truncation of a forward solve: estimated, warned about, and named as the cause of a negative cut factor."""

import json
import re
import warnings

import h5py
import numpy as np
import pytest

from shspec import ConformalFactor, spectrum
from shspec.cli import main
from shspec.errors import InvalidArgumentError, NotPositiveError, TruncationWarning
from shspec.galerkin.model import HarmonicModel
from shspec.galerkin.truncation import _outer_projection, basis_truncation, tail_bound
from shspec.sphere.grid import evaluate_on_grid
from shspec.sphere.harmonics import ncoeffs


def _exact(k):
    l = np.repeat(np.arange(20), 2 * np.arange(20) + 1)[:k]
    return (l * (l + 1)).astype(float)


def _error(res):
    """max relative error of the nonzero eigenvalues of a boost against l(l+1)."""
    k = res.eigenvalues.size
    return np.max(np.abs(res.eigenvalues[1:] - _exact(k)[1:]) / _exact(k)[1:])


@pytest.mark.parametrize("k", [10, 16])
def test_an_under_resolved_boost_warns_and_a_resolved_one_does_not(k):
    rho = ConformalFactor.mobius_boost(5.0, 20)
    with pytest.warns(TruncationWarning, match="may be off by"):
        res = spectrum(rho, lmax=20, k=k)
    error = _error(res)
    assert error > 1e-3
    # the estimate is of the right size: within a factor 3 of the true error
    assert error / 3 <= res.truncation.total <= 3 * error
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


def test_a_deeply_negative_rho_is_not_called_a_truncation():
    """Issue 50, item 25: coefficients up to degree 3 whose top degree is 0 look undecayed, and this rho, negative
    by 15 % of its maximum, was called "probably the truncation of a positive function"."""
    a = np.zeros(16)
    a[0], a[6] = 1.0, 1.5
    with pytest.raises(NotPositiveError, match="rho is negative there") as err:
        spectrum(a, lmax=8, k=4)
    assert "truncation of a positive function, not" not in str(err.value)


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
    with pytest.warns(TruncationWarning, match=r"degrees 13 and 14\): raise lmax from 12 to about (\d+)") as caught:
        spectrum(rho, lmax=12, k=25)
    wanted = int(re.search(r"to about (\d+)", str(caught[0].message)).group(1))
    assert 12 < wanted <= 20
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the degree named is enough
        spectrum(rho, lmax=wanted, k=25)
    with pytest.warns(TruncationWarning, match=r"cutting rho at degree 8 .* raise lmax_factor from 8 to 30"):
        spectrum(rho, lmax=30, k=25, lmax_factor=8)


@pytest.mark.parametrize("lmax, k", [(16, 16), (20, 36), (24, 16)])
def test_the_basis_estimate_is_the_size_of_the_true_error(lmax, k):
    # a boost on a tilted axis (every order m present), expanded far enough that its own truncation is negligible:
    # the eigenvalues are l(l+1), so the error of the basis is known exactly
    rho = ConformalFactor.mobius_boost(3.0, 30, axis=(0.3, -0.5, 0.81))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TruncationWarning)
        res = spectrum(rho, lmax=lmax, k=k)
    error = _error(res)
    assert error > 1e-9
    assert error / 3 <= res.truncation.basis <= 3 * error


def test_the_outer_projection_is_the_mass_matrix_beyond_the_basis():
    # (ρv) on the degrees Lb+1, Lb+2 by quadrature equals the rows of a larger basis' mass matrix
    rho = ConformalFactor.mobius_boost(3.0, 6, axis=(0.3, -0.5, 0.81))
    vecs = np.random.default_rng(1).standard_normal((ncoeffs(8), 70))  # two blocks of columns, the last narrower
    projection = _outer_projection(8, 6)
    got = projection(vecs, evaluate_on_grid(rho.coefficients, projection.grid))
    mass = HarmonicModel(10, 6).mass_matrix(rho)
    np.testing.assert_allclose(got, mass[ncoeffs(8):, :ncoeffs(8)] @ vecs, rtol=0, atol=1e-13 * np.abs(got).max())


def test_basis_truncation_checks_its_arguments():
    vecs = np.eye(9)[:, :4]
    lam = np.array([0.0, 2.0, 2.0, 2.0])
    a = np.zeros(4)
    a[0] = np.sqrt(4 * np.pi)
    errors, decays = basis_truncation(lam, vecs, a)  # the unit sphere in its own basis: nothing missing
    assert errors.shape == decays.shape == (4,) and not errors.any()
    for args, message in [((lam[:3], vecs, a), "shape"), ((lam, vecs[:8], a), "rows"),
                          ((lam, vecs, np.zeros(7)), "coefficients"), ((-lam, vecs, a), ">= 0"),
                          ((lam, vecs, np.zeros(36)), "2\\*Lb"), ((lam * np.nan, vecs, a), "finite"),
                          (("abc", vecs, a), "numeric")]:
        with pytest.raises(InvalidArgumentError, match=message):
            basis_truncation(*args)
