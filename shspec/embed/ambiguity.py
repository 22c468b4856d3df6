"""Bumps versus dips: which parts of a re-embedding the metric does not decide.

Edge lengths fix a surface only up to isometric bending.  The classic case is Pogorelov's: a convex cap cut off by
a plane can be mirrored through that plane — a bump becomes a dip — without changing any length inside it; only
the crease along the boundary costs anything, and on a triangle mesh that cost is small.  So the candidates are the
*caps*: connected regions of positive Gaussian curvature (angle defect > 0) bounded by saddle-shaped (negative)
curvature, such as the bunny's ears and tail or a dimple.  A surface that is elliptic everywhere (a convex blob)
has no proper cap and is rigid (Cauchy, Alexandrov); nothing is reported.

For each cap, largest first, :func:`detect_ambiguity` reflects its vertices through the least-squares plane of
the ring around it, lets both the original and the mirrored configuration relax for a few Gauss–Newton iterations
of the strain energy (:mod:`shspec.embed.embed`, no pressure), and compares their RMS edge strains.  When the
mirrored one is no worse than the original by more than ``rtol`` (relative) or ``atol`` (absolute strain), the cap
is reported ambiguous: the factors alone cannot tell which way it points, and the embedding's choice came from the
pressure prior (outwards).  The test is a heuristic that looks at one cap at a time, not a proof of uniqueness.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..core.checks import check_int, check_options
from ..errors import InvalidArgumentError
from ..mesh.cotan import cotan_stiffness, vertex_areas
from ..mesh.triangle_mesh import TriangleMesh
from .options import EmbedOptions, EmbedResult
from .solver import lm_iterate
from .system import EmbedSystem
from .lengths import check_sphere

__all__ = ["AmbiguityOptions", "Cap", "AmbiguityReport", "detect_ambiguity", "angle_defects"]


@dataclass(frozen=True)
class AmbiguityOptions:
    """Options of :func:`detect_ambiguity`.

    Attributes
    ----------
    min_area, max_area : float
        Caps with an area fraction outside [min_area, max_area] of the whole surface are not tested.
    max_caps : int
        Test at most this many caps, the largest first.
    iterations : int
        Gauss–Newton iterations that relax each configuration.
    rtol, atol : float
        Ambiguous when rms_mirrored ≤ max(rms_original (1 + rtol), rms_original + atol).  The default atol = 0.5 %
        strain is the level at which the cMCF factors of a 642-vertex blob reproduce the true surface's own edge
        lengths: differences below it are not evidence either way.

    Examples
    --------
    >>> from shspec.embed import AmbiguityOptions
    >>> AmbiguityOptions(max_caps=2).max_caps
    2
    """

    min_area: float = 0.003
    max_area: float = 0.5
    max_caps: int = 6
    iterations: int = 8
    rtol: float = 0.5
    atol: float = 5e-3

    def __post_init__(self):
        if not 0 < self.min_area < self.max_area <= 1:
            raise InvalidArgumentError(f"need 0 < min_area < max_area <= 1, got {self.min_area}, {self.max_area}")
        for name in ("max_caps", "iterations"):
            value = getattr(self, name)
            check_int(value, f"AmbiguityOptions.{name}", minimum=1)
        for name in ("rtol", "atol"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise InvalidArgumentError(f"AmbiguityOptions.{name} must be finite and >= 0, got {value!r}")


@dataclass(frozen=True)
class Cap:
    """One tested cap.

    Attributes
    ----------
    vertices : (k,) int array
        Its vertices.
    area_fraction : float
        Its share of the surface area.
    kind : str
        "bump" (mean curvature outwards) or "dip".
    rms_original, rms_mirrored : float
        RMS relative edge strain of the surface after relaxing, as embedded and with the cap mirrored.
    ambiguous : bool
        The mirrored cap fits the lengths about as well (see :class:`AmbiguityOptions`).

    Examples
    --------
    >>> from shspec.embed import Cap
    >>> sorted(Cap.__dataclass_fields__)
    ['ambiguous', 'area_fraction', 'kind', 'rms_mirrored', 'rms_original', 'vertices']
    """

    vertices: np.ndarray = field(repr=False)
    area_fraction: float
    kind: str
    rms_original: float
    rms_mirrored: float
    ambiguous: bool


@dataclass(frozen=True)
class AmbiguityReport:
    """Result of :func:`detect_ambiguity`.

    Attributes
    ----------
    caps : tuple of Cap
        The tested caps, largest first.
    candidates : int
        Caps found with an area fraction in range (more than were tested if > ``max_caps``).
    ambiguous : bool
        Some tested cap is ambiguous.

    Examples
    --------
    >>> from shspec.embed import detect_ambiguity, embed
    >>> from shspec.mesh import blob, cmcf
    >>> flow = cmcf(blob(2))
    >>> report = detect_ambiguity(flow.sphere, embed(flow.sphere, flow.factors))
    >>> type(report).__name__, report.candidates >= len(report.caps)
    ('AmbiguityReport', True)
    """

    caps: tuple
    candidates: int
    ambiguous: bool


def angle_defects(mesh: TriangleMesh) -> np.ndarray:
    """Discrete Gaussian curvature 2π − Σ (corner angles), (n,) radians, at each vertex of a closed mesh.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.embed import angle_defects
    >>> from shspec.mesh import icosphere
    >>> round(angle_defects(icosphere(1)).sum() / (4 * np.pi), 6)   # Gauss-Bonnet: 2 pi chi
    1.0
    """
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    p = mesh.vertices[mesh.faces]
    total = np.zeros(mesh.nvertices)
    for k in range(3):
        u = p[:, (k + 1) % 3] - p[:, k]
        v = p[:, (k + 2) % 3] - p[:, k]
        ang = np.arctan2(np.linalg.norm(np.cross(u, v), axis=1), np.einsum("ij,ij->i", u, v))
        total += np.bincount(mesh.faces[:, k], weights=ang, minlength=mesh.nvertices)
    return 2.0 * np.pi - total


def _caps(mesh: TriangleMesh, edges: np.ndarray, opt: AmbiguityOptions):
    """Connected components of elliptic vertices with an area fraction in range, largest first, and their count."""
    elliptic = angle_defects(mesh) > 0
    keep = elliptic[edges[:, 0]] & elliptic[edges[:, 1]]
    n = mesh.nvertices
    G = sp.csr_matrix((np.ones(int(keep.sum())), (edges[keep, 0], edges[keep, 1])), shape=(n, n))
    _, label = connected_components(G, directed=False)
    area = vertex_areas(mesh)
    frac = np.bincount(label, weights=area) / area.sum()
    ok = [lab for lab in np.argsort(-frac) if opt.min_area <= frac[lab] <= opt.max_area
          and elliptic[label == lab].all()]
    return [np.flatnonzero(label == lab) for lab in ok], frac, label


def _mirror(x: np.ndarray, cap: np.ndarray, ring: np.ndarray) -> np.ndarray:
    """Positions with the cap's vertices reflected through the least-squares plane of its ring."""
    c = x[ring].mean(axis=0)
    _, _, vt = np.linalg.svd(x[ring] - c)
    nrm = vt[-1]
    y = x.copy()
    y[cap] -= 2.0 * ((x[cap] - c) @ nrm)[:, None] * nrm
    return y


