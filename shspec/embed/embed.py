"""Re-embedding: vertex positions in R³ whose edge lengths are those of a conformal factor on a spherical mesh.

Energy
------
In a frame scaled so that the target area is 4π, with r_e = |x_i − x_j| / ℓ'_e − 1 the relative strain of edge e,

    E(x) = 1/(2|E|) Σ_e r_e²  −  β V(x) / (4π),

V the enclosed (signed) volume.  The first term is the mean squared strain; it is sparse (one term per edge) and its
gradient Jᵀr/|E| and Gauss–Newton matrix JᵀJ/|E| (J: |E| × 3n with 6 entries per row) cost O(|E|).  The second is
a *pressure prior*: on a round sphere a pressure β stretches every edge by a strain ≈ β, so β is dimensionless and
reads as "how much strain we trade for volume".  It is the principled default for the bump/dip ambiguity: the
metric does not tell a bump from a dip of the same shape, but the bump encloses more volume, so during the
continuation every new feature grows outwards.  β is switched off for the final iterations, so the result is a
stationary point of the strain alone (the fixed damping makes the convergence linear, not quadratic: it is
stopped by ``tol`` when the remaining decrease is slow), and a dip the metric really forces (through the surrounding lengths) is
kept.  :mod:`shspec.embed.ambiguity` then checks which concave regions could have been the other way.

Solver
------
Gauss–Newton with a smoothing damping (a Levenberg–Marquardt step whose damping is a bi-Laplacian):

    (JᵀJ/|E| + μ B⊗I₃ + ε M⊗I₃) δ = −∇E,      B = L M⁻¹ L / 4π,  M ← M / 4π,

with L and M the cotan stiffness and lumped mass of the sphere mesh.  Edge lengths alone leave the motion of a
vertex normal to a flat one-ring free to first order, and that is where folds start; B penalizes only the
high-frequency part of the step, so smooth inflation is not slowed while vertex-scale wrinkles are.  ε fixes the
rigid motions.  The system is sparse with the two-ring pattern of the mesh (≈ 98 n non-zeros, linear in n) and is
solved inexactly by conjugate gradients (each iteration one O(E) product), preconditioned by S ⊗ I₃ with S the
n × n isotropic part of the matrix, factored by SuperLU once per continuation step in a nested-dissection order
(fill ~ n log n).  A backtracking Armijo line search on E makes every step a descent step.  An optional
bi-Laplacian filter of the factors (:func:`~shspec.embed.lengths.smooth_factors`) handles noisy input factors.

Continuation: the factors grow from 1 to c as c^t (:mod:`shspec.embed.continuation`), a few Gauss–Newton steps
each, then the pressure is turned off and the last step is iterated to convergence.

Limitations
-----------
The metric fixes the shape only up to isometric deformations, and a triangle mesh's edge lengths do not fix its
bending either: a region can be reflected through the plane of its boundary at little cost.  The pressure prior
picks bumps; a true dip is recovered only when the surrounding metric forces it.  The result is defined up to a
rigid motion (its centroid is put at the origin) and a reflection.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..errors import InvalidArgumentError
from ..mesh.cotan import cotan_stiffness, vertex_areas
from ..mesh.triangle_mesh import TriangleMesh
from .continuation import continuation_schedule
from .lengths import check_factors, check_sphere, mesh_edges, smooth_factors, target_edge_lengths
from .quality import edge_length_error, folded_faces, self_intersections

__all__ = ["EmbedOptions", "EmbedResult", "embed", "EmbedSystem", "nested_dissection"]


@dataclass(frozen=True)
class EmbedOptions:
    """Options of :func:`embed`.

    Attributes
    ----------
    steps : int or None
        Continuation steps; None chooses them from the range of log c (see ``max_log_step``).
    max_log_step : float
        Largest change of the centred log-factor per continuation step when ``steps`` is None.
    iterations : int
        Gauss–Newton iterations per intermediate continuation step.
    final_iterations : int
        Most iterations at t = 1 (without pressure).
    tol : float
        Stop a phase when a Gauss–Newton step lowers the energy by less than ``tol`` relative.  The default 2 %
        stops when only the slow drift along near-isometric (soft) deformations is left: on the blob the strain is
        then ~5e-4, ten times below the 5e-3 at which the original mesh itself matches the cMCF target lengths.
    pressure : float
        Pressure prior β ≥ 0 during the continuation (dimensionless strain, see the module notes); 0 removes the
        prior, and the bump/dip choice is then left to rounding.
    damping : float
        Bi-Laplacian step damping μ > 0.
    ridge : float
        Mass-matrix damping ε > 0 that fixes the rigid motions.
    smoothing : float
        Bi-Laplacian filter strength α ≥ 0 applied to the factors first (0: none).
    cg_tol : float
        Relative residual of the inner CG solves (inexact Gauss–Newton).
    cg_maxiter : int
        Most CG iterations per Gauss–Newton step.
    check_intersections : bool
        Count self-intersections in the result (O(m log m), a few seconds at 10⁵ faces).
    """

    steps: int | None = None
    max_log_step: float = 0.35
    iterations: int = 4
    final_iterations: int = 100
    tol: float = 2e-2
    pressure: float = 0.01
    damping: float = 1e-3
    ridge: float = 1e-8
    smoothing: float = 0.0
    cg_tol: float = 1e-2
    cg_maxiter: int = 200
    check_intersections: bool = True

    def __post_init__(self):
        if self.steps is not None and (isinstance(self.steps, bool) or not isinstance(self.steps, (int, np.integer))
                                       or self.steps < 1):
            raise InvalidArgumentError(f"EmbedOptions.steps must be None or a positive integer, got {self.steps!r}")
        for name in ("iterations", "final_iterations", "cg_maxiter"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise InvalidArgumentError(f"EmbedOptions.{name} must be a positive integer, got {value!r}")
        for name in ("max_log_step", "tol", "damping", "ridge", "cg_tol"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise InvalidArgumentError(f"EmbedOptions.{name} must be finite and > 0, got {value!r}")
        for name in ("pressure", "smoothing"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise InvalidArgumentError(f"EmbedOptions.{name} must be finite and >= 0, got {value!r}")


@dataclass(frozen=True)
class EmbedResult:
    """Result of :func:`embed`.

    Attributes
    ----------
    mesh : TriangleMesh
        The embedded surface: the sphere's faces, positions in the factors' length unit, centroid at the origin.
    edges : (E, 2) int array
        The edges, as in :func:`~shspec.embed.lengths.mesh_edges`.
    target_lengths : (E,) array
        ℓ'_e, after the optional smoothing of the factors (length unit).
    edge_error_rms, edge_error_max : float
        RMS and largest relative edge-length error |x_i − x_j|/ℓ'_e − 1.
    folded_faces : int
        Faces folded against an edge-neighbour (:func:`~shspec.embed.quality.folded_faces`).
    self_intersections : int
        Intersecting pairs of non-adjacent faces, or −1 if not checked.
    steps : int
        Continuation steps.
    iterations : int
        Gauss–Newton iterations in all.
    cg_iterations : int
        Preconditioned CG iterations in all (each: one product with the system matrix, O(E)).
    energy : (iterations,) array
        Energy E after each iteration (its pressure term included during the continuation).
    system_nnz : int
        Non-zeros of the sparse 3n × 3n Gauss–Newton matrix (≈ 98 n: 3 × 3 blocks on the two-ring pattern).
    converged : bool
        The final iterations met ``tol`` before ``final_iterations``.
    success : bool
        converged, no folded faces, no self-intersection.
    seconds : float
        Wall time.
    """

    mesh: TriangleMesh
    edges: np.ndarray = field(repr=False)
    target_lengths: np.ndarray = field(repr=False)
    edge_error_rms: float
    edge_error_max: float
    folded_faces: int
    self_intersections: int
    steps: int
    iterations: int
    cg_iterations: int
    energy: np.ndarray = field(repr=False)
    system_nnz: int
    converged: bool
    success: bool
    seconds: float


class EmbedSystem:
    """The sparse least-squares problem of one re-embedding, in the frame of area 4π (see the module notes).

    Parameters
    ----------
    sphere : TriangleMesh
        Unit-sphere mesh, n vertices, E edges.
    damping, ridge : float
        μ and ε.

    Notes
    -----
    Every call costs O(E) except :meth:`precondition`, a sparse Cholesky-like factorization of an n × n matrix in a
    geometric nested-dissection order (:func:`nested_dissection`), whose fill grows like n log n on a sphere mesh.
    SciPy's own orderings (MMD, COLAMD) fill these matrices almost densely: 200 s for the 40962-vertex Laplacian.
    """

    def __init__(self, sphere: TriangleMesh, damping: float, ridge: float):
        self.sphere = sphere
        self.edges = mesh_edges(sphere)
        n = sphere.nvertices
        L = cotan_stiffness(sphere)
        m = vertex_areas(sphere) / (4.0 * np.pi)
        B = (L @ sp.diags(1.0 / m) @ L) / (4.0 * np.pi) ** 2
        self._reg_scalar = (damping * B + ridge * sp.diags(m)).tocsr()
        self._reg = sp.kron(self._reg_scalar, sp.identity(3)).tocsr()
        self._order = nested_dissection(sphere.vertices, self._reg_scalar)
        i, j = self.edges[:, 0], self.edges[:, 1]
        self._rows = np.repeat(np.arange(self.edges.shape[0]), 6)
        self._cols = np.stack([3 * i, 3 * i + 1, 3 * i + 2, 3 * j, 3 * j + 1, 3 * j + 2], axis=1).ravel()
        self.n = n
        self._lu = None

    def residual(self, x: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """Relative strains r_e (E,) of positions x (n, 3) against lengths (E,)."""
        d = x[self.edges[:, 0]] - x[self.edges[:, 1]]
        return np.linalg.norm(d, axis=1) / lengths - 1.0

    def volume(self, x: np.ndarray) -> float:
        """Signed enclosed volume of positions x (n, 3)."""
        p = x[self.sphere.faces]
        return float(np.einsum("ij,ij->", p[:, 0], np.cross(p[:, 1], p[:, 2])) / 6.0)

    def volume_gradient(self, x: np.ndarray) -> np.ndarray:
        """∂V/∂x, (n, 3): each face adds (x₁×x₂, x₂×x₀, x₀×x₁)/6 to its vertices."""
        f = self.sphere.faces
        p = x[f]
        g = np.zeros_like(x)
        for k in range(3):
            contrib = np.cross(p[:, (k + 1) % 3], p[:, (k + 2) % 3]) / 6.0
            for a in range(3):
                g[:, a] += np.bincount(f[:, k], weights=contrib[:, a], minlength=self.n)
        return g

    def energy(self, x: np.ndarray, lengths: np.ndarray, pressure: float) -> float:
        """E(x) of the module notes."""
        r = self.residual(x, lengths)
        return 0.5 * float(r @ r) / r.size - pressure * self.volume(x) / (4.0 * np.pi)

    def jacobian(self, x: np.ndarray, lengths: np.ndarray) -> sp.csr_matrix:
        """J = ∂r/∂x, (E, 3n) with 6 non-zeros per row: ±(x_i − x_j)/(|x_i − x_j| ℓ'_e)."""
        d = x[self.edges[:, 0]] - x[self.edges[:, 1]]
        dist = np.maximum(np.linalg.norm(d, axis=1), 1e-300)
        g = d / (dist * lengths)[:, None]
        return sp.csr_matrix((np.concatenate([g, -g], axis=1).ravel(), (self._rows, self._cols)),
                             shape=(lengths.size, 3 * self.n))

    def matrix(self, x: np.ndarray, lengths: np.ndarray) -> sp.csr_matrix:
        """The damped Gauss–Newton matrix JᵀJ/|E| + μB⊗I₃ + εM⊗I₃, (3n, 3n), symmetric positive definite."""
        J = self.jacobian(x, lengths)
        return (J.T @ J) / lengths.size + self._reg

    def precondition(self, lengths: np.ndarray) -> None:
        """Factor the scalar preconditioner S = Σ_e (e_i − e_j)(e_i − e_j)ᵀ/(3|E|ℓ'_e²) + μB + εM, (n, n).

        S ⊗ I₃ is the isotropic part of the Gauss–Newton matrix (the trace of each edge's 3 × 3 block is spread
        over the three directions); it is factored once per continuation step.
        """
        i, j = self.edges[:, 0], self.edges[:, 1]
        w = 1.0 / (3.0 * lengths.size * lengths ** 2)
        G = sp.csr_matrix((np.concatenate([-w, -w]), (np.concatenate([i, j]), np.concatenate([j, i]))),
                          shape=(self.n, self.n))
        S = G - sp.diags(np.asarray(G.sum(axis=1)).ravel()) + self._reg_scalar
        p = self._order
        self._lu = splu(S[p][:, p].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                        options=dict(SymmetricMode=True))

    def solve(self, A: sp.csr_matrix, rhs: np.ndarray, rtol: float, maxiter: int) -> tuple[np.ndarray, int]:
        """Preconditioned CG for A δ = rhs, δ and rhs (n, 3) interleaved as A's unknowns; returns δ, iterations.

        Inner products use ``einsum`` rather than BLAS: for vectors of this size a threaded BLAS gains nothing and,
        on a loaded machine, its thread pool made each dot product a thousand times slower.
        """
        if self._lu is None:
            raise InvalidArgumentError("call precondition() before solve()")
        p = self._order

        def precond(r):
            z = np.empty_like(r)
            z[p] = self._lu.solve(np.ascontiguousarray(r[p]))
            return z

        def dot(u, v):
            return float(np.einsum("ij,ij->", u, v))

        x = np.zeros_like(rhs)
        r = rhs.copy()
        bound = rtol * np.sqrt(dot(rhs, rhs))
        z = precond(r)
        d = z.copy()
        rz = dot(r, z)
        for it in range(1, maxiter + 1):
            Ad = (A @ d.ravel()).reshape(-1, 3)
            alpha = rz / dot(d, Ad)
            x += alpha * d
            r -= alpha * Ad
            if np.sqrt(dot(r, r)) <= bound:
                return x, it
            z = precond(r)
            rz_new = dot(r, z)
            d = z + (rz_new / rz) * d
            rz = rz_new
        return x, maxiter


def nested_dissection(points: np.ndarray, pattern: sp.spmatrix, leaf: int = 64) -> np.ndarray:
    """Fill-reducing elimination order by geometric nested dissection.

    The vertex set is split at the median of its widest coordinate; the vertices of the lower half that are
    coupled (in ``pattern``) to the upper half form the separator, which is eliminated last.  On a sphere mesh each
    cut is a near-great circle of O(√n) vertices, which gives the n log n fill of planar nested dissection.

    Parameters
    ----------
    points : (n, 3) array
        Vertex positions.
    pattern : (n, n) sparse matrix
        Symmetric sparsity pattern of the matrix to factor.
    leaf : int
        Parts of at most this many vertices are not split further.

    Returns
    -------
    (n,) int array
        A permutation: ``order[k]`` is the vertex eliminated k-th.
    """
    points = np.asarray(points, dtype=float)
    P = sp.csr_matrix(pattern)
    n = points.shape[0]
    if P.shape != (n, n):
        raise InvalidArgumentError(f"pattern must be ({n}, {n}), got {P.shape}")
    out: list[np.ndarray] = []
    # Explicit stack of (vertex set, separator to emit after it): the separator must follow both halves.
    stack: list[tuple[str, np.ndarray]] = [("part", np.arange(n))]
    side = np.zeros(n, dtype=np.int8)
    while stack:
        kind, idx = stack.pop()
        if kind == "sep" or idx.size <= leaf:
            out.append(idx)
            continue
        pts = points[idx]
        axis = int(np.argmax(np.ptp(pts, axis=0)))
        upper = pts[:, axis] > np.median(pts[:, axis])
        side[idx] = np.where(upper, 2, 1)
        lower = idx[~upper]
        rows = P[lower]
        touches = np.zeros(lower.size, dtype=bool)
        hit = side[rows.indices] == 2
        np.logical_or.at(touches, np.repeat(np.arange(lower.size), np.diff(rows.indptr)), hit)
        side[idx] = 0
        sep = lower[touches]
        # Push in reverse: the stack pops the lower part first, then the upper, then the separator.
        stack.append(("sep", sep))
        stack.append(("part", idx[upper]))
        stack.append(("part", lower[~touches]))
    return np.concatenate(out)


def _iterate(system, x, lengths, pressure, max_iter, opt, history, stats):
    """Damped, inexact Gauss–Newton with Armijo backtracking; returns x and whether ``opt.tol`` was met."""
    e0 = system.energy(x, lengths, pressure)
    for _ in range(max_iter):
        A = system.matrix(x, lengths)
        r = system.residual(x, lengths)
        grad = (system.jacobian(x, lengths).T @ r).reshape(-1, 3) / r.size
        if pressure:
            grad -= pressure * system.volume_gradient(x) / (4.0 * np.pi)
        # CG from zero on an SPD matrix returns a descent direction however early it stops, so a loose
        # tolerance only costs Gauss–Newton iterations, never robustness.
        delta, its = system.solve(A, -grad, opt.cg_tol, opt.cg_maxiter)
        stats["nnz"] = A.nnz
        stats["cg"] += its
        slope = float(np.vdot(grad, delta))
        if slope >= 0:
            return x, True
        s = 1.0
        while True:
            trial = x + s * delta
            e1 = system.energy(trial, lengths, pressure)
            if e1 <= e0 + 1e-4 * s * slope:
                break
            s *= 0.5
            if s < 1e-8:
                # No decrease along a descent direction: the energy is at rounding level.
                return x, True
        x = trial
        history.append(e1)
        decrease = e0 - e1
        e0 = e1
        if decrease <= opt.tol * max(abs(e1), 1e-300):
            return x, True
    return x, False


def embed(sphere: TriangleMesh, factors, options: EmbedOptions | None = None) -> EmbedResult:
    """Embed the metric c·g₀ of a unit-sphere mesh in R³.

    Parameters
    ----------
    sphere : TriangleMesh
        Mesh with vertices on the unit sphere, n vertices (e.g. :attr:`CMCFResult.sphere`).
    factors : (n,) array
        Per-vertex conformal factors c > 0 (target area per unit-sphere area, e.g. :attr:`CMCFResult.factors`).
        Harmonic factors: sample them first with :func:`~shspec.mesh.bridge.sample_harmonic`.
    options : EmbedOptions, optional

    Returns
    -------
    EmbedResult

    Raises
    ------
    InvalidArgumentError
        Wrong types or shapes.
    MeshError
        Vertices off the unit sphere.
    NotPositiveError
        A factor ≤ 0.
    """
    opt = options if options is not None else EmbedOptions()
    if not isinstance(opt, EmbedOptions):
        raise InvalidArgumentError(f"options must be EmbedOptions, got {type(opt).__name__}")
    sphere = check_sphere(sphere)
    c = check_factors(factors, sphere.nvertices)
    start = time.perf_counter()
    if opt.smoothing > 0:
        c = smooth_factors(sphere, c, opt.smoothing)
    system = EmbedSystem(sphere, opt.damping, opt.ridge)
    a = vertex_areas(sphere)
    schedule = continuation_schedule(c, opt.steps, max_log_step=opt.max_log_step)
    x = sphere.vertices.copy()
    history: list[float] = []
    stats = {"nnz": 0, "cg": 0}
    converged = False
    for k, t in enumerate(schedule):
        ct = c ** t
        # Each intermediate metric is rescaled to area 4π: only the shape changes from step to step.
        lengths = target_edge_lengths(sphere, ct, system.edges) * np.sqrt(4.0 * np.pi / (ct @ a))
        system.precondition(lengths)
        x, _ = _iterate(system, x, lengths, opt.pressure, opt.iterations, opt, history, stats)
        if k == schedule.size - 1:
            x, converged = _iterate(system, x, lengths, 0.0, opt.final_iterations, opt, history, stats)
    scale = np.sqrt((c @ a) / (4.0 * np.pi))
    x = (x - x.mean(axis=0)) * scale
    mesh = sphere.with_vertices(x)
    target = target_edge_lengths(sphere, c, system.edges)
    rms, emax = edge_length_error(mesh, system.edges, target)
    folds = folded_faces(mesh)
    inter = self_intersections(mesh) if opt.check_intersections else -1
    return EmbedResult(mesh=mesh, edges=system.edges, target_lengths=target, edge_error_rms=rms,
                       edge_error_max=emax, folded_faces=folds, self_intersections=inter, steps=schedule.size,
                       iterations=len(history), cg_iterations=stats["cg"], energy=np.array(history),
                       system_nnz=int(stats["nnz"]),
                       converged=bool(converged), success=bool(converged and folds == 0 and inter <= 0),
                       seconds=time.perf_counter() - start)
