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

The basis band limit Lb of the recommended K is the smallest at which those K eigenvalues of the reference have
converged: their largest relative change from Lb − 2 to Lb (a second solve per candidate, which a plan can afford)
is at most ``basis_tol`` (default 1e-6, the tolerance at which :func:`~shspec.galerkin.solver.spectrum` warns).  The
scan starts at (Lb + 1)² ≥ 1.5 K, the floor :func:`basis_degree_for`; the floor alone is not enough: for a random ρ
of degree 10 (amplitude 0.2, seed 1) and K = 144 its Lb = 14 leaves the eigenvalues 6e-3 off, and at Lb = 24 they
are still 6e-7 off (measured against Lb = 28); the plan's own reference (seed 0) gets Lb = 26.  The analysis itself runs at the floor of the largest candidate: singular values do not
need eigenvalues converged to 1e-6, and a converged basis for K = 4(La + 1)² would cost far more than the plan.

``shspec fit`` (:func:`plan_fit`) asks for at least :data:`SEARCH_NUMEIG_FACTOR` = 2.5 eigenvalues per coefficient
of ρ, more than identifiability needs, because more eigenvalues leave the search fewer wrong minima.  Measured at
degree 8 (random centred ρ, random starts of the fit's law, one thread each): with the 100 eigenvalues that
identifiability asks for, 2 of 4 starts recovered the truth of seed 1 and 0 of 4 that of seed 202; with 200, 4 of 4
and 1 of 4, in 17-251 s per success.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.checks import check_float, check_int
from ..errors import InvalidArgumentError
from ..gaunt.cache import get_table
from ..gaunt.table import MAX_BASIS_DEGREE
from ..galerkin.model import HarmonicModel
from ..galerkin.truncation import DEFAULT_TRUNCATION_TOL, basis_degree_for
from ..sphere.factor import ConformalFactor
from ..sphere.random import random_centred_coefficients
from ..core.threads import reproducible_call
from ..inverse.identifiability import identifiability_by_numeig
from ..inverse.options import FitOptions

__all__ = ["NumeigPlan", "converged_basis_degree", "candidate_numeigs", "plan_numeig", "plan_fit", "PLANNED_ACCURACY",
           "search_numeig", "supported_degree"]


#: Degrees of basis added per Gaunt table while :func:`converged_basis_degree` scans upwards.
_SCAN_CHUNK = 8


def converged_basis_degree(reference, numeig: int, *, tol: float = DEFAULT_TRUNCATION_TOL,
                           cache_dir=None) -> tuple[int, float]:
    """The smallest Lb ≥ :func:`basis_degree_for` at which the first K eigenvalues of ρ have converged (module
    notes).

    Parameters
    ----------
    reference : (n,) array or ConformalFactor
        Coefficients of ρ; its degree is La.
    numeig : int
        K ≥ 2.
    tol : float
        Largest accepted relative change of an eigenvalue from Lb − 2 to Lb, > 0.
    cache_dir : path-like, optional
        Where the Gaunt tables are.

    Returns
    -------
    lmax : int
        Lb.
    change : float
        The largest relative change from Lb − 2 to Lb (≤ tol).

    Raises
    ------
    InvalidArgumentError
        For bad arguments, or when the eigenvalues have not converged at the largest basis shspec supports.
    ResourceLimitError
        When the basis needed would not fit in memory.
    """
    a = _reference_coefficients(reference)
    la = int(np.sqrt(a.size)) - 1
    numeig = check_int(numeig, "numeig", minimum=2)
    tol = check_float(tol, "tol", positive=True)
    lb = basis_degree_for(numeig, la)
    table = None

    def eigenvalues(degree):
        nonlocal table
        if table is None:  # any cached table that covers it, else one of this size
            table = get_table(degree, la, cache_dir=cache_dir)
        elif degree > table.lmax:  # the scan goes on: a table a few degrees larger than needed at once
            table = get_table(min(degree + _SCAN_CHUNK, MAX_BASIS_DEGREE), la, cache_dir=cache_dir)
        return HarmonicModel(degree, la, table=table).eigenvalues(a, numeig)[1:]

    # the comparison needs Lb − 2 to hold K eigenvalues and the factor's degree
    previous = eigenvalues(lb - 2) if (lb - 1) ** 2 >= numeig and 2 * (lb - 2) >= la else None
    change = np.inf
    while lb <= MAX_BASIS_DEGREE:
        ev = eigenvalues(lb)
        if previous is not None:
            change = float(np.max(np.abs(ev / previous - 1)))
            if change <= tol:
                return lb, change
        previous, lb = ev, lb + 2
    raise InvalidArgumentError(f"the first {numeig} eigenvalues of rho (degree {la}) have not converged to {tol:g} "
                               f"at the largest basis Lb = {MAX_BASIS_DEGREE} (last change {change:.2g})")


def _reference_coefficients(reference, lmax_factor: int | None = None) -> np.ndarray:
    """The coefficients of ``reference`` (array or ConformalFactor), cut or zero-padded to degree La if given."""
    factor = reference if isinstance(reference, ConformalFactor) else ConformalFactor(reference)
    if lmax_factor is None:
        return factor.coefficients
    if factor.lmax >= lmax_factor:
        return factor.truncated(lmax_factor).coefficients
    return np.concatenate([factor.coefficients, np.zeros((lmax_factor + 1) ** 2 - factor.coefficients.size)])


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
        Basis band limit Lb at which the reference's first ``numeig`` eigenvalues have converged
        (:func:`converged_basis_degree`); the analysis basis when numeig is None.
    lmax_factor : int
    noise, accuracy : float
    rows : tuple of Identifiability
        One per candidate K, ascending.
    basis_change : float or None
        Largest relative change of those eigenvalues from Lb − 2 to Lb (None when numeig is None).
    analysis_lmax : int
        The basis of the analysis (:func:`basis_degree_for` the largest candidate, unless given).
    identified : int or None
        The K that meets the accuracy; ``numeig`` is larger where :func:`plan_fit` asks for more for its search
        (:data:`SEARCH_NUMEIG_FACTOR`).  None: equal to ``numeig``.

    Examples
    --------
    >>> from shspec.fitting import plan_numeig
    >>> plan = plan_numeig(3, noise=1e-6, accuracy=1e-3)
    >>> plan.numeig, plan.lmax, plan.lmax_factor
    (20, 11, 3)
    >>> plan.statement().split(":")[0]
    'K = 20 eigenvalues determine rho of degree 3 with noise gain 2.3e+02'
    """

    numeig: int | None
    lmax: int
    lmax_factor: int
    noise: float
    accuracy: float
    rows: tuple
    basis_change: float | None
    analysis_lmax: int
    identified: int | None = None

    def to_dict(self) -> dict:
        """JSON-ready, without the singular values."""
        return {"numeig": self.numeig, "lmax": self.lmax, "lmax_factor": self.lmax_factor, "noise": self.noise,
                "accuracy": self.accuracy, "basis_change": self.basis_change, "analysis_lmax": self.analysis_lmax,
                "identified": self.identified or self.numeig,
                "rows": [{k: v for k, v in r.to_dict().items() if k != "singular_values"} for r in self.rows]}

    def statement(self) -> str:
        """One sentence for the console."""
        if self.numeig is None:
            best = self.rows[-1]
            return (f"no K up to {best.numeig} determines rho of degree {self.lmax_factor} to {self.accuracy:g} "
                    f"from eigenvalues accurate to {self.noise:g} (noise gain {best.noise_gain:.2g} at K = "
                    f"{best.numeig})")
        k = self.identified or self.numeig
        row = next(r for r in self.rows if r.numeig == k)
        search = ("" if k == self.numeig else f"; the fit takes K = {self.numeig}, {SEARCH_NUMEIG_FACTOR:g} per "
                  "coefficient of rho, as fewer leave its search more wrong minima")
        return (f"K = {k} eigenvalues determine rho of degree {self.lmax_factor} with noise gain "
                f"{row.noise_gain:.2g}: eigenvalues accurate to {self.noise:g} give rho to about "
                f"{row.noise_gain * self.noise:.2g} (wanted {self.accuracy:g}){search}; they have converged at "
                f"basis Lb = {self.lmax} (change {self.basis_change:.1g} from Lb = {self.lmax - 2})")


def plan_numeig(lmax_factor: int, reference=None, *, candidates=None, noise: float = 1e-8,
                accuracy: float = 1e-6, lmax: int | None = None,
                basis_tol: float = DEFAULT_TRUNCATION_TOL, min_numeig: int | None = None) -> NumeigPlan:
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
    basis_tol : float
        Convergence wanted of the recommended K eigenvalues (:func:`converged_basis_degree`).
    min_numeig : int, optional
        Recommend at least this K where some candidate meets the accuracy (that K is then ``identified``); the
        basis is converged for the K recommended only.

    Returns
    -------
    NumeigPlan

    Raises
    ------
    InvalidArgumentError
        For bad degrees, tolerances or candidates, or a reference of the wrong size.

    Examples
    --------
    >>> from shspec.fitting import plan_numeig
    >>> plan = plan_numeig(3, noise=1e-6, accuracy=1e-3)   # eigenvalues to 1e-6, rho to 1e-3
    >>> plan.numeig, plan.lmax
    (20, 11)
    """
    la = check_int(lmax_factor, "lmax_factor", minimum=2)
    noise = check_float(noise, "noise", positive=True)
    accuracy = check_float(accuracy, "accuracy", positive=True)
    ks = candidate_numeigs(la) if candidates is None else sorted({check_int(k, "candidate K", minimum=2)
                                                                  for k in candidates})
    if not ks:
        raise InvalidArgumentError("candidates must name at least one K")
    a = random_centred_coefficients(0, la, 0.2) if reference is None else _reference_coefficients(reference, la)
    basis_tol = check_float(basis_tol, "basis_tol", positive=True)
    lb = basis_degree_for(ks[-1], la) if lmax is None else check_int(lmax, "lmax", minimum=la)
    rows = tuple(identifiability_by_numeig(HarmonicModel(lb, la), a, ks))
    good = [r.numeig for r in rows if not r.underdetermined and r.noise_gain * noise <= accuracy]
    k = good[0] if good else None
    identified = None
    if k is not None and min_numeig is not None and check_int(min_numeig, "min_numeig", minimum=2) > k:
        identified, k = k, min_numeig
    lmax_k, change = converged_basis_degree(a, k, tol=basis_tol) if k is not None else (lb, None)
    return NumeigPlan(numeig=k, lmax=lmax_k, lmax_factor=la, noise=noise, accuracy=accuracy, rows=rows,
                      basis_change=change, analysis_lmax=lb, identified=identified)


#: Relative L2 accuracy of ρ that the K of :func:`plan_fit` gives a fit reaching its ``residual_tol``.
PLANNED_ACCURACY = 1e-8

#: Eigenvalues per coefficient of ρ that :func:`plan_fit` asks for at least: more than identifiability needs, as the
#: extra eigenvalues take wrong minima away from the search (module notes).
SEARCH_NUMEIG_FACTOR = 2.5


def search_numeig(lmax_factor: int) -> int:
    """The fewest eigenvalues :func:`plan_fit` asks for at degree La: :data:`SEARCH_NUMEIG_FACTOR` per coefficient.

    Examples
    --------
    >>> from shspec.fitting.numeig_plan import search_numeig
    >>> search_numeig(6), search_numeig(8)
    (122, 202)
    """
    return int(round(SEARCH_NUMEIG_FACTOR * (lmax_factor + 1) ** 2))


def supported_degree(numeig: int) -> int:
    """The degree La that ``numeig`` eigenvalues support at :data:`SEARCH_NUMEIG_FACTOR` per coefficient (0 for
    fewer than a degree-1 fit would take).

    Examples
    --------
    >>> from shspec.fitting.numeig_plan import supported_degree
    >>> supported_degree(74), supported_degree(150), supported_degree(6)
    (4, 6, 0)
    """
    return max(0, int(np.sqrt(numeig / SEARCH_NUMEIG_FACTOR)) - 1)


@reproducible_call
def plan_fit(lmax_factor: int, reference=None, options: FitOptions | None = None) -> NumeigPlan:
    """The plan of ``shspec fit`` without ``--numeig``: :func:`plan_numeig` for ρ to :data:`PLANNED_ACCURACY` from
    eigenvalues accurate to the fit's ``residual_tol``, on a basis converged to its ``success_tol``, so that the
    truth itself succeeds there (the change from Lb − 2 overstates the error: at degrees 8, 10 and 12 six random
    truths were off by at most a sixth of it).  The search runs on a smaller basis and only the polish on this one
    (:attr:`~shspec.inverse.options.FitOptions.search_basis_tol`).

    Parameters
    ----------
    lmax_factor : int
        La ≥ 2.
    reference : ((La + 1)²,) array or ConformalFactor, optional
        As in :func:`plan_numeig`.
    options : FitOptions, optional
        The fit's options (default ``FitOptions()``).

    Examples
    --------
    >>> from shspec.fitting import plan_fit
    >>> plan = plan_fit(3)            # what shspec fit plans for a rho of degree 3
    >>> plan.numeig, plan.identified, plan.lmax   # 2.5 per coefficient, more than the 20 identified
    (40, 20, 17)
    """
    options = FitOptions() if options is None else options
    la = check_int(lmax_factor, "lmax_factor", minimum=2)
    # the basis is scanned for the K of the search alone (scanning it for the identified K too cost a third of the
    # plan: 9.2 s at degree 12)
    return plan_numeig(la, reference, noise=options.residual_tol, accuracy=PLANNED_ACCURACY,
                       basis_tol=options.success_tol, min_numeig=search_numeig(la))
