"""What a fit is aimed at: a target spectrum, its errors, and the truth when known.

:class:`Target` is all the inverse solver sees of a target.  A mesh's targets add its cMCF (the
:class:`~shspec.fitting.targets.MeshTarget` of :mod:`shspec.fitting.targets`, where the builders of targets live);
the solver reaches what they add only through :meth:`Target.factor_samples`.

Area.  A spectrum fixes the area through Weyl's law; :func:`estimate_area` fits the counting function
N(λ) ≈ Aλ/(4π) + c to the target, which is exact on the round sphere (N = (l+1)² at the top of each multiplet, l² + 1
at its bottom: their mean is λ + 1 + ... ) and good to a few per cent on smooth surfaces.  When the truth is known
its area is used instead.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..core.checks import check_float, check_int, real_array
from ..errors import InvalidArgumentError
from ..sphere.factor import ConformalFactor

__all__ = ["Target", "estimate_area"]


@dataclass(frozen=True)
class Target:
    """A target spectrum and what is known about it.

    Attributes
    ----------
    name : str
    eigenvalues : (k,) array
        λ*₀ = 0 first, ascending (1/area).
    area : float or None
        The true area when known.
    truth : ConformalFactor or None
        The true harmonic ρ (for a mesh: its centred cMCF factors expanded to degree La).
    errors : (k,) array or None
        The target's own error: the absolute one-sigma uncertainty of each eigenvalue (measurement noise, a mesh's
        discretization error); entry 0 is ignored (λ₀ = 0 exactly).  When known, a fit weighs eigenvalue i by
        1/σ_i², succeeds when its residuals are consistent with them, and reports the error bar they leave on ρ.
        None: the eigenvalues are taken as exact (to :attr:`~shspec.inverse.FitOptions.success_tol`).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.inverse import Target
    >>> l = np.repeat(np.arange(4), 2 * np.arange(4) + 1)
    >>> t = Target("round", l * (l + 1.0))
    >>> t.numeig, t.source, round(t.area_estimate() / (4 * np.pi), 1)
    (16, 'spectrum', 1.0)
    >>> t.with_noise(1e-3).errors[:3]
    array([0.   , 0.002, 0.002])
    """

    name: str
    eigenvalues: np.ndarray
    area: float | None = None
    truth: ConformalFactor | None = None
    errors: np.ndarray | None = dataclasses.field(default=None, repr=False)

    def __post_init__(self):
        if not isinstance(self.name, str):
            raise InvalidArgumentError(f"a target's name is a string, got {self.name!r}")
        lam = real_array(self.eigenvalues, "a target's eigenvalues")
        if lam.ndim != 1 or lam.size < 2:
            raise InvalidArgumentError(f"a target needs a (k,) spectrum with k >= 2, got shape {lam.shape}")
        bad = np.flatnonzero(~np.isfinite(lam))
        if bad.size:
            raise InvalidArgumentError(f"a target's eigenvalue {bad[0]} is {lam[bad[0]]}; every one must be finite")
        if abs(lam[0]) > 1e-8 * lam[-1] or np.any(lam[1:] <= 0) or np.any(np.diff(lam) < -1e-12 * lam[-1]):
            raise InvalidArgumentError("a target spectrum must start with λ₀ = 0 and ascend through positive values")
        object.__setattr__(self, "eigenvalues", lam)
        if self.truth is not None and not isinstance(self.truth, ConformalFactor):
            raise InvalidArgumentError(f"a target's truth is a ConformalFactor, got {type(self.truth).__name__}")
        if self.errors is not None:
            err = real_array(self.errors, "a target's errors")
            if err.shape != lam.shape:
                raise InvalidArgumentError(f"a target's errors must have the shape of its eigenvalues {lam.shape}, got "
                                           f"{err.shape}")
            bad = np.flatnonzero(~(np.isfinite(err[1:]) & (err[1:] > 0)))
            if bad.size:
                raise InvalidArgumentError(f"the error of eigenvalue {bad[0] + 1} is {err[bad[0] + 1]}; every error "
                                           "after lambda_0 must be finite and > 0")
            err = err.copy()
            err[0] = 0.0
            object.__setattr__(self, "errors", err)

    @property
    def source(self) -> str:
        """Where the eigenvalues come from: "harmonic" (the Galerkin spectrum of a known ρ) or "spectrum" (given
        values, truth unknown); a mesh target says which of its spectra it is."""
        return "harmonic" if self.truth is not None else "spectrum"

    def first(self, k: int) -> "Target":
        """The target cut to its first ``k`` eigenvalues (and their errors)."""
        k = check_int(k, "k", minimum=2, maximum=self.numeig)
        return dataclasses.replace(self, eigenvalues=self.eigenvalues[:k],
                                   errors=None if self.errors is None else self.errors[:k])

    def with_noise(self, relative: float) -> "Target":
        """The target with the error σ_i = ``relative``·λ_i of every eigenvalue (``shspec fit --noise``)."""
        relative = check_float(relative, "the relative noise", positive=True)
        return dataclasses.replace(self, errors=relative * self.eigenvalues)

    @property
    def numeig(self) -> int:
        return self.eigenvalues.size

    def area_estimate(self) -> float:
        """The true area if known, else Weyl's estimate from the spectrum (:func:`estimate_area`)."""
        return self.area if self.area is not None else estimate_area(self.eigenvalues)

    def factor_samples(self) -> tuple | None:
        """Per-vertex truth of a mesh target: (points (n, 3) on the unit sphere, area weights (n,), factors (n,)),
        or None (a spectrum's target has none)."""
        return None


def estimate_area(eigenvalues) -> float:
    """Area from a spectrum (k,) by least squares on Weyl's law N(λ_n) ≈ Aλ_n/(4π) + c (module notes).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.inverse import estimate_area
    >>> l = np.repeat(np.arange(8), 2 * np.arange(8) + 1)
    >>> round(estimate_area(l * (l + 1.0)) / (4 * np.pi), 2)   # the unit sphere
    1.0
    """
    lam = np.asarray(eigenvalues, dtype=float)
    if lam.ndim != 1 or lam.size < 4 or np.any(lam[1:] <= 0):
        raise InvalidArgumentError("estimating the area needs at least 4 eigenvalues, λ₀ = 0 and the rest > 0")
    n = np.arange(lam.size) + 0.5
    # the λ column in units of its largest entry: with λ ~ 1e14 and a column of ones, lstsq's default cut of small
    # singular values dropped the constant and the area changed with the spectrum's scale
    unit = lam[-1] / (4 * np.pi)
    design = np.stack([lam[1:] / (4 * np.pi * unit), np.ones(lam.size - 1)], 1)
    coef = np.linalg.lstsq(design, n[1:], rcond=None)[0]
    if not coef[0] > 0:
        raise InvalidArgumentError("the spectrum does not grow like Weyl's law; cannot estimate the area")
    return float(coef[0] / unit)
