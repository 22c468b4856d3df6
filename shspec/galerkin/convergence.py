"""Convergence studies of the Galerkin spectrum: in the basis band limit Lb, and in the band limit La of ρ.

Galerkin eigenvalues approach the true ones from above and, for smooth ρ, exponentially fast in Lb: the error of an
eigenvalue behaves like C·exp(−r·Lb).  :func:`convergence` measures the change of each eigenvalue against the finest
basis and fits the rate r per eigenvalue group (the groups are the multiplets of the round sphere: indices l², …,
(l+1)² − 1 form group l).  The same can be done in La (how many coefficients of ρ matter).  The piecewise-linear
spectrum of a sphere mesh carrying ρ converges from below
(:func:`~shspec.mesh.factor_spectrum.pl_spectrum_of_factor`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InvalidArgumentError
from ..sphere.factor import as_factor
from ..sphere.harmonics import check_degree
from .model import HarmonicModel

__all__ = ["ConvergenceStudy", "convergence", "convergence_in_factor"]


@dataclass
class ConvergenceStudy:
    """Eigenvalues for a sequence of band limits and their convergence.

    Attributes
    ----------
    parameter : str
        ``"lmax"`` (the basis band limit varies) or ``"lmax_factor"`` (ρ is truncated).
    values : (n,) int array
        The band limits, ascending; the last one is the reference.
    eigenvalues : (n, k) float array
        λ for each band limit (λ₀ = 0 included).
    fixed : int
        The band limit held fixed (La when Lb varies, Lb when La varies).
    pl_eigenvalues : dict[str, (k,) array]
        Optional piecewise-linear spectra to show beside (label -> eigenvalues).
    """

    parameter: str
    values: np.ndarray
    eigenvalues: np.ndarray
    fixed: int
    pl_eigenvalues: dict = field(default_factory=dict)

    @property
    def reference(self) -> np.ndarray:
        """(k,) eigenvalues at the largest band limit."""
        return self.eigenvalues[-1]

    @property
    def change(self) -> np.ndarray:
        """(n, k) relative change |λ(L) − λ(L_max)| / λ(L_max) (0 for λ₀)."""
        ref = self.reference
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.abs(self.eigenvalues - ref[None, :]) / np.where(ref > 0, ref, np.inf)[None, :]
        return rel

    def groups(self) -> list[tuple[int, slice]]:
        """(l, index slice) of the round-sphere multiplets covered by the k eigenvalues (λ₀ excluded)."""
        k = self.eigenvalues.shape[1]
        out = []
        l = 1
        while l * l < k:
            out.append((l, slice(l * l, min((l + 1) ** 2, k))))
            l += 1
        return out

    def group_change(self) -> np.ndarray:
        """(n, g) largest relative change within each multiplet group."""
        rel = self.change
        return np.stack([rel[:, s].max(axis=1) for _, s in self.groups()], axis=1)

    def rates(self, floor: float = 1e-13) -> np.ndarray:
        """(g,) fitted exponential rate r per group (change ~ exp(−r·L)), from the points above ``floor``.

        NaN where fewer than two points lie above the floor (converged to round-off, or too few band limits).
        """
        change = self.group_change()[:-1]
        x = self.values[:-1].astype(float)
        out = np.full(change.shape[1], np.nan)
        for g in range(change.shape[1]):
            ok = change[:, g] > floor
            if ok.sum() >= 2:
                out[g] = -np.polyfit(x[ok], np.log(change[ok, g]), 1)[0]
        return out

    def table(self) -> list[dict]:
        """Rows for CSV/JSON: one per band limit, with the largest change over all eigenvalues and per group."""
        rows = []
        gc = self.group_change()
        for n, value in enumerate(self.values):
            row = {self.parameter: int(value), "max_relative_change": float(np.nanmax(self.change[n, 1:]))}
            for (l, _), c in zip(self.groups(), gc[n]):
                row[f"group_l{l}"] = float(c)
            rows.append(row)
        return rows

    def plot(self, ax=None):
        """Log relative change against the band limit, one line per multiplet group; returns the Axes."""
        import matplotlib.pyplot as plt

        if ax is None:
            ax = plt.figure(figsize=(7, 4.5)).add_subplot(111)
        gc = self.group_change()[:-1]
        x = self.values[:-1]
        cmap = plt.get_cmap("viridis")
        groups = self.groups()
        for g, (l, _) in enumerate(groups):
            ax.semilogy(x, np.maximum(gc[:, g], 1e-17), "o-", color=cmap(g / max(len(groups) - 1, 1)), ms=3,
                        label=f"group l={l}")
        ax.set_xlabel("basis band limit Lb" if self.parameter == "lmax" else "factor band limit La")
        ax.set_ylabel(f"relative change vs {self.parameter}={self.values[-1]}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
        return ax

    def plot_spectra(self, ax=None):
        """Eigenvalues against their index for each band limit, with PL spectra if any; returns the Axes."""
        import matplotlib.pyplot as plt

        if ax is None:
            ax = plt.figure(figsize=(7, 4.5)).add_subplot(111)
        idx = np.arange(self.eigenvalues.shape[1])
        for value, lam in zip(self.values, self.eigenvalues):
            ax.plot(idx, lam, ".-", ms=3, lw=0.8, label=f"harmonic {self.parameter}={value}")
        for label, lam in self.pl_eigenvalues.items():
            ax.plot(idx[: lam.size], lam[: idx.size], "k--", lw=0.8, label=label)
        ax.set_xlabel("index i")
        ax.set_ylabel("eigenvalue")
        ax.legend(fontsize=7)
        ax.grid(True, alpha=0.3)
        return ax


def _check_values(values, name: str) -> np.ndarray:
    vals = sorted({check_degree(v, name) for v in np.atleast_1d(values).tolist()})
    if len(vals) < 2:
        raise InvalidArgumentError(f"a convergence study needs at least two distinct {name} values, got {values!r}")
    return np.array(vals)


def convergence(rho, lmax_values, k: int, *, lmax_factor: int | None = None, cache_dir=None) -> ConvergenceStudy:
    """Spectra of ρ for each basis band limit Lb in ``lmax_values`` (the largest is the reference).

    Parameters
    ----------
    rho : ConformalFactor or coefficients (flat, cilm, SHCoeffs)
    lmax_values : sequence of int
        Basis band limits; k <= (min Lb + 1)**2.
    k : int
        Eigenvalues per spectrum.
    lmax_factor : int, optional
        Truncate ρ to this La (default: its band limit, capped at 2·min(Lb)).

    Examples
    --------
    >>> from shspec import ConformalFactor, convergence
    >>> study = convergence(ConformalFactor.mobius_boost(2.0, lmax=16), [8, 12, 16], k=9)
    >>> [row["lmax"] for row in study.table()]
    [8, 12, 16]
    """
    factor = as_factor(rho)
    values = _check_values(lmax_values, "lmax")
    la = factor.lmax if lmax_factor is None else check_degree(lmax_factor, "lmax_factor")
    la = min(la, 2 * int(values[0]))
    factor = factor.truncated(la)
    big = HarmonicModel(int(values[-1]), la, cache_dir=cache_dir)
    lams = np.array([HarmonicModel(int(lb), la, table=big.table).spectrum(factor, k).eigenvalues for lb in values])
    return ConvergenceStudy("lmax", values, lams, la)


def convergence_in_factor(rho, lmax_factor_values, lmax: int, k: int, *, cache_dir=None) -> ConvergenceStudy:
    """Spectra at a fixed basis Lb of ρ truncated to each La in ``lmax_factor_values`` (the largest is the reference).

    This measures how many coefficients of ρ the first k eigenvalues depend on.  Each truncation must stay
    positive (a :class:`NotPositiveError` names the first that does not).

    Examples
    --------
    >>> from shspec import ConformalFactor, convergence_in_factor
    >>> rho = ConformalFactor.mobius_boost(1.5, lmax=16)
    >>> study = convergence_in_factor(rho, [4, 8, 12, 16], lmax=20, k=9)   # rho cut at La, one basis
    >>> len(study.table())
    4
    """
    factor = as_factor(rho)
    values = _check_values(lmax_factor_values, "lmax_factor")
    big = HarmonicModel(lmax, int(values[-1]), cache_dir=cache_dir)
    lams = []
    for la in values:
        model = HarmonicModel(lmax, int(la), table=big.table)
        lams.append(model.spectrum(factor.truncated(int(la)), k).eigenvalues)
    return ConvergenceStudy("lmax_factor", values, np.array(lams), lmax)


