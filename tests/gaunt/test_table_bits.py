"""Gaunt tables give the same bits whichever table they come from, and damaged tables are never used (issue 34)."""

from __future__ import annotations

import warnings

import h5py
import numpy as np
import pytest

from shspec.cli import main
from shspec.errors import CorruptTableError
from shspec.galerkin import spectrum
from shspec.gaunt import build_table, list_tables, load_table, save_table, verify_table
from shspec.gaunt.cache import _checksum
from shspec.sphere import ConformalFactor


@pytest.mark.parametrize("big", [(30, 30), (20, 10)])
def test_restricted_table_is_bit_identical_to_a_direct_build(tmp_path, big):
    # a family truncated at La = 6 used to take the forward recursion, and the same family of the larger table the
    # two-sided one, so the (10, 6) values depended on which table was cached (4.4e-16 apart)
    table = build_table(*big)
    assert verify_table(table, 1000) < 2e-15  # values before the forward sweep stops are forward values now
    save_table(table, tmp_path)
    restricted = load_table(10, 6, tmp_path)
    assert restricted.metadata["restricted_from"] == list(big)
    direct = build_table(10, 6)
    assert np.array_equal(restricted.values, direct.values)

    rng = np.random.default_rng(3)
    a = np.zeros(49)
    a[0] = np.sqrt(4 * np.pi)
    a[1:] = 0.05 * rng.standard_normal(48)
    rho = ConformalFactor(a)
    from_cache = spectrum(rho, 10, 30, lmax_factor=6, cache_dir=tmp_path, truncation_tol=None).eigenvalues
    from_direct = spectrum(rho, 10, 30, lmax_factor=6, table=direct, truncation_tol=None).eigenvalues
    assert np.array_equal(from_cache, from_direct)


def _damage(path, how):
    with h5py.File(path, "r+") as f:
        if how == "group":
            del f["values"]
            f.create_group("values")
        else:
            values = f["values"][...]
            values[7] = np.nan
            f["values"][...] = values
            f.attrs["checksum"] = _checksum(values)  # as if written so: the checksum matches


@pytest.mark.parametrize("how", ["group", "nan"])
def test_a_damaged_table_is_named_everywhere_and_never_used(tmp_path, capsys, how):
    path = save_table(build_table(10, 6), tmp_path)
    _damage(path, how)
    expected = "instead of a dataset" if how == "group" else "NaN or inf"
    with pytest.raises(CorruptTableError, match=expected):
        load_table(10, 6, tmp_path)
    with warnings.catch_warnings(), pytest.raises(FileNotFoundError):
        warnings.simplefilter("ignore")  # the NaN table is skipped with a warning, the group one by list_tables
        load_table(8, 4, tmp_path)  # the damaged larger table is never restricted: nothing covers (8, 4)
    [info] = list_tables(tmp_path, verify=True)
    assert expected in info.problem
    capsys.readouterr()
    assert main(["precompute", "list", "--cache-dir", str(tmp_path)]) == 0
    assert "PROBLEM" in capsys.readouterr().out
    assert main(["precompute", "verify", "--lmax", "10", "--lmax-factor", "6", "--cache-dir", str(tmp_path)]) == 1
    assert expected in capsys.readouterr().err
    assert main(["forward", "--lmax", "10", "--lmax-factor", "6", "--numeig", "5", "--cache-dir", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err
