"""Comparison of a fitted ρ with the truth, up to what a spectrum cannot see: Möbius maps and O(3).

Both factors are Möbius-centred (a_1m = 0, :func:`~shspec.sphere.mobius.center_harmonic`); then the element of O(3)
that best maps the fit onto the truth is found (:mod:`shspec.sphere.rotate`: Wigner-D rotations, the mirror
z ↦ −z).  The search minimizes ‖R·a − b‖² over SO(3) for
both a and its mirror image.  Levenberg–Marquardt on local rotation-vector coordinates refines the 24 rotations of
the octahedral group on the misfit of degrees ≤ 2 (smooth over SO(3)), then the best distinct few on degrees ≤ 3,
4, ..., La in turn (see :func:`align`).  The per-degree power
Σ_m a_lm², invariant under O(3), needs no alignment.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.optimize
from scipy.spatial.transform import Rotation

from ..errors import InvalidArgumentError
from ..sphere.factor import ConformalFactor
from ..sphere.harmonics import as_coefficients, lmax_of_size, ncoeffs
from ..sphere.mobius import center_harmonic
from ..sphere.rotate import rotator, mirror_coefficients, power_spectrum, rotate_coefficients

__all__ = ["Alignment", "align"]

#: Candidates kept from one degree level to the next, per handedness.
_REFINED_SEEDS = 8


def _euler(rotation: Rotation) -> np.ndarray:
    """z-y-z Euler angles of a rotation; at gimbal lock scipy's choice (third angle 0) is as good as any."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return rotation.as_euler("zyz")


@dataclass(frozen=True)
class Alignment:
    """Result of :func:`align`.

    Attributes
    ----------
    aligned : (N,) array
        The fit after centering and the best O(3) element, to be compared with ``reference``.
    reference : (N,) array
        The centred truth.
    angles : (3,) array
        z-y-z Euler angles (radians, pyshtools' ``SHRotateRealCoef`` convention) of the rotation applied after the
        optional mirror.
    mirrored : bool
        The best element is improper (the mirror z ↦ −z first).
    relative_error : float
        ‖aligned − reference‖ / ‖reference‖: the relative L2 error of ρ on the sphere (orthonormal basis).
    power : (La+1, 2) array
        Per-degree power of the fit (column 0) and of the truth (column 1).
    power_error : float
        ‖P_fit − P_truth‖ / ‖P_truth‖ over degrees, rotation and reflection invariant.

    Examples
    --------
    >>> from shspec.fitting import blob_factor
    >>> from shspec.inverse import align
    >>> from shspec.sphere.rotate import rotate_coefficients
    >>> import numpy as np
    >>> rho = blob_factor()
    >>> turned = rotate_coefficients(rho.coefficients, np.array([0.3, 1.1, -0.4]))   # what a spectrum cannot tell
    >>> al = align(turned, rho)
    >>> al.relative_error < 1e-8, al.mirrored
    (True, False)
    """

    aligned: np.ndarray
    reference: np.ndarray
    angles: np.ndarray
    mirrored: bool
    relative_error: float
    power: np.ndarray
    power_error: float


def align(fit, truth, *, center: bool = True, center_tol: float = 1e-12) -> Alignment:
    """Centre both factors and find the element of O(3) that maps ``fit`` closest to ``truth``.

    Parameters
    ----------
    fit, truth : flat vector, cilm array, SHCoeffs or ConformalFactor
        The two factors; the shorter one is zero-padded to the larger band limit.
    center : bool
        Möbius-centre each factor whose |a_1m| / a_00 exceeds ``center_tol`` first.
    center_tol : float

    Returns
    -------
    Alignment

    Raises
    ------
    InvalidArgumentError
        If a factor is zero or not a valid coefficient vector.
    NotPositiveError
        If centering meets a factor that is not positive.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.fitting import blob_factor
    >>> from shspec.inverse import align
    >>> from shspec.sphere.rotate import rotate_coefficients
    >>> rho = blob_factor()
    >>> turned = rotate_coefficients(rho.coefficients, np.array([0.3, 1.1, -0.4]))
    >>> align(turned, rho).relative_error < 1e-8
    True
    """

    vecs = [f.coefficients if isinstance(f, ConformalFactor) else as_coefficients(f) for f in (fit, truth)]
    lmax = max(lmax_of_size(v.size) for v in vecs)
    vecs = [as_coefficients(v, lmax) for v in vecs]
    if center:
        vecs = [center_harmonic(v, lmax, tol=center_tol).coefficients
                if lmax >= 1 and np.max(np.abs(v[1:4])) > center_tol * abs(v[0]) else v for v in vecs]
    a, b = vecs
    norm_b = np.linalg.norm(b)
    if norm_b == 0 or np.linalg.norm(a) == 0:
        raise InvalidArgumentError("cannot align a zero factor")
    angles, mirrored = _best_element_of_o3(a, b, lmax)
    aligned = rotate_coefficients(mirror_coefficients(a) if mirrored else a, angles)
    pa, pb = power_spectrum(a), power_spectrum(b)
    return Alignment(aligned=aligned, reference=b, angles=np.asarray(angles), mirrored=bool(mirrored),
                     relative_error=float(np.linalg.norm(aligned - b) / norm_b), power=np.stack([pa, pb], 1),
                     power_error=float(np.linalg.norm(pa - pb) / np.linalg.norm(pb)))


def _best_element_of_o3(a: np.ndarray, b: np.ndarray, lmax: int) -> tuple:
    """(Euler angles, mirrored) of the element of O(3) that maps ``a`` closest to ``b`` (both of degree lmax)."""
    best = (np.inf, None, False)
    seeds = Rotation.create_group("O")
    for mirrored in (False, True):
        src = mirror_coefficients(a) if mirrored else a
        candidates = [seeds[i] for i in range(len(seeds))]
        # Coarse to fine in degree: the misfit of degrees <= 2 varies slowly over SO(3) and has few local minima;
        # each finer level refines the best candidates of the coarser one, so that the oscillating high degrees
        # only ever see starts already close to a good minimum.
        for level in range(min(2, lmax), lmax + 1):
            n = ncoeffs(level)
            rotate, src_l, b_l = rotator(level), src[:n], b[:n]

            def residual(omega, seed):
                return rotate(src_l, _euler(Rotation.from_rotvec(omega) * seed)) - b_l

            refined = []
            for seed in candidates:
                res = scipy.optimize.least_squares(residual, np.zeros(3), args=(seed,), method="lm", xtol=1e-12,
                                                   ftol=1e-15, gtol=1e-15, max_nfev=100)
                refined.append((float(res.fun @ res.fun), Rotation.from_rotvec(res.x) * seed))
            refined.sort(key=lambda item: item[0])
            # Distinct candidates only: many seeds fall into the same minimum, and the degree-2 misfit alone has
            # four equivalent ones (a quadrupole is symmetric under three half-turns) that finer degrees tell apart.
            candidates = []
            for _, rot in refined:
                if all((rot.inv() * kept).magnitude() > 1e-3 for kept in candidates):
                    candidates.append(rot)
                if len(candidates) == _REFINED_SEEDS:
                    break
        if refined[0][0] < best[0]:
            best = (refined[0][0], _euler(refined[0][1]), mirrored)
    return best[1], best[2]
