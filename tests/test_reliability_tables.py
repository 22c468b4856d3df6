"""Gaunt tables give the same bits whichever table they come from, and damaged tables are never used (issue 34)."""

from __future__ import annotations

import numpy as np
import pytest

from shspec.galerkin import spectrum
from shspec.gaunt import build_table, load_table, save_table, verify_table
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
