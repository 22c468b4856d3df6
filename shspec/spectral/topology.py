"""The Euler characteristic, genus and area of a closed surface from its first K eigenvalues, before any fit.

Method
------
The heat trace of a closed surface is Z(t) = A/(4πt) + χ/6 + a₁t + a₂t² + … as t → 0.  From K eigenvalues,
Z_K(t) = Σ_{n<K} e^{−λ_n t} plus the tail above λ_K (:func:`~shspec.spectral.heat.spectral_tail`, with the density
of the spectrum's own top quarter, :func:`~shspec.spectral.weyl.top_density`) is fitted by least
squares on 40 log-spaced times of a window [t₀, t₁] to

    A/(4πt) + χ/6 + Σ_{p=1}^{P} a_p t^p + Σ_{q=2}^{Q} b_q t^{−q}

with the area A known or fitted.  The negative powers are the error of a discretization, not of the surface: P1
finite elements (cotan) shift eigenvalues by λ_h = λ(1 + αh²λ + βh⁴λ² + …), which changes Z by −αh²t Z''(t) + … =
−2αh²A/(4πt²) + O(t^{−3}) and leaves the 1/t and constant terms alone.  Exact spectra get b_q ≈ 0.

The window.  Its lower end is set by the truncation: the tail is wrong by at most about 2D e^{−λ_K t}, where
D is the largest distance of the counting function from its smooth fit near λ_K (:mod:`shspec.spectral.weyl`), so
t₀ = u₀/λ_K with u₀ = ln(2D/ε) keeps that error below ``tail_tolerance`` ε.  Its upper end is set by the
asymptotic series, whose range depends on the curvature, unknown beforehand: windows of several widths t₁/t₀ and
starts (multiples of u₀) are all fitted.  A model (P, Q) that is right gives the same χ in every window, one that
misses a term drifts with the window, so the model whose χ varies least over the windows is chosen (P ∈ {1, 2},
Q ∈ {2, 3} by default), and its half-range over the windows is the first part of the uncertainty.

Uncertainty.  σ_χ² = (window half-range)² + (model)² + (drift/2)² + (noise)² + floor²: the model part is half
the difference between the chosen model's χ and the runner-up's (the next most stable), the drift the change of χ
when only the first K/2 eigenvalues are used (a converged estimate does not move), the noise part propagates a
given relative eigenvalue noise ε through the least squares (var Z(t_i, t_j) = ε² Σ_n λ_n² t_i t_j
e^{−λ_n(t_i + t_j)}), and the floor (0.02) is the scatter the exact round sphere shows between windows.

What the fit does not model.  Those parts measure how χ moves within the model; a term the model lacks moves every
window alike.  The real meshes spot, bunny and blub at 600 and 1200 vertices, and spot at 2930, read χ = 5 … 10
with σ of 0.1 … 0.7, the same after a midpoint subdivision (not the cotan error, then, but their features against
the heat kernel's reach): stable and wrong.  An estimate that no surface can have tells it: when χ is further from
the nearest possible value 2 − 2g (g ≥ 0) than ``consistency`` σ, that distance is a lower bound of what the model
misses, and it joins σ as the part ``unexplained``; the genus is then undetermined (rule (a) below).

Genus.  For a connected orientable surface g = (2 − χ)/2.  The nearest integer g ≥ 0 is reported; the estimate is
``confident`` when (a) it is within ``max_offset`` (¼) of that integer and within 3σ_g of it, (b) every other
integer is at least ``confidence`` (3) σ_g away, and (c) the spectrum has exactly one zero eigenvalue (one
component).  Surfaces with features finer than the heat kernel's reach √t₀ (thin ears, legs, tubes) are outside
the asymptotic regime at the available t: their χ drifts with the window and the estimate says so by not being
confident; more eigenvalues (a smaller t₀ = u₀/λ_K) bring them in.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ..core.checks import check_int, check_options
from ..errors import InvalidArgumentError, TopologyError
from .heat import as_eigenvalues, heat_trace, spectral_tail
from .weyl import top_density, weyl_fit

__all__ = ["TopologyOptions", "TopologyEstimate", "estimate_topology", "check_genus_zero", "MIN_EIGENVALUES"]

#: Fewest eigenvalues :func:`estimate_topology` accepts: below this no window is both truncation-safe and wide.
MIN_EIGENVALUES = 20

#: Range of the largest eigenvalue the heat-trace fit handles: its windows have t ~ 1/λ_max and its design matrix
#: holds powers of t up to the fourth or so, which over- or underflow double precision far outside it.
_EIGENVALUE_RANGE = (1e-60, 1e60)
#: How far a known area may be from Weyl's law λ_k ≈ 4πk/A before it is refused as another surface's (a real
#: surface's spectrum is within a factor ~3 of the law at k >= MIN_EIGENVALUES).
_AREA_MISMATCH = 1e6


def _positive_tuple(values, name: str, *, minimum: float = 0.0) -> tuple:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise InvalidArgumentError(f"{name} must be a sequence of numbers, got {values!r}") from None
    if not out or not all(np.isfinite(v) and v > minimum for v in out):
        raise InvalidArgumentError(f"{name} must be a non-empty sequence of finite numbers > {minimum}, got {values!r}")
    return out


@dataclass(frozen=True)
class TopologyOptions:
    """Options of :func:`estimate_topology` (module notes).

    Attributes
    ----------
    tail_tolerance : float
        ε: the largest error of the tail correction allowed in Z (dimensionless); sets t₀ = ln(2D/ε)/λ_K.
    window_starts : tuple of float
        Window starts as multiples of t₀ (each ≥ 1: never below the truncation limit).
    window_ratios : tuple of float
        Window widths t₁/t₀ (each > 1).
    positive_powers : tuple of int
        Candidate P: highest power t^P of the curvature series fitted (P ≥ 1).
    negative_powers : tuple of int
        Candidate Q: discretization terms t^{−2} … t^{−Q} fitted (0: none; else ≥ 2).  The default leaves out 0:
        every computed spectrum (cotan, Galerkin) has them, and a model without them, fitted with the area free,
        hides them in the area and can be stable and wrong at once (it read a genus-3 chain of rings as genus 4
        with 500 eigenvalues; :doc:`/benchmarks`).  Exact closed-form spectra lose little.
    samples : int
        Times per window (log-spaced).
    confidence : float
        Every other genus must be at least this many σ away.
    max_offset : float
        |g estimate − g| at most this for a confident genus.
    consistency : float
        … and at most this many σ_g.
    floor : float
        Smallest σ_χ reported.
    zero_rtol : float
        Eigenvalues below zero_rtol·λ_K count as zero (one per connected component).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import TopologyOptions, estimate_topology
    >>> l = np.repeat(np.arange(25), 2 * np.arange(25) + 1)
    >>> strict = TopologyOptions(confidence=5.0)      # call a genus only 5 sigma from the next one
    >>> estimate_topology(l * (l + 1.0), area=4 * np.pi, options=strict).genus
    0
    """

    tail_tolerance: float = 1e-3
    window_starts: tuple = (1.0, 1.25, 1.5)
    window_ratios: tuple = (4.0, 6.0, 8.0)
    positive_powers: tuple = (1, 2)
    negative_powers: tuple = (2, 3)
    samples: int = 40
    confidence: float = 3.0
    max_offset: float = 0.25
    consistency: float = 3.0
    floor: float = 0.02
    zero_rtol: float = 1e-6

    def __post_init__(self):
        if not (0 < self.tail_tolerance < 1):
            raise InvalidArgumentError(f"tail_tolerance must be in (0, 1), got {self.tail_tolerance}")
        starts = _positive_tuple(self.window_starts, "window_starts")
        if min(starts) < 1:
            raise InvalidArgumentError(f"window_starts must be >= 1 (below t0 the truncation shows), got {starts}")
        ratios = _positive_tuple(self.window_ratios, "window_ratios", minimum=1.0)
        pos = tuple(check_int(p, "positive_powers entry", minimum=1, maximum=6) for p in self.positive_powers)
        neg = tuple(check_int(q, "negative_powers entry", minimum=0, maximum=6) for q in self.negative_powers)
        if not pos or not neg or 1 in neg:
            raise InvalidArgumentError("positive_powers and negative_powers must be non-empty; a negative power "
                                       "of 1 is the area term, so negative_powers holds 0 or values >= 2")
        check_int(self.samples, "samples", minimum=8, maximum=10_000)
        for name in ("confidence", "max_offset", "consistency", "floor"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise InvalidArgumentError(f"{name} must be finite and positive, got {value}")
        if not (0 < self.zero_rtol < 1):
            raise InvalidArgumentError(f"zero_rtol must be in (0, 1), got {self.zero_rtol}")
        object.__setattr__(self, "window_starts", starts)
        object.__setattr__(self, "window_ratios", ratios)
        object.__setattr__(self, "positive_powers", pos)
        object.__setattr__(self, "negative_powers", neg)


@dataclass(frozen=True)
class TopologyEstimate:
    """What the heat trace of K eigenvalues says about the surface.

    Attributes
    ----------
    euler_characteristic, euler_characteristic_error : float
        χ and σ_χ.
    genus : int
        Nearest integer g ≥ 0 to (2 − χ)/2 (connected, orientable surface).
    genus_estimate, genus_error : float
        (2 − χ)/2 and σ_χ/2.
    separation : float
        Distance from the estimate to the nearest other integer g' ≥ 0, in units of σ_g.
    confident : bool
        See the module notes; a confident genus was never wrong in the measured cases (:doc:`/benchmarks`).
    statement : str
        E.g. "genus 1; the nearest other integer is 4.2σ away".
    area, area_error : float
        A and its half-range over the windows (the given area and 0 when it was known).
    area_known : bool
    weyl_area : float
        The area from the counting function alone (:func:`~shspec.spectral.weyl.weyl_fit`), for comparison.
    window : (float, float)
        Smallest t₀ and largest t₁ of the windows fitted (area units).
    numeig : int
        Eigenvalues used, λ₀ = 0 included.
    components : int
        Eigenvalues that are zero (connected components).
    positive_powers, negative_powers : int
        The model chosen (P, Q).
    coefficients : dict
        Median fitted a_p and b_q of the chosen model.
    error_budget : dict
        The parts of σ_χ: ``window``, ``model``, ``drift``, ``noise``, ``floor`` and ``unexplained`` (module
        notes).
    relative_noise : float
        The eigenvalue noise propagated.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import estimate_topology
    >>> l = np.repeat(np.arange(25), 2 * np.arange(25) + 1)
    >>> est = estimate_topology(l * (l + 1.0), area=4 * np.pi)
    >>> est.statement.split(";")[0], est.numeig
    ('genus 0', 625)
    """

    euler_characteristic: float
    euler_characteristic_error: float
    genus: int
    genus_estimate: float
    genus_error: float
    separation: float
    confident: bool
    statement: str
    area: float
    area_error: float
    area_known: bool
    weyl_area: float
    window: tuple
    numeig: int
    components: int
    positive_powers: int
    negative_powers: int
    coefficients: dict = field(default_factory=dict)
    error_budget: dict = field(default_factory=dict)
    relative_noise: float = 0.0

    def to_dict(self) -> dict:
        """JSON-ready dict of every field (``window`` as a two-element list)."""
        d = asdict(self)
        d["window"] = [float(x) for x in self.window]
        return d


def _design(t, area_known: bool, p: int, q: int) -> np.ndarray:
    cols = [] if area_known else [1.0 / (4 * np.pi * t)]
    cols.append(np.full_like(t, 1.0 / 6.0))
    cols += [t ** k for k in range(1, p + 1)]
    cols += [t ** -k for k in range(2, q + 1)]
    return np.stack(cols, axis=1)


def _fit_windows(lam, area, opt, p, q, noise):
    """χ, A, coefficients, χ's noise σ and the window ends, in every window, for the model (p, q)."""
    top = top_density(lam)
    lk = top.lam_max
    u0 = math.log(2.0 * top.fluctuation / opt.tail_tolerance)
    known = area is not None
    out = []
    for start, ratio in itertools.product(opt.window_starts, opt.window_ratios):
        t0 = start * u0 / lk
        t = np.geomspace(t0, ratio * t0, opt.samples)
        y = heat_trace(lam, t) + spectral_tail(t, lk, top.density, top.density_slope)
        if known:
            y = y - area / (4 * np.pi * t)
        X = _design(t, known, p, q)
        scale = np.linalg.norm(X, axis=0)
        pinv = np.linalg.pinv(X / scale) / scale[:, None]
        coef = pinv @ y
        ichi = 0 if known else 1
        sigma_noise = 0.0
        if noise > 0:
            # dy_i/dλ_n = −t_i e^{−λ_n t_i}; relative noise ε gives δλ_n = ε λ_n ξ_n.
            jac = t[:, None] * lam[None, :] * np.exp(-np.outer(t, lam))
            sigma_noise = noise * float(np.linalg.norm(pinv[ichi] @ jac))
        out.append((coef[ichi], area if known else coef[0], coef[ichi + 1:], sigma_noise, t0, ratio * t0))
    return out


