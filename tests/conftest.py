"""Shared fixtures.  Every test run gets its own table cache, so tests never touch the user cache (~/.cache/shspec)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

from shspec.mesh.builtin import builtin_mesh_path

_CACHE = tempfile.mkdtemp(prefix="shspec-test-cache-")
os.environ["SHSPEC_CACHE"] = _CACHE



@pytest.fixture(scope="session")
def cache_dir() -> Path:
    """The session's table cache (also in $SHSPEC_CACHE)."""
    return Path(_CACHE)


@pytest.fixture(scope="session")
def shared_meshes() -> Path:
    """The folder of the genus-0 test meshes shipped with shspec (bunny, spot, blub at 600, 1200 and full size)."""
    return builtin_mesh_path("bunny").parent


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


def random_factor_coefficients(rng: np.random.Generator, lmax: int, amplitude: float = 0.08,
                               decay: float = 1.0) -> np.ndarray:
    """Coefficients of a smooth, clearly positive random ρ of area 4π (amplitude of the non-constant part)."""
    n = (lmax + 1) ** 2
    l = np.repeat(np.arange(lmax + 1), 2 * np.arange(lmax + 1) + 1)
    a = rng.standard_normal(n) * amplitude / (1.0 + l) ** decay
    a[0] = np.sqrt(4 * np.pi)
    return a
