"""Continuation from the round sphere to the target metric: the factors grow geometrically, c_t = c^t.

Growing log c linearly in t keeps every intermediate metric a conformal factor of the same shape, so each step
changes every edge length by the same relative amount (c_i c_j)^(Δt/4) and the previous solution is a good start:
the surface inflates a little at a time, along the way the pressure prior (see :mod:`shspec.embed.embed`) chooses,
instead of being asked to jump to the final shape from the sphere, where folding in is as cheap as bulging out.
:func:`~shspec.embed.embed.embed` uses the schedule's first step and then adapts the step to the strain.
"""

from __future__ import annotations

import numpy as np

from ..core.checks import check_int
from ..errors import InvalidArgumentError

__all__ = ["continuation_schedule"]


def continuation_schedule(factors, steps: int | None = None, *, max_log_step: float = 0.35) -> np.ndarray:
    """Continuation parameters 0 < t_1 < ... < t_K = 1.

    Parameters
    ----------
    factors : (n,) array
        Conformal factors c > 0 of the target.
    steps : int, optional
        Number K ≥ 1 of steps.  Default: the smallest K with max|log c − mean log c| / K ≤ ``max_log_step``, so that
        the edge lengths change by at most about e^(max_log_step/2) − 1 (≈ 19 %) relative to each other per step.
    max_log_step : float
        Largest change of the centred log-factor per step, used when ``steps`` is None.

    Returns
    -------
    (K,) array
        t_k = k / K.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.embed import continuation_schedule
    >>> schedule = continuation_schedule(np.array([1.0, 10.0, 100.0]))   # exponents t: the factors grow as c**t
    >>> float(schedule[-1]), bool(np.all(np.diff(schedule) > 0))
    (1.0, True)
    """
    c = np.asarray(factors, dtype=float)
    if c.ndim != 1 or c.size == 0 or not np.all(np.isfinite(c)) or np.any(c <= 0):
        raise InvalidArgumentError("factors must be a non-empty (n,) array of finite values > 0")
    if steps is None:
        if not (np.isfinite(max_log_step) and max_log_step > 0):
            raise InvalidArgumentError(f"max_log_step must be finite and > 0, got {max_log_step}")
        u = np.log(c)
        steps = max(1, int(np.ceil(np.max(np.abs(u - u.mean())) / max_log_step)))
    steps = check_int(steps, "steps", minimum=1)
    return np.arange(1, steps + 1) / steps