def _estimate_chi(lam, area, opt, noise):
    """The chosen model (window half-range, median χ, P, Q, per-window fits) and the runner-up's disagreement."""
    models = []
    for p, q in itertools.product(opt.positive_powers, opt.negative_powers):
        fits = _fit_windows(lam, area, opt, p, q, noise)
        chis = np.array([f[0] for f in fits])
        models.append((0.5 * float(chis.max() - chis.min()), float(np.median(chis)), p, q, fits))
    models.sort(key=lambda m: m[0])
    best = models[0]
    # The runner-up is nearly as plausible: half the disagreement of the two most stable models is part of σ.
    model_spread = 0.5 * abs(best[1] - models[1][1]) if len(models) > 1 else 0.0
    return best, model_spread


def estimate_topology(eigenvalues, area: float | None = None, *, numeig: int | None = None,
                      relative_noise: float = 0.0, options: TopologyOptions | None = None) -> TopologyEstimate:
    """Euler characteristic, genus and area of a closed surface from its spectrum (module notes).

    Parameters
    ----------
    eigenvalues : (k,) array_like
        λ₀ = 0 first, ascending, in 1/area; every one should be trusted (a mesh's cotan spectrum: k well below
        the number of vertices, e.g. k ≤ n/10).
    area : float, optional
        The surface area, when known (a mesh's); else fitted.
    numeig : int, optional
        Use only the first ``numeig`` eigenvalues (default: all).
    relative_noise : float
        Relative standard deviation ε of independent noise on each eigenvalue, propagated into σ_χ (default 0).
    options : TopologyOptions, optional

    Returns
    -------
    TopologyEstimate

    Raises
    ------
    InvalidArgumentError
        If the spectrum is not a closed surface's (see :func:`~shspec.spectral.heat.as_eigenvalues`), shorter
        than :data:`MIN_EIGENVALUES`, or an argument is out of range.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import estimate_topology
    >>> l = np.repeat(np.arange(25), 2 * np.arange(25) + 1)
    >>> est = estimate_topology(l * (l + 1.0), area=4 * np.pi)   # the unit sphere's spectrum
    >>> round(est.euler_characteristic, 2), est.genus, est.confident
    (2.0, 0, True)
    """
    opt = check_options(options, TopologyOptions)
    lam = _used_eigenvalues(eigenvalues, numeig)
    area = None if area is None else _checked_area(area, lam)
    noise = float(relative_noise)
    if not (np.isfinite(noise) and 0 <= noise < 1):
        raise InvalidArgumentError(f"relative_noise must be in [0, 1), got {relative_noise}")

    (spread, _, p, q, fits), model_spread = _estimate_chi(lam, area, opt, noise)
    chi = float(np.median([f[0] for f in fits]))
    parts = {"window": spread, "model": model_spread, "drift": 0.5 * _drift(lam, area, opt, p, q, noise, chi),
             "noise": float(np.median([f[3] for f in fits]))}
    sigma, consistent_within, budget = _error_budget(chi, parts, opt)
    areas = np.array([f[1] for f in fits])
    components = int(np.count_nonzero(lam <= opt.zero_rtol * lam[-1]))
    names = [f"a{k}" for k in range(1, p + 1)] + [f"b{k}" for k in range(2, q + 1)]
    coefs = np.median(np.array([f[2] for f in fits]), axis=0)
    return TopologyEstimate(
        euler_characteristic=chi, euler_characteristic_error=sigma,
        **_genus_verdict(chi, sigma, consistent_within, components, opt),
        area=float(np.median(areas)), area_error=0.0 if area is not None else 0.5 * float(areas.max() - areas.min()),
        area_known=area is not None, weyl_area=weyl_fit(lam).area,
        window=(min(f[4] for f in fits), max(f[5] for f in fits)), numeig=int(lam.size), components=components,
        positive_powers=p, negative_powers=q, coefficients={k: float(v) for k, v in zip(names, coefs)},
        error_budget=budget, relative_noise=noise)


