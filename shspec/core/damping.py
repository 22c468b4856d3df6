"""The damping update of Levenberg–Marquardt trust regions (Nielsen's rule), shared by every LM loop in shspec.

After a trial step δ with gain ratio ϱ = (actual decrease) / (decrease predicted by the quadratic model):

* accepted (ϱ > 0): μ ← μ · max(1/3, 1 − (2ϱ − 1)³) and ν ← 2.  A very good step (ϱ → 1) shrinks μ threefold, a
  barely useful one (ϱ → 0) keeps it almost unchanged (the factor tends to 2 only at ϱ = 0, then clipped by the
  smooth cubic), so μ does not oscillate as with the classic "×10 / ÷10" rule.
* rejected (ϱ <= 0, or no step at all, e.g. a failed factorization, passed as ϱ = NaN or −inf): μ ← μ · ν and
  ν ← 2ν, so consecutive rejections grow μ geometrically faster (2, 8, 64, … times).

H. B. Nielsen, "Damping parameter in Marquardt's method", IMM-REP-1999-05, DTU (1999); K. Madsen, H. B. Nielsen,
O. Tingleff, "Methods for non-linear least squares problems", 2nd ed., DTU (2004), §3.2.
"""

from __future__ import annotations

import math

from ..errors import InvalidArgumentError

__all__ = ["nielsen_update"]


def nielsen_update(mu: float, nu: float, gain: float, *, floor: float = 0.0,
                   ceiling: float = math.inf) -> tuple[float, float]:
    """Nielsen's update of the damping μ and its growth factor ν after a step of gain ratio ``gain``.

    Parameters
    ----------
    mu : float
        Current damping μ > 0.
    nu : float
        Current growth factor ν >= 1 of a rejection (2 after every accepted step).
    gain : float
        Gain ratio ϱ of the trial step; ϱ > 0 means accepted, anything else (NaN included) rejected.
    floor, ceiling : float
        μ is kept in [floor, ceiling].

    Returns
    -------
    (mu, nu) : tuple of float
        The new damping and growth factor.
    """
    if not (mu > 0 and math.isfinite(mu)):
        raise InvalidArgumentError(f"the damping mu must be finite and > 0, got {mu!r}")
    if not nu >= 1:
        raise InvalidArgumentError(f"the growth factor nu must be >= 1, got {nu!r}")
    if gain > 0:
        # ϱ ≥ 1 gives the factor 1/3 already; the clip keeps the cube finite for the huge ϱ of an accelerated step
        # whose predicted decrease is tiny
        return max(floor, mu * max(1.0 / 3.0, 1.0 - (2.0 * min(gain, 1.0) - 1.0) ** 3)), 2.0
    return min(ceiling, mu * nu), 2.0 * nu