def detect_ambiguity(sphere: TriangleMesh, result: EmbedResult, options: AmbiguityOptions | None = None,
                     embed_options: EmbedOptions | None = None) -> AmbiguityReport:
    """Test which caps of a re-embedding could be mirrored (bump ↔ dip) at about the same edge-length error.

    Parameters
    ----------
    sphere : TriangleMesh
        The unit-sphere mesh the embedding was computed from (n vertices).
    result : EmbedResult
        The output of :func:`~shspec.embed.embed.embed` for that sphere.
    options : AmbiguityOptions, optional
    embed_options : EmbedOptions, optional
        Damping and CG settings of the relaxation (default: EmbedOptions()).

    Returns
    -------
    AmbiguityReport

    Examples
    --------
    >>> from shspec.embed import AmbiguityOptions, detect_ambiguity, embed
    >>> from shspec.mesh import blob, cmcf
    >>> flow = cmcf(blob(2))
    >>> report = detect_ambiguity(flow.sphere, embed(flow.sphere, flow.factors), AmbiguityOptions(max_caps=2))
    >>> report.ambiguous, len(report.caps) <= 2
    (False, True)
    """
    opt = check_options(options, AmbiguityOptions)
    eopt = check_options(embed_options, EmbedOptions, "embed_options")
    sphere = check_sphere(sphere)
    if not isinstance(result, EmbedResult):
        raise InvalidArgumentError(f"result must be an EmbedResult, got {type(result).__name__}")
    if not np.array_equal(result.mesh.faces, sphere.faces):
        raise InvalidArgumentError("result was not computed on this sphere mesh (faces differ)")
    mesh = result.mesh
    caps, _, _ = _caps(mesh, result.edges, opt)
    # Work in the area-4π frame of the solver, where its tolerances are calibrated.
    scale = np.sqrt(mesh.area() / (4.0 * np.pi))
    lengths = result.target_lengths / scale
    system = EmbedSystem(sphere, eopt.damping, eopt.ridge)
    system.precondition(lengths)
    x0 = mesh.vertices / scale

    def relax(x):
        x, _ = lm_iterate(system, x, lengths, 0.0, opt.iterations, eopt, [], {"nnz": 0, "cg": 0})
        r = system.residual(x, lengths)
        return float(np.sqrt(np.mean(r * r)))

    rms0 = relax(x0)
    area = vertex_areas(mesh)
    normals = np.zeros_like(x0)
    fn = mesh.face_normals_unnormalized()
    for k in range(3):
        for a in range(3):
            normals[:, a] += np.bincount(mesh.faces[:, k], weights=fn[:, a], minlength=mesh.nvertices)
    Lx = cotan_stiffness(mesh) @ mesh.vertices
    out = []
    for cap in caps[:opt.max_caps]:
        inside = np.zeros(mesh.nvertices, dtype=bool)
        inside[cap] = True
        e = result.edges
        ring = np.unique(np.concatenate([e[inside[e[:, 0]] & ~inside[e[:, 1]], 1],
                                         e[~inside[e[:, 0]] & inside[e[:, 1]], 0]]))
        if ring.size < 3:
            continue
        rms1 = relax(_mirror(x0, cap, ring))
        # Lx points outwards at a vertex where the surface bends away from its normal (convex), inwards at a dip.
        kind = "bump" if float(np.einsum("ij,ij->", normals[cap], Lx[cap])) > 0 else "dip"
        amb = rms1 <= max(rms0 * (1.0 + opt.rtol), rms0 + opt.atol)
        out.append(Cap(vertices=cap, area_fraction=float(area[cap].sum() / area.sum()), kind=kind,
                       rms_original=rms0, rms_mirrored=rms1, ambiguous=bool(amb)))
    return AmbiguityReport(caps=tuple(out), candidates=len(caps), ambiguous=any(c.ambiguous for c in out))