def _used_eigenvalues(eigenvalues, numeig: int | None) -> np.ndarray:
    """The first ``numeig`` eigenvalues (all if None), checked: a closed surface's, enough, and in the range the
    heat-trace fit handles."""
    lam = as_eigenvalues(eigenvalues, minimum=MIN_EIGENVALUES)
    if numeig is not None:
        lam = lam[:check_int(numeig, "numeig", minimum=MIN_EIGENVALUES, maximum=lam.size)]
    top = float(lam[-1])
    if not _EIGENVALUE_RANGE[0] <= top <= _EIGENVALUE_RANGE[1]:
        raise InvalidArgumentError(
            f"the largest eigenvalue {top:.3g} is outside [{_EIGENVALUE_RANGE[0]:g}, {_EIGENVALUE_RANGE[1]:g}], where "
            "the heat-trace fit over- or underflows; rescale the spectrum (a surface scaled by s has eigenvalues "
            "lambda/s^2)")
    return lam


def _checked_area(area, lam: np.ndarray) -> float:
    """A known ``area`` as a float, checked against the spectrum ``lam`` by Weyl's law."""
    area = float(area)
    if not (np.isfinite(area) and area > 0):
        raise InvalidArgumentError(f"area must be finite and positive, got {area}")
    weyl = 4 * np.pi * (lam.size - 1) / float(lam[-1])
    if not 1 / _AREA_MISMATCH <= area / weyl <= _AREA_MISMATCH:
        raise InvalidArgumentError(
            f"the area {area:.3g} is {area / weyl:.2g} times the area Weyl's law gives for this spectrum "
            f"(about {weyl:.3g}): it is not this surface's area (or the spectrum is in other units)")
    return area


