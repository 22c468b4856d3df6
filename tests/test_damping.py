"""Nielsen's damping update (shspec.core.damping), shared by every Levenberg–Marquardt loop."""

from __future__ import annotations

import math
import warnings

import pytest

from shspec.core.damping import nielsen_update
from shspec.errors import InvalidArgumentError


def test_accepted_steps_shrink_the_damping_by_the_cubic_rule():
    assert nielsen_update(1.0, 8.0, 0.5) == (1.0, 2.0)            # 1 − 0³: a half-good step keeps μ
    assert nielsen_update(1.0, 2.0, 1.0) == (pytest.approx(1 / 3), 2.0)
    assert nielsen_update(1.0, 2.0, 0.25)[0] == pytest.approx(1.125)  # 1 − (−0.5)³
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a huge gain (accelerated step, tiny prediction) must not overflow
        assert nielsen_update(1.0, 2.0, 1e300) == (pytest.approx(1 / 3), 2.0)
    assert nielsen_update(1e-20, 2.0, 1.0, floor=1e-18)[0] == 1e-18


def test_rejected_steps_grow_the_damping_geometrically():
    mu, nu = 1.0, 2.0
    for expected in (2.0, 8.0, 64.0):
        mu, nu = nielsen_update(mu, nu, float("nan"))
        assert mu == expected
    assert nielsen_update(1.0, 2.0, -1.0, ceiling=1.5) == (1.5, 4.0)
    with pytest.raises(InvalidArgumentError):
        nielsen_update(0.0, 2.0, 1.0)
    with pytest.raises(InvalidArgumentError):
        nielsen_update(math.inf, 2.0, 1.0)
    with pytest.raises(InvalidArgumentError):
        nielsen_update(1.0, 0.5, 1.0)
