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
def interrupt_fit(monkeypatch):
    """``interrupt_fit(at)`` makes the ``at``-th step of the LM optimizer raise KeyboardInterrupt (what Ctrl-C, or
    SIGTERM as the command line turns it, raises mid-fit), and returns a call that restores the optimizer."""
    from shspec.inverse.optimize import _CLASSES

    cls = _CLASSES["lm"]
    original = cls.step

    def arm(at: int):
        calls = {"n": 0}

        def step(self):
            calls["n"] += 1
            if calls["n"] == at:
                raise KeyboardInterrupt
            original(self)

        monkeypatch.setattr(cls, "step", step)
        return lambda: monkeypatch.setattr(cls, "step", original)

    return arm


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