def _drift(lam, area, opt, p, q, noise, chi: float) -> float:
    """How far χ moves when the model (p, q) fits only the first half of the eigenvalues (0 when that is all)."""
    half = lam[:max(MIN_EIGENVALUES, lam.size // 2)]
    if half.size == lam.size:
        return 0.0
    return abs(chi - float(np.median([f[0] for f in _fit_windows(half, area, opt, p, q, noise)])))


def _error_budget(chi: float, parts: dict, opt) -> tuple:
    """σ_χ, the bound of rule (a) and the budget: ``parts`` (window, model, drift, noise), the floor and the part
    ``unexplained`` (module notes)."""
    budget = {**parts, "floor": opt.floor}
    sigma = float(np.sqrt(sum(v * v for v in budget.values())))
    possible = 2.0 - 2.0 * max(0, round((2.0 - chi) / 2.0))
    unexplained = abs(chi - possible)
    budget["unexplained"] = unexplained if unexplained > opt.consistency * sigma else 0.0
    # rule (a) asks whether the model explains the estimate: with σ before what it does not explain
    consistent_within = opt.consistency * sigma / 2.0
    return float(np.hypot(sigma, budget["unexplained"])), consistent_within, budget


def _genus_verdict(chi: float, sigma: float, consistent_within: float, components: int, opt) -> dict:
    """The fields of :class:`TopologyEstimate` about the genus, with χ ± ``sigma``, by the rules (a)–(c) of the
    module notes."""
    g_est = (2.0 - chi) / 2.0
    g_sigma = sigma / 2.0
    genus = max(0, int(round(g_est)))
    others = [g for g in (genus - 1, genus + 1) if g >= 0]
    separation = min(abs(g_est - g) for g in others) / g_sigma
    offset = abs(g_est - genus)
    reasons = []
    if components != 1:
        reasons.append(f"{components} zero eigenvalues (components); the genus formula needs one")
    if offset > opt.max_offset or offset > consistent_within:
        where = (f"χ = {chi:.2f} is above 2, which no connected surface has" if g_est < -opt.max_offset else
                 f"the estimate {g_est:.2f} is {offset:.2f} from the nearest genus")
        reasons.append(f"{where}: the asymptotic series does not hold at these t (more eigenvalues needed)")
    if separation < opt.confidence:
        reasons.append(f"the nearest other integer is only {separation:.1f}σ away")
    confident = not reasons
    head = f"genus {genus}; the nearest other integer is {separation:.1f}σ away"
    statement = head if confident else f"genus undetermined (best guess {genus}): " + "; ".join(reasons)
    return dict(genus=genus, genus_estimate=g_est, genus_error=g_sigma, separation=float(separation),
                confident=confident, statement=statement)


def check_genus_zero(eigenvalues, area: float | None = None, **kwargs) -> TopologyEstimate | None:
    """The guard of genus-0 operations (fits): raise when the heat trace says confidently that genus ≠ 0.

    Parameters
    ----------
    eigenvalues, area, **kwargs
        As for :func:`estimate_topology`.

    Returns
    -------
    TopologyEstimate or None
        The estimate, when it does not contradict genus 0 (genus 0, or not confident); None when there are fewer
        than :data:`MIN_EIGENVALUES` eigenvalues, too few to tell anything.

    Raises
    ------
    TopologyError
        When the estimate is confident and its genus is not 0; the message gives χ ± σ and the statement.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.spectral import check_genus_zero
    >>> l = np.repeat(np.arange(25), 2 * np.arange(25) + 1)
    >>> check_genus_zero(l * (l + 1.0), area=4 * np.pi).genus     # raises TopologyError for a confident genus > 0
    0
    """
    if np.size(eigenvalues) < MIN_EIGENVALUES:
        return None
    est = estimate_topology(eigenvalues, area, **kwargs)
    if est.confident and est.genus != 0:
        raise TopologyError(
            f"the heat trace of the first {est.numeig} eigenvalues says genus {est.genus}, not 0: Euler "
            f"characteristic {est.euler_characteristic:.2f} ± {est.euler_characteristic_error:.2f} "
            f"({est.statement}); a genus-0 model cannot fit it")
    return est
