"""Between the optimizer and the model: the optimizer moves free variables x, the model receives parameters p(x).

    u = base with u[free] = x,      p = f(u) elementwise,   f = identity or exp,

so the gauge (which parameters are free, the others fixed at ``base``) and the transform (p = exp(u) keeps
positive parameters positive and lets them span decades) are one object, and the chain rule is applied here and
nowhere else: ∂/∂x = (∂/∂p)[..., free] · f′(u[free]).  The regularizer acts on u (on a for harmonic coefficients,
on s = log c for log factors), which the model's :meth:`~shspec.spectral_model.SpectralModel.regularizer` defines.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgumentError, NotPositiveError
from ..spectral_model import TRANSFORMS

__all__ = ["Parametrization"]


@dataclass(frozen=True)
class Parametrization:
    """Free variables x (nfree,) ↦ variables u (n,) ↦ parameters p (n,).

    Attributes
    ----------
    base : (n,) array
        The variables u at the start; the entries outside ``free`` stay fixed.
    free : (nfree,) int array
        Indices of the free variables, ascending.
    transform : {"identity", "exp"}
        p = u, or p = exp(u).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.inverse import Parametrization
    >>> p = Parametrization.at(np.array([1.0, 2.0, 3.0]), free=[0, 2])
    >>> p.nfree, p.params(np.array([5.0, 6.0]))   # entry 1 stays fixed
    (2, array([5., 2., 6.]))
    """

    base: np.ndarray
    free: np.ndarray
    transform: str = "identity"

    def __post_init__(self):
        base = np.array(self.base, dtype=float)
        free = np.asarray(self.free, dtype=np.int64)
        if base.ndim != 1:
            raise InvalidArgumentError(f"the base variables must be an (n,) array, got shape {base.shape}")
        bad = np.flatnonzero(~np.isfinite(base))
        if bad.size:
            raise InvalidArgumentError(f"the base variables must be finite; entry {bad[0]} is {base[bad[0]]}")
        if free.ndim != 1 or free.size == 0 or np.any(free < 0) or np.any(free >= base.size) \
                or np.any(np.diff(free) <= 0):
            raise InvalidArgumentError("free must be a non-empty ascending array of distinct variable indices")
        if self.transform not in TRANSFORMS:
            raise InvalidArgumentError(f"transform must be one of {TRANSFORMS}, got {self.transform!r}")
        base.setflags(write=False)
        object.__setattr__(self, "base", base)
        object.__setattr__(self, "free", free)

    @classmethod
    def at(cls, params, free, transform: str = "identity") -> "Parametrization":
        """The parametrization whose fixed parameters are those of ``params`` (n,)."""
        p = np.asarray(params, dtype=float)
        if transform == "exp":
            if np.any(p <= 0):
                raise NotPositiveError(f"log variables need positive parameters; parameter "
                                       f"{int(np.flatnonzero(p <= 0)[0])} is {p[p <= 0][0]:.3g}")
            p = np.log(p)
        return cls(p, free, transform)

    @property
    def nfree(self) -> int:
        return self.free.size

    @property
    def size(self) -> int:
        return self.base.size

    def initial(self) -> np.ndarray:
        """The free variables (nfree,) of ``base``."""
        return self.base[self.free].copy()

    def variables(self, x) -> np.ndarray:
        """u (n,) for free values x (nfree,)."""
        u = self.base.copy()
        u[self.free] = x
        return u

    def params(self, x) -> np.ndarray:
        """p (n,) for free values x (nfree,)."""
        u = self.variables(x)
        if self.transform != "exp":
            return u
        with np.errstate(over="ignore", under="ignore"):
            p = np.exp(u)
        if not np.all(np.isfinite(p) & (p > 0)):
            # a trial step of the optimizer beyond what double precision can hold: not a usable point
            bad = int(np.flatnonzero(~(np.isfinite(p) & (p > 0)))[0])
            raise NotPositiveError(f"log variable {bad} = {u[bad]:.3g} overflows or underflows exp")
        return p

    def pullback(self, x, derivative) -> np.ndarray:
        """∂/∂x from ∂/∂p: ``derivative`` of shape (..., n) (a gradient or a Jacobian's rows) → (..., nfree)."""
        d = np.asarray(derivative)[..., self.free]
        if self.transform == "exp":
            d = d * np.exp(np.asarray(x, dtype=float))
        return d
