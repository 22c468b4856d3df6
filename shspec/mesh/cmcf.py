"""Conformalized mean-curvature flow (Kazhdan, Solomon, Ben-Chen, "Can mean-curvature flow be modified to be
non-singular?", SGP 2012) from a genus-0 mesh to the unit sphere.

The input is first scaled to area 4π. Each step solves (M_t + δ L₀) x_{t+1} = M_t x_t with the cotan stiffness L₀
frozen at the input and the lumped mass M_t of the current mesh, then moves the area-weighted centroid to the origin
and rescales to area 4π. Roundness is max_i | |x_i| / r̄ − 1 |, r̄ the area-weighted mean radius: the largest
relative deviation of a vertex from the best sphere about the centroid. The flow stops when roundness ≤ ``tol``, or
when it has stagnated: a discrete fixed point (where L₀x = κ M_t x) is round only up to the discretization
(measured: 2e-3 for bunny.obj, 6e-3 for spot.obj, 3e-3 for blub.obj, 2e-2 to 6e-2 for their 600-vertex versions).
The vertices are then projected radially onto the unit sphere and, by default, Möbius-centred.

The linear systems are solved by conjugate gradients preconditioned with a sparse LU of an earlier step's matrix,
refactored only when CG needs more than ``refactor_after`` iterations: the matrices of consecutive steps differ only
in their diagonal, and less and less as the flow converges.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..core.checks import check_float, check_int, check_options
from ..errors import InvalidArgumentError, MeshError
from ..core.threads import reproducible_call
from .cotan import cotan_stiffness, vertex_areas
from .mobius import center_mesh
from .progress import announce, bar, shown
from .triangle_mesh import TriangleMesh
from .validate import validate_mesh

__all__ = ["CMCFOptions", "CMCFResult", "cmcf", "roundness", "quasiconformal_distortion", "flipped_faces"]

#: Range of a mesh's size (largest extent along an axis) that cMCF accepts: its areas and conformal factors scale as
#: the size squared and its cotan weights multiply two of them, which over- or underflows double precision beyond.
SIZE_RANGE = (1e-50, 1e50)


@dataclass(frozen=True)
class CMCFOptions:
    """Options of :func:`cmcf`.

    Attributes
    ----------
    step : float
        Time step δ for the surface scaled to area 4π (δ = 4π is lapy's step 1 at unit area).  From δ ≈ 10 on,
        the iterates hardly depend on δ (the step is then close to the inverse iteration x ← L₀⁺M_t x, which has
        the same fixed points), and larger δ makes the lagged preconditioner better: on bunny, spot and blub,
        δ = 1000 needs 40 % fewer CG iterations than δ = 10 for the same 22-31 steps.
    tol : float
        Stop as soon as roundness ≤ tol.
    stall_iterations, stall_ratio : int, float
        Stop when the best roundness of the last ``stall_iterations`` steps is no better than ``stall_ratio`` times
        the best before them while varying by less than 25 % within them: the flow has reached its discrete fixed
        point (rather than oscillating on the way there, which it does with large steps).
    max_iter : int
        Most steps; reaching it without convergence gives ``success = False``.
    center : bool
        Möbius-centre the projected sphere (vertex weights: the input's vertex areas).
    cg_tol : float
        Relative residual of each linear solve.
    refactor_after : int
        Refactor the preconditioner when CG needed more iterations than this.
    validate : bool
        Validate the input mesh first (:func:`~shspec.mesh.validate.validate_mesh`).

    Examples
    --------
    >>> from shspec.mesh import CMCFOptions, blob, cmcf
    >>> flow = cmcf(blob(2), CMCFOptions(max_iter=50))
    >>> flow.iterations <= 50
    True
    """

    step: float = 1000.0
    tol: float = 1e-4
    stall_iterations: int = 4
    stall_ratio: float = 0.98
    max_iter: int = 200
    center: bool = True
    cg_tol: float = 1e-9
    refactor_after: int = 12
    validate: bool = True

    def __post_init__(self):
        for name in ("step", "tol", "cg_tol"):
            check_float(getattr(self, name), f"CMCFOptions.{name}", positive=True)
        for name in ("stall_iterations", "max_iter", "refactor_after"):
            value = getattr(self, name)
            check_int(value, f"CMCFOptions.{name}", minimum=1)
        if not 0 < self.stall_ratio <= 1:
            raise InvalidArgumentError(f"CMCFOptions.stall_ratio must be in (0, 1], got {self.stall_ratio}")


@dataclass(frozen=True)
class CMCFResult:
    """Result of :func:`cmcf`.

    Attributes
    ----------
    sphere : TriangleMesh
        The spherical mesh: the input's faces, vertices on the unit sphere (Möbius-centred if asked).
    factors : (n,) array
        Conformal factors c_i = (vertex area on the input) / (vertex area on ``sphere``), in the input's length
        unit squared per unit-sphere area, so that Σ c_i a_i^sphere = input area.
    roundness : float
        Roundness of the flowed mesh before the projection (see the module notes): the best over the steps taken,
        whose vertices are the ones projected (on coarse meshes the roundness can creep up again at the end).
    history : (iterations,) array
        Roundness after each step.
    iterations : int
        Flow steps taken.
    flips : int
        Faces of ``sphere`` whose orientation is reversed relative to the input's.
    distortion_mean, distortion_max : float
        Area-weighted mean and maximum quasi-conformal distortion σ₁/σ₂ ≥ 1 of the piecewise-affine map from the
        input triangles to the sphere's triangles (1 = conformal).
    centering_residual : float
        |Σ w_i x_i| / Σ w_i after Möbius centering (nan if not centred).
    success : bool
        Roundness ≤ tol, or stagnation reached, within max_iter, and no flipped faces.
    seconds : float
        Wall time.
    stop_reason : str
        Why the flow stopped: "tolerance" (roundness ≤ tol), "stalled" (the roundness stopped improving above tol:
        the rounder sphere this mesh allows, see ``stall_iterations``) or "max_iter".

    Examples
    --------
    >>> from shspec.mesh import blob, cmcf
    >>> flow = cmcf(blob(2))
    >>> flow.sphere, flow.success, flow.roundness < 0.02
    (TriangleMesh(162 vertices, 320 faces), True, True)
    >>> round(float(flow.factors.min()), 2), round(float(flow.factors.max()), 2)   # area ratios per vertex
    (0.73, 1.87)
    """

    sphere: TriangleMesh
    factors: np.ndarray
    roundness: float
    history: np.ndarray = field(repr=False)
    iterations: int
    flips: int
    distortion_mean: float
    distortion_max: float
    centering_residual: float
    success: bool
    seconds: float
    stop_reason: str = ""


def roundness(vertices, weights) -> float:
    """max_i | |x_i − x̄| / r̄ − 1 | for vertices (n, 3).

    x̄ and r̄ are the centroid and the mean radius weighted by ``weights`` (n,), e.g. the vertex areas.

    Examples
    --------
    >>> from shspec.mesh import icosphere, roundness, vertex_areas
    >>> sphere = icosphere(2)
    >>> roundness(sphere.vertices, vertex_areas(sphere)) < 1e-12   # its vertices lie on a sphere
    True
    """
    x = np.asarray(vertices, dtype=float)
    w = np.asarray(weights, dtype=float)
    r = np.linalg.norm(x - (w @ x) / w.sum(), axis=1)
    return float(np.max(np.abs(r / ((w @ r) / w.sum()) - 1.0)))


def flipped_faces(sphere: TriangleMesh, reference_sign: float = 1.0) -> int:
    """Number of faces of a mesh around the origin whose normal points inward (outward if reference_sign < 0)."""
    p = sphere.vertices[sphere.faces]
    orient = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p.sum(axis=1))
    return int(np.count_nonzero(orient * np.sign(reference_sign) < 0))


def quasiconformal_distortion(source: TriangleMesh, target: TriangleMesh) -> np.ndarray:
    """Per-face quasi-conformal distortion σ₁/σ₂ (m,) of the affine maps from source to target triangles.

    Both meshes share their faces; each triangle is put in 2-D coordinates of its own plane.
    """
    if source.faces.shape != target.faces.shape or np.any(source.faces != target.faces):
        raise InvalidArgumentError("source and target must have the same faces")

    def frames(mesh):
        p = mesh.vertices[mesh.faces]
        e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        u = e1 / np.linalg.norm(e1, axis=1)[:, None]
        nrm = np.cross(e1, e2)
        v = np.cross(nrm / np.linalg.norm(nrm, axis=1)[:, None], u)
        # Columns: the two edge vectors in the (u, v) frame of the triangle's plane.
        return np.stack([np.stack([np.einsum("ij,ij->i", e, u), np.einsum("ij,ij->i", e, v)], 1)
                         for e in (e1, e2)], 2)

    A, B = frames(source), frames(target)
    J = B @ np.linalg.inv(A)
    s = np.linalg.svd(J, compute_uv=False)
    return s[:, 0] / s[:, 1]


def _pcg(A, B, X0, precond, tol, maxiter):
    """Conjugate gradients on the columns of B (n, d) at once, preconditioned by ``precond``; returns X, iterations."""
    X = X0.copy()
    R = B - A @ X
    bnorm = np.linalg.norm(B, axis=0)
    Z = precond(R)
    P = Z.copy()
    rz = np.einsum("ij,ij->j", R, Z)
    for it in range(1, maxiter + 1):
        AP = A @ P
        alpha = rz / np.einsum("ij,ij->j", P, AP)
        X += alpha * P
        R -= alpha * AP
        if np.all(np.linalg.norm(R, axis=0) <= tol * bnorm):
            return X, it
        Z = precond(R)
        rz_new = np.einsum("ij,ij->j", R, Z)
        P = Z + (rz_new / rz) * P
        rz = rz_new
    return X, maxiter + 1


@reproducible_call
def cmcf(mesh: TriangleMesh, options: CMCFOptions | None = None) -> CMCFResult:
    """Map a genus-0 mesh conformally onto the unit sphere by conformalized mean-curvature flow.

    Parameters
    ----------
    mesh : TriangleMesh
        Closed genus-0 mesh, n vertices (any position, scale and unit).
    options : CMCFOptions, optional

    Returns
    -------
    CMCFResult
        The sphere mesh, the per-vertex conformal factors and the quality report.

    Raises
    ------
    MeshError
        If ``options.validate`` and the mesh is not a closed manifold genus-0 mesh, or if its size is outside
        :data:`SIZE_RANGE`.
    ConvergenceError
        If Möbius centering fails (the flow itself reports failure through ``success``).

    Examples
    --------
    >>> from shspec.mesh import blob, cmcf
    >>> flow = cmcf(blob(2))                 # the blob flowed onto the unit sphere, conformally
    >>> flow.sphere.nvertices, flow.factors.shape
    (162, (162,))
    """
    opt = check_options(options, CMCFOptions)
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    _check_size(mesh)
    if opt.validate:
        validate_mesh(mesh)
    start = time.perf_counter()
    areas0 = vertex_areas(mesh)
    round_final, x, history = _flow(mesh, areas0, opt)
    stop_reason = "tolerance" if round_final <= opt.tol else "stalled" if _stalled(history, opt) else "max_iter"
    converged = stop_reason != "max_iter"
    sphere = mesh.with_vertices(x / np.linalg.norm(x, axis=1)[:, None])
    residual = float("nan")
    if opt.center:
        centred = center_mesh(sphere, areas0)
        sphere, residual = centred.sphere, float(np.linalg.norm(centred.center))
    flips = flipped_faces(sphere, mesh.signed_volume())
    qc = quasiconformal_distortion(mesh, sphere)
    fa = mesh.face_areas()
    factors = areas0 / vertex_areas(sphere)
    return CMCFResult(sphere=sphere, factors=factors, roundness=round_final, history=np.array(history),
                      iterations=len(history), flips=flips, distortion_mean=float(fa @ qc / fa.sum()),
                      distortion_max=float(qc.max()), centering_residual=residual,
                      success=bool(converged and flips == 0), seconds=time.perf_counter() - start,
                      stop_reason=stop_reason)


def _check_size(mesh: TriangleMesh) -> None:
    """Refuse a mesh whose extent is outside :data:`SIZE_RANGE`."""
    if np.all(np.isfinite(mesh.vertices)):  # NaN and inf are validate_mesh's to name
        size = float(np.max(np.ptp(mesh.vertices, axis=0)))
        if not SIZE_RANGE[0] <= size <= SIZE_RANGE[1]:
            which = "too large" if size > SIZE_RANGE[1] else "too small"
            raise MeshError(f"the mesh is {size:.3g} across, {which} for the flow (within [{SIZE_RANGE[0]:g}, "
                            f"{SIZE_RANGE[1]:g}]: its areas and conformal factors, ~ size^2, would leave double "
                            "precision); rescale it")


def _flow(mesh: TriangleMesh, areas0, opt: CMCFOptions) -> tuple:
    """The flow's steps until round or stalled; returns the best roundness, its positions (n, 3) and the history."""
    x, m = _normalize(mesh.vertices, areas0)
    # The cotan weights are scale invariant, so L₀ of the normalized mesh is L₀ of the input.
    L0 = cotan_stiffness(mesh).tocsc()
    history = []
    best = (np.inf, x)
    lu = None
    if shown(mesh.nvertices):
        announce(f"cMCF of a {mesh.nvertices}-vertex mesh: up to {opt.max_iter} flow steps (a sparse factorization, "
                 f"then conjugate-gradient solves) until its roundness is at most {opt.tol:g}")
    steps = bar(mesh.nvertices, opt.max_iter, "cMCF", "steps", iterable=range(1, opt.max_iter + 1))
    # the bar closes when the loop ends, also by break (tqdm closes its iterator in a finally)
    for _ in steps:
        A = (sp.diags(m) + opt.step * L0).tocsc()
        b = m[:, None] * x
        if lu is None:
            lu = splu(A)
            x, cg_its = lu.solve(b), 0
        else:
            # Start CG from the best multiple of the current positions: a step mostly shrinks the surface
            # (by 1/(1 + 2δ) for a round sphere), and only the small rest is left for CG to find.
            Ax = A @ x
            x0 = x * (np.einsum("ij,ij->j", x, b) / np.einsum("ij,ij->j", x, Ax))
            x, cg_its = _pcg(A, b, x0, lu.solve, opt.cg_tol, opt.refactor_after)
            if cg_its > opt.refactor_after:
                lu = splu(A)
                x = lu.solve(b)
        x, m = _normalize(x, vertex_areas(mesh.with_vertices(x)))
        history.append(roundness(x, m))
        steps.set_postfix_str(f"roundness {history[-1]:.2g}", refresh=False)
        if history[-1] < best[0]:
            best = (history[-1], x)
        if history[-1] <= opt.tol or _stalled(history, opt):
            break
    return best[0], best[1], history


def _normalize(x, areas):
    """Translate the ``areas``-weighted centroid of x (n, 3) to 0 and scale to total area 4π.

    Returns the new positions and the vertex areas (n,) that go with them (translation leaves areas unchanged).
    """
    factor = 4 * np.pi / areas.sum()
    return (x - (areas @ x) / areas.sum()) * np.sqrt(factor), areas * factor


def _stalled(history, opt) -> bool:
    s = opt.stall_iterations
    if len(history) <= s:
        return False
    window = history[-s:]
    return min(window) > opt.stall_ratio * min(history[:-s]) and max(window) < 1.25 * min(window)
