"""What a harmonic fit of a spectrum can expect before it runs: the measured record of the many-law benchmark.

The benchmark (``benchmarks/bench_many_laws.py``) fits the exact spectra of random ρ drawn from five laws that are
not the planner's (per-degree amplitude ∝ l⁻¹, l⁻¹·⁵, l⁻², one dominant degree, axisymmetric; total RMS of ρ − 1
from 0.05 to 0.3) with ``shspec fit``'s defaults on an idle 2-core machine, each stopped at its degree's goal.  A
run is a degree La and a number of eigenvalues per coefficient of ρ; :data:`MEASURED` holds every run made, and a
test checks it against the benchmark's JSON record.

A plan states the run that applies to it (:func:`expectation`): the same degree, at least as many eigenvalues per
coefficient, an exact spectrum, the default options and schedule, and the starts on at least two processes.  Where
one of these does not hold, or the degree was not measured, it says that the expectation is unknown and why:
no number is extrapolated.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Measured", "MEASURED", "expectation"]


@dataclass(frozen=True)
class Measured:
    """One run of the many-law benchmark.

    Attributes
    ----------
    degree : int
        La of the truths and of the fits.
    per_coefficient : float
        Eigenvalues given per coefficient of ρ: K = round(per_coefficient·(La + 1)²).
    truths, recovered : int
        Truths fitted, and those recovered within ``goal_s`` (per-degree power of ρ to 1e-8 relative after
        alignment).
    goal_s : float
        Where each fit was stopped (s): a truth not recovered by then counts as not recovered.
    wall_median_s, wall_p90_s : float
        Median and 90th percentile of the fits' wall times (s), stopped ones at the goal.

    Examples
    --------
    >>> from shspec.fitting.expected import Measured
    >>> print(Measured(6, 2.5, 24, 22, 120.0, 40.0, 110.0).statement())
    22 of 24 recovered within 120 s; wall time median 40 s, 90th percentile 110 s
    """

    degree: int
    per_coefficient: float
    truths: int
    recovered: int
    goal_s: float
    wall_median_s: float
    wall_p90_s: float

    def statement(self) -> str:
        return (f"{self.recovered} of {self.truths} recovered within {self.goal_s:.0f} s; wall time median "
                f"{self.wall_median_s:.0f} s, 90th percentile {self.wall_p90_s:.0f} s")


#: Every run of the many-law benchmark (``benchmarks/results/bench_many_laws.json``) on an idle 2-core machine (not
#: those with one core kept busy).
MEASURED = (Measured(6, 2.5, 24, 22, 120.0, 36.1, 77.6), Measured(6, 1.5, 10, 8, 120.0, 21.1, 59.4),
            Measured(8, 2.5, 18, 9, 300.0, 236.4, 303.2), Measured(10, 2.5, 6, 1, 720.0, 725.5, 726.1))


def expectation(degree: int, numeig: int, unlike: str | None = None) -> tuple[Measured | None, str]:
    """The benchmark run that applies to a fit of ``numeig`` eigenvalues at degree ``degree``, and the line a plan
    prints: its record, or why the expectation is unknown.

    Parameters
    ----------
    degree : int
        La of the fit.
    numeig : int
        K, the eigenvalues fitted.
    unlike : str, optional
        How the fit differs from the benchmark's (options, errors, workers), if it does: the expectation is then
        unknown for that reason.

    Returns
    -------
    (Measured or None, str)

    Examples
    --------
    >>> from shspec.fitting.expected import expectation
    >>> expectation(13, 500)[1]
    'expected success and time: unknown (the many-law benchmark has not measured degree 13)'
    """
    if unlike is not None:
        return None, f"expected success and time: unknown ({unlike})"
    runs = [m for m in MEASURED if m.degree == degree]
    if not runs:
        return None, f"expected success and time: unknown (the many-law benchmark has not measured degree {degree})"
    given = {m: int(round(m.per_coefficient * (degree + 1) ** 2)) for m in runs}  # the benchmark's K of each run
    fewer = [m for m in runs if given[m] <= numeig]
    if not fewer:
        return None, (f"expected success and time: unknown ({numeig} eigenvalues; the many-law benchmark measured "
                      f"degree {degree} with {min(given.values())} and more)")
    run = max(fewer, key=lambda m: m.per_coefficient)
    return run, (f"expected, from the many-law benchmark at degree {degree} with {run.per_coefficient:g} "
                 f"eigenvalues per coefficient (an idle 2-core machine): {run.statement()}")
