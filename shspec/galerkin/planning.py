"""Before a harmonic fit: how many eigenvalues K determine ρ of degree La well enough, and the basis that resolves them.

For a reference ρ (the truth when known, else a random centred ρ drawn from the law of the fit's starts), the
relative Jacobian of the first K eigenvalues is analysed for a list of candidate K
(:func:`~shspec.inverse.identifiability.identifiability_by_numeig`, one spectrum for all of them), and the smallest K
whose noise gain g satisfies g·σ ≤ accuracy is recommended: σ is the relative error on the eigenvalues (noise of a
measured spectrum, or the residual a fit ends at) and accuracy the wanted relative L2 error of ρ.  The defaults
σ = 1e-8, accuracy = 1e-6 ask for g ≤ 100 (``shspec identifiability``); ``shspec fit`` without ``--numeig`` asks
for ρ to 1e-8 from a fit that reaches its ``residual_tol`` (1e-13), g ≤ 1e5.  For the blob at La = 15 (Lb 38,
measured): g = 1.8e6 at K = 289, 1.4e5 at 576, 9.5e4 at 704, 3.9e3 at 1024, so the fit's rule picks K = 704 for it and
the stricter default of ``shspec identifiability`` none up to 4·(La + 1)².  A random reference of degree 15 is much
better determined (g = 630 at K = 289): at a ρ whose high degrees are zero, high-degree changes move the low
eigenvalues only weakly.

The basis band limit Lb is chosen so that (Lb + 1)² ≥ 1.5 K: a margin of half again as many basis functions as
eigenvalues, with which the K-th eigenvalue of the fits here had converged (issue 12's truncation estimate).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..checks import check_float, check_int
from ..errors import InvalidArgumentError
from ..inverse.identifiability import identifiability_by_numeig
from ..sphere.factor import ConformalFactor
from ..sphere.random import random_centred_coefficients
from .solver import HarmonicModel

__all__ = ["NumeigPlan", "basis_degree_for", "candidate_numeigs", "plan_numeig"]


def basis_degree_for(numeig: int, lmax_factor: int) -> int:
    """The smallest Lb ≥ La with (Lb + 1)² ≥ 1.5·K (module notes)."""
    numeig = check_int(numeig, "numeig", minimum=2)
    lmax_factor = check_int(lmax_factor, "lmax_factor", minimum=0)
    return max(int(np.ceil(np.sqrt(1.5 * numeig))) - 1, lmax_factor)


def candidate_numeigs(lmax_factor: int) -> list[int]:
    """K values tried by default: (La + 2)², and n·f for n = (La + 1)² coefficients and f = 1.25, 1.5, …, 4."""
    la = check_int(lmax_factor, "lmax_factor", minimum=2)
    n = (la + 1) ** 2
    return sorted({(la + 2) ** 2} | {int(round(n * f)) for f in np.arange(1.25, 4.01, 0.25)})


@dataclass(frozen=True)
class NumeigPlan:
    """The recommended K and the analysis behind it.

    Attributes
    ----------
    numeig : int or None
        The smallest candidate K with noise_gain·noise ≤ accuracy (None: no candidate reaches it).
    lmax : int
        Basis band limit Lb for ``numeig`` (for the largest candidate when numeig is None).
    lmax_factor : int
    noise, accuracy : float
    rows : tuple of Identifiability
        One per candidate K, ascending.
    """

    numeig: int | None
    lmax: int
    lmax_factor: int
    noise: float
    accuracy: float
    rows: tuple

    def to_dict(self) -> dict:
        """JSON-ready, without the singular values."""
        return {"numeig": self.numeig, "lmax": self.lmax, "lmax_factor": self.lmax_factor, "noise": self.noise,
                "accuracy": self.accuracy,
                "rows": [{k: v for k, v in r.to_dict().items() if k != "singular_values"} for r in self.rows]}

    def statement(self) -> str:
        """One sentence for the console."""
        if self.numeig is None:
            best = self.rows[-1]
            return (f"no K up to {best.numeig} determines rho of degree {self.lmax_factor} to {self.accuracy:g} "
                    f"from eigenvalues accurate to {self.noise:g} (noise gain {best.noise_gain:.2g} at K = "
                    f"{best.numeig})")
        row = next(r for r in self.rows if r.numeig == self.numeig)
        return (f"K = {self.numeig} eigenvalues (basis Lb = {self.lmax}) determine rho of degree "
                f"{self.lmax_factor} with noise gain {row.noise_gain:.2g}: eigenvalues accurate to {self.noise:g} "
                f"give rho to about {row.noise_gain * self.noise:.2g} (wanted {self.accuracy:g})")


def plan_numeig(lmax_factor: int, reference=None, *, candidates=None, noise: float = 1e-8,
                accuracy: float = 1e-6, lmax: int | None = None) -> NumeigPlan:
    """Recommend K for fitting ρ of degree La (module notes).

    Parameters
    ----------
    lmax_factor : int
        La ≥ 2.
    reference : ((La + 1)²,) array or ConformalFactor, optional
        Coefficients of the reference ρ (degree ≤ La; a higher-degree one is truncated).  Default: a random centred
        ρ (seed 0) of the law of the fit's random starts.
    candidates : sequence of int, optional
        K values to analyse (default :func:`candidate_numeigs`).
    noise : float
        Relative error σ > 0 on the eigenvalues.
    accuracy : float
        Wanted relative L2 error of ρ, > 0.
    lmax : int, optional
        Basis band limit of the analysis (default :func:`basis_degree_for` the largest candidate).

    Returns
    -------
    NumeigPlan

    Raises
    ------
    InvalidArgumentError
        For bad degrees, tolerances or candidates, or a reference of the wrong size.
    """
    la = check_int(lmax_factor, "lmax_factor", minimum=2)
    noise = check_float(noise, "noise", positive=True)
    accuracy = check_float(accuracy, "accuracy", positive=True)
    ks = candidate_numeigs(la) if candidates is None else sorted({check_int(k, "candidate K", minimum=2)
                                                                  for k in candidates})
    if not ks:
        raise InvalidArgumentError("candidates must name at least one K")
    if reference is None:
        a = random_centred_coefficients(0, la, 0.2)
    else:
        factor = reference if isinstance(reference, ConformalFactor) else ConformalFactor(reference)
        a = factor.truncated(la).coefficients if factor.lmax >= la else \
            np.concatenate([factor.coefficients, np.zeros((la + 1) ** 2 - factor.coefficients.size)])
    lb = basis_degree_for(ks[-1], la) if lmax is None else check_int(lmax, "lmax", minimum=la)
    rows = tuple(identifiability_by_numeig(HarmonicModel(lb, la), a, ks))
    good = [r.numeig for r in rows if not r.underdetermined and r.noise_gain * noise <= accuracy]
    k = good[0] if good else None
    return NumeigPlan(numeig=k, lmax=basis_degree_for(k, la) if k is not None else lb, lmax_factor=la, noise=noise,
                      accuracy=accuracy, rows=rows)
