"""Helpers shared by the experiments: reference factors and figure handling."""

from __future__ import annotations

import numpy as np

from ..sphere.factor import ConformalFactor
from ..sphere.harmonics import degrees


def centred_random_factor(lmax_factor: int, amplitude: float, seed: int) -> ConformalFactor:
    """A smooth random ρ of area 4π with a_1m = 0 (Möbius-centred gauge) and coefficients decaying like 1/(1+l).

    ``amplitude`` is the RMS of the non-constant part relative to the mean; the result is checked to be positive.
    """
    rng = np.random.default_rng(seed)
    l = degrees(lmax_factor)
    a = rng.standard_normal(l.size) / (1.0 + l)
    a[l == 1] = 0.0
    a[0] = 0.0
    a *= amplitude * np.sqrt(4 * np.pi) / np.linalg.norm(a)
    a[0] = np.sqrt(4 * np.pi)
    rho = ConformalFactor(a, name=f"random(La={lmax_factor}, seed={seed})")
    rho.check_positive()
    return rho


def figure(rows: int, cols: int, width: float = 12, height: float | None = None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(rows, cols, figsize=(width, height or 4.2 * rows), squeeze=False)
    return fig, axes.ravel()


def save_figure(fig, path) -> None:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
