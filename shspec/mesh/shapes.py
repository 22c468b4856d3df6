"""Built-in, deterministic genus-0 test surfaces: icospheres, the study's star-shaped surfaces and "blob".

All of them are an icosphere (:func:`trimesh.creation.icosphere`, 10·4^s + 2 vertices after s subdivisions) whose
unit vertex directions u are moved radially to r(u)·u.  The connectivity is that of the icosphere, so vertex i of
every shape sits over vertex i of :func:`icosphere` with the same ``subdivisions``.
"""

from __future__ import annotations

import numpy as np
import trimesh

from ..core.checks import check_int
from ..errors import InvalidArgumentError
from ..sphere.harmonics import flat_index
from ..sphere.evaluate import harmonic_matrix
from .triangle_mesh import TriangleMesh

__all__ = ["icosphere", "star_surface", "blob", "BLOB_COEFFICIENTS", "MAX_SUBDIVISIONS"]

#: 10·4^7 + 2 = 163842 vertices; beyond this an icosphere is more than a workstation wants to build in a test.
MAX_SUBDIVISIONS = 7

#: Radial function of :func:`blob`: r(u) = 1 + Σ c_lm Y_lm(u), real orthonormal harmonics, (l, m) -> c_lm.
#: Smooth, with no symmetry plane, and star-shaped: Σ |c_lm| max|Y_lm| < 0.56 < 1, so r > 0.44.
BLOB_COEFFICIENTS = {
    (1, 0): 0.10,
    (2, 0): 0.30,
    (2, 2): 0.15,
    (3, 1): -0.20,
    (3, -2): 0.12,
    (4, 3): 0.08,
}


def _subdivisions(value) -> int:
    return check_int(value, "subdivisions", minimum=0, maximum=MAX_SUBDIVISIONS)


def icosphere(subdivisions: int = 3) -> TriangleMesh:
    """Unit icosphere: 10·4^s + 2 vertices on the unit sphere, 20·4^s outward-oriented faces.

    Parameters
    ----------
    subdivisions : int, default 3
        Number s of 4-to-1 subdivisions of the icosahedron, 0..7 (s = 3: 642 vertices, s = 4: 2562, s = 5: 10242,
        s = 6: 40962).

    Examples
    --------
    >>> from shspec.mesh import icosphere
    >>> sphere = icosphere(2)
    >>> sphere, round(sphere.area(), 3)       # a little under 4 pi: the faces are flat
    (TriangleMesh(162 vertices, 320 faces), 12.33)
    """
    s = _subdivisions(subdivisions)
    m = trimesh.creation.icosphere(subdivisions=s, radius=1.0)
    v = np.asarray(m.vertices, dtype=float)
    # trimesh projects to radius 1 in float; renormalize so |x| = 1 to rounding.
    return TriangleMesh(v / np.linalg.norm(v, axis=1)[:, None], np.asarray(m.faces))


def _radial(sub: int, radius: np.ndarray) -> TriangleMesh:
    base = icosphere(sub)
    return TriangleMesh(base.vertices * radius[:, None], base.faces)


def star_surface(l: int, m: int, p: float, subdivisions: int = 4) -> TriangleMesh:
    """The study's star-shaped surface r(u) = 1 + p·|Y_l^m(u)| over an icosphere.

    Parameters
    ----------
    l, m : int
        Degree l ≥ 0 and order |m| ≤ l of the real orthonormal harmonic (shspec's convention).
    p : float
        Amplitude p ≥ 0 (p = 0 gives the icosphere).
    subdivisions : int, default 4
        Icosphere subdivisions (see :func:`icosphere`).

    Returns
    -------
    TriangleMesh
        Vertex i at (1 + p |Y_l^m(u_i)|) u_i, u_i the icosphere's vertex i.

    Examples
    --------
    >>> from shspec.mesh import star_surface
    >>> star_surface(3, 3, 0.4, 2)             # r = 1 + 0.4 |Y_3^3| over an icosphere
    TriangleMesh(162 vertices, 320 faces)
    """
    l, m = check_int(l, "l"), check_int(m, "m", minimum=None)
    if l < 0 or abs(m) > l:
        raise InvalidArgumentError(f"need l >= 0 and |m| <= l, got l = {l}, m = {m}")
    p = float(p)
    if not np.isfinite(p) or p < 0:
        raise InvalidArgumentError(f"amplitude p must be finite and >= 0, got {p}")
    sub = _subdivisions(subdivisions)
    u = icosphere(sub).vertices
    y = harmonic_matrix(u, l)[:, int(flat_index(l, m))]
    return _radial(sub, 1.0 + p * np.abs(y))


def blob(subdivisions: int = 4) -> TriangleMesh:
    """The "blob" benchmark surface r(u) = 1 + Σ c_lm Y_lm(u) with :data:`BLOB_COEFFICIENTS` (degree ≤ 4).

    Smooth, asymmetric and star-shaped; vertex i sits over the icosphere's vertex i.

    Examples
    --------
    >>> from shspec.mesh import blob, euler_characteristic
    >>> surface = blob(2)
    >>> surface, euler_characteristic(surface)
    (TriangleMesh(162 vertices, 320 faces), 2)
    """
    sub = _subdivisions(subdivisions)
    u = icosphere(sub).vertices
    lmax = max(l for l, _ in BLOB_COEFFICIENTS)
    Y = harmonic_matrix(u, lmax)
    r = np.ones(u.shape[0])
    for (l, m), c in BLOB_COEFFICIENTS.items():
        r += c * Y[:, int(flat_index(l, m))]
    return _radial(sub, r)
