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
stationary point of the strain alone (the damping floor makes the convergence linear, not quadratic: it is
stopped by ``tol`` when the remaining decrease is slow), and a dip the metric really forces (through the surrounding
lengths) is kept.  :mod:`shspec.embed.ambiguity` then checks which concave regions could have been the other way.

Solver
------
Levenberg–Marquardt with a smoothing damping (a bi-Laplacian trust region):

    (JᵀJ/|E| + μ B⊗I₃ + ε M⊗I₃) δ = −∇E,      B = L M⁻¹ L / 4π,

with L the cotan stiffness of the sphere mesh and M the lumped mass *of the target metric* (sphere vertex area
times the local area ratio (ℓ'/ℓ)², in the frame of area 4π, total ≈ 1).  Edge lengths alone leave the motion of
a vertex normal to a flat one-ring free to first order, and that is where folds start; B penalizes only the
high-frequency part of the step, so smooth inflation is not slowed while vertex-scale wrinkles are.  The metric
masses matter for extreme factors: with the unit sphere's own masses, B grows like 1/(sphere edge)² where the sphere
is compressed (the bunny's ears: c up to 10⁷ × the smallest), so a fixed μ damped those regions 10⁴ × more than
JᵀJ and the solver stalled at 25 % rms strain; with the metric's masses B and JᵀJ scale alike everywhere (the
cotan L is scale invariant).  ε fixes the rigid motions.

μ is adapted by the gain ratio ϱ = (actual decrease of E) / (decrease predicted by the Gauss–Newton model
−∇E·δ − ½|Jδ|²/|E|): a step with ϱ ≤ 0 is rejected and μ doubles (then quadruples, ...), an accepted step shrinks μ
by max(1/3, 1 − (2ϱ − 1)³) (Nielsen's rule), never below ``min_damping``.  Measured on bunny_1200, letting μ fall
below ~1e-3 buys strain *below* the one of the true bunny against the same lengths (0.3 % against 6 %) by crumpling
(126 folded faces) and moves the ears further away (Hausdorff 15 % against 6 % of the diagonal): the factors'
discretization error is absorbed by wrinkles.  So ``min_damping`` defaults to the starting μ, and the trust region
only grows the damping where the model is poor.

The system is sparse with the two-ring pattern of the mesh (≈ 98 n non-zeros, linear in n) and is solved inexactly
by conjugate gradients (each iteration one O(E) product), preconditioned by S ⊗ I₃ with S the n × n isotropic part
of the matrix, factored by SuperLU in a nested-dissection order (fill ~ n log n) once per continuation step and
again only when μ has moved by more than a factor 4 since.  An optional bi-Laplacian filter of the factors
(:func:`~shspec.embed.lengths.smooth_factors`) handles noisy input factors.

Continuation: the factors grow from 1 to c as c^t (:mod:`shspec.embed.continuation`), a few iterations each.  The
step in t adapts to the strain: a step after which the rms strain exceeds ``continuation_strain`` and twice the
strain of the previous accepted step is undone and halved; after an accepted step the next one doubles.  Then the
pressure is turned off and the last metric is iterated to convergence.

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

__all__ = ["EmbedOptions", "EmbedResult", "embed", "EmbedSystem", "nested_dissection", "vertex_factors"]


@dataclass(frozen=True)
class EmbedOptions:
    """Options of :func:`embed`.

    Attributes
    ----------
    steps : int or None
        Continuation steps: an int fixes a uniform schedule t = k/steps (no adaptation); None adapts the steps to
        the strain, starting from the step given by ``max_log_step``.
    max_log_step : float
        Change of the centred log-factor over the first continuation step when ``steps`` is None.
    continuation_strain : float
        A continuation step whose rms strain after its iterations exceeds both this and twice the strain after the
        previous step is undone and halved (``steps`` None only).
    min_step : float
        Smallest continuation step in t; a step this small is accepted whatever its strain.
    iterations : int
        Levenberg–Marquardt iterations per intermediate continuation step.
    final_iterations : int
        Most iterations at t = 1 (without pressure).
    tol : float
        Stop a phase when an accepted step (with a gain ratio > 1/4) lowers the energy by less than ``tol``
        relative.  The default 2 % stops when only the slow drift along near-isometric (soft) deformations is left:
        on the blob the strain is then ~5e-4, ten times below the 5e-3 at which the original mesh itself matches the
        cMCF target lengths.
    pressure : float
        Pressure prior β ≥ 0 during the continuation (dimensionless strain, see the module notes); 0 removes the
        prior, and the bump/dip choice is then left to rounding.
    damping : float
        Starting bi-Laplacian step damping μ > 0 of the trust region.
    min_damping : float or None
        Floor of μ (None: ``damping``; see the module notes for why lower floors crumple extreme shapes).
    ridge : float
        Mass-matrix damping ε > 0 that fixes the rigid motions.
    smoothing : float
        Bi-Laplacian filter strength α ≥ 0 applied to the factors first (0: none).
    cg_tol : float
        Relative residual of the inner CG solves (inexact Levenberg–Marquardt).
    cg_maxiter : int
        Most CG iterations per step.
    check_intersections : bool
        Count self-intersections in the result (O(m log m), a few seconds at 10⁵ faces).
    """

    steps: int | None = None
    max_log_step: float = 1.4
    continuation_strain: float = 0.05
    min_step: float = 1e-3
    iterations: int = 4
    final_iterations: int = 100
    tol: float = 2e-2
    pressure: float = 0.01
    damping: float = 1e-3
    min_damping: float | None = None
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
        for name in ("max_log_step", "continuation_strain", "tol", "damping", "ridge", "cg_tol"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise InvalidArgumentError(f"EmbedOptions.{name} must be finite and > 0, got {value!r}")
        for name in ("pressure", "smoothing"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise InvalidArgumentError(f"EmbedOptions.{name} must be finite and >= 0, got {value!r}")
        if not (np.isfinite(self.min_step) and 0 < self.min_step <= 1):
            raise InvalidArgumentError(f"EmbedOptions.min_step must be in (0, 1], got {self.min_step!r}")
        if self.min_damping is not None and not (np.isfinite(self.min_damping) and 0 < self.min_damping):
            raise InvalidArgumentError(f"EmbedOptions.min_damping must be None or finite and > 0, "
                                       f"got {self.min_damping!r}")


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
        Accepted continuation steps.
    iterations : int
        Accepted Levenberg–Marquardt iterations in all.
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
    cpu_seconds : float
        CPU time of this process (the honest measure on a shared machine).
    rejected_iterations : int
        Levenberg–Marquardt steps rejected by the trust region (μ grew).
    continuation_retries : int
        Continuation steps undone and halved because of their strain.
    final_damping : float
        μ at the end.
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
    cpu_seconds: float = 0.0
    rejected_iterations: int = 0
    continuation_retries: int = 0
    final_damping: float = float("nan")


class EmbedSystem:
    """The sparse least-squares problem of one re-embedding, in the frame of area 4π (see the module notes).

    Parameters
    ----------
    sphere : TriangleMesh
        Unit-sphere mesh, n vertices, E edges.
    damping, ridge : float
        Starting μ and ε.

    Notes
    -----
    Every call costs O(E) except :meth:`precondition`, a sparse Cholesky-like factorization of an n × n matrix in a
    geometric nested-dissection order (:func:`nested_dissection`), whose fill grows like n log n on a sphere mesh.
    SciPy's own orderings (MMD, COLAMD) fill these matrices almost densely: 200 s for the 40962-vertex Laplacian.
    The damping terms use the metric of the lengths last given to :meth:`set_metric` (or :meth:`precondition`);
    until then, the unit sphere's.
    """

    def __init__(self, sphere: TriangleMesh, damping: float, ridge: float):
        self.sphere = sphere
        self.edges = mesh_edges(sphere)
        n = sphere.nvertices
        self.n = n
        self.damping = float(damping)
        self.ridge = float(ridge)
        self._L = cotan_stiffness(sphere).tocsr()
        self._area = vertex_areas(sphere) / (4.0 * np.pi)
        i, j = self.edges[:, 0], self.edges[:, 1]
        self._chord = np.linalg.norm(sphere.vertices[i] - sphere.vertices[j], axis=1)
        self._degree = np.bincount(self.edges.ravel(), minlength=n)
        self._rows = np.repeat(np.arange(self.edges.shape[0]), 6)
        self._cols = np.stack([3 * i, 3 * i + 1, 3 * i + 2, 3 * j, 3 * j + 1, 3 * j + 2], axis=1).ravel()
        self._lu = None
        self._factored_damping = None
        self._metric_lengths = None
        self._set_masses(self._area)
        self._order = nested_dissection(sphere.vertices, self._reg_scalar)

    def _set_masses(self, m: np.ndarray) -> None:
        self.masses = m
        self._B = ((self._L @ sp.diags(1.0 / m) @ self._L) / (4.0 * np.pi) ** 2).tocsr()
        self._M = sp.diags(m).tocsr()
        self._Bk = sp.kron(self._B, sp.identity(3)).tocsr()
        self._Mk = sp.kron(self._M, sp.identity(3)).tocsr()

    @property
    def _reg_scalar(self) -> sp.csr_matrix:
        """μB + εM, (n, n)."""
        return (self.damping * self._B + self.ridge * self._M).tocsr()

    def set_metric(self, lengths: np.ndarray) -> None:
        """Take the lumped masses of the damping from target lengths (E,) in the area-4π frame.

        The mass of vertex i is its unit-sphere vertex area times the geometric mean over its edges of the area
        ratio (ℓ'_e/ℓ_e)² (ℓ_e the sphere's chord), i.e. ≈ c_i for lengths of factors c; scaled by 1/4π.
        """
        lengths = np.asarray(lengths, dtype=float)
        if lengths.shape != self._chord.shape:
            raise InvalidArgumentError(f"lengths must have shape {self._chord.shape}, got {lengths.shape}")
        if self._metric_lengths is not None and np.array_equal(lengths, self._metric_lengths):
            return
        log_ratio = 2.0 * np.log(lengths / self._chord)
        mean = np.bincount(self.edges.ravel(), weights=np.repeat(log_ratio, 2), minlength=self.n) / self._degree
        self._set_masses(self._area * np.exp(mean))
        self._metric_lengths = lengths.copy()
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
        return (J.T @ J) / lengths.size + self.damping * self._Bk + self.ridge * self._Mk

    def precondition(self, lengths: np.ndarray) -> None:
        """Set the metric of ``lengths`` and factor the scalar preconditioner, (n, n),

        S = Σ_e (e_i − e_j)(e_i − e_j)ᵀ/(3|E|ℓ'_e²) + μB + εM.

        S ⊗ I₃ is the isotropic part of the Gauss–Newton matrix (the trace of each edge's 3 × 3 block is spread
        over the three directions); it is factored once per continuation step and when μ has changed a lot.
        """
        self.set_metric(lengths)
        i, j = self.edges[:, 0], self.edges[:, 1]
        w = 1.0 / (3.0 * lengths.size * lengths ** 2)
        G = sp.csr_matrix((np.concatenate([-w, -w]), (np.concatenate([i, j]), np.concatenate([j, i]))),
                          shape=(self.n, self.n))
        S = G - sp.diags(np.asarray(G.sum(axis=1)).ravel()) + self._reg_scalar
        p = self._order
        self._lu = splu(S[p][:, p].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                        options=dict(SymmetricMode=True))
        self._factored_damping = self.damping

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
    """Levenberg–Marquardt with the bi-Laplacian trust region of the module notes; returns x and whether ``opt.tol``
    was met (or no further decrease is possible).  μ lives in ``system.damping`` and carries over between calls."""
    floor = opt.min_damping if opt.min_damping is not None else opt.damping
    ceiling = 1e8 * floor
    growth = 2.0
    e0 = system.energy(x, lengths, pressure)
    for _ in range(max_iter):
        if system._lu is None or not 0.25 <= system.damping / system._factored_damping <= 4.0:
            system.precondition(lengths)
            stats["factorizations"] = stats.get("factorizations", 0) + 1
        A = system.matrix(x, lengths)
        J = system.jacobian(x, lengths)
        r = system.residual(x, lengths)
        grad = (J.T @ r).reshape(-1, 3) / r.size
        if pressure:
            grad -= pressure * system.volume_gradient(x) / (4.0 * np.pi)
        # CG from zero on an SPD matrix returns a descent direction however early it stops, so a loose
        # tolerance only costs iterations, never robustness.
        delta, its = system.solve(A, -grad, opt.cg_tol, opt.cg_maxiter)
        stats["nnz"] = A.nnz
        stats["cg"] += its
        Jd = J @ delta.ravel()
        predicted = -(float(np.vdot(grad, delta)) + 0.5 * float(Jd @ Jd) / r.size)
        if not predicted > 0:
            return x, True
        trial = x + delta
        e1 = system.energy(trial, lengths, pressure)
        gain = (e0 - e1) / predicted
        if gain > 0:
            x = trial
            history.append(e1)
            decrease = e0 - e1
            e0 = e1
            system.damping = max(floor, system.damping * max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3))
            growth = 2.0
            if gain > 0.25 and decrease <= opt.tol * max(abs(e1), 1e-300):
                return x, True
        else:
            stats["rejected"] = stats.get("rejected", 0) + 1
            if system.damping >= ceiling:
                # No decrease even with a tiny, smooth step: the energy is at rounding level.
                return x, True
            system.damping = min(ceiling, system.damping * growth)
            growth *= 2.0
    return x, False


def vertex_factors(sphere: TriangleMesh, factors) -> np.ndarray:
    """Per-vertex factors (n,) of a sphere mesh from per-vertex values or a harmonic ρ sampled at the vertices.

    Parameters
    ----------
    sphere : TriangleMesh
        Unit-sphere mesh, n vertices.
    factors : (n,) array, ConformalFactor, pyshtools SHCoeffs, cilm array (2, L+1, L+1) or (N,) coefficients
        A (n,) array is read as per-vertex values, also when n happens to be a square (L+1)²; any other 1-D
        length (L+1)² as flat harmonic coefficients of ρ (shspec's convention), which are evaluated at the vertex
        directions (:func:`~shspec.mesh.bridge.sample_harmonic`).

    Returns
    -------
    (n,) array
        Values c > 0.

    Raises
    ------
    InvalidArgumentError
        Not numeric, or a length that is neither n nor a square.
    NotPositiveError
        ρ ≤ 0 at some vertex (a band-limited expansion of extreme factors can be).
    """
    from ..sphere.factor import ConformalFactor
    from ..sphere.evaluate import sample_harmonic

    sphere = check_sphere(sphere)
    n = sphere.nvertices
    if isinstance(factors, ConformalFactor):
        values = sample_harmonic(factors.coefficients, sphere.vertices)
    elif type(factors).__module__.startswith("pyshtools"):
        values = sample_harmonic(factors, sphere.vertices)
    else:
        try:
            arr = np.asarray(factors, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidArgumentError(f"factors must be numeric: {exc}") from None
        if arr.shape == (n,):
            values = arr
        elif arr.ndim == 3 or (arr.ndim == 1 and arr.size > 0 and round(np.sqrt(arr.size)) ** 2 == arr.size):
            if not np.all(np.isfinite(arr)):
                raise InvalidArgumentError("harmonic coefficients contain NaN or inf")
            values = sample_harmonic(arr, sphere.vertices)
        else:
            raise InvalidArgumentError(f"factors must be ({n},) per-vertex values or (L+1)² harmonic coefficients, "
                                       f"got shape {arr.shape}")
    return check_factors(values, n)


def _continuation(system, sphere, c, area, x, opt, history, stats):
    """Run the continuation c^t, t → 1, with pressure; returns x, the last lengths, accepted steps and retries."""
    if opt.steps is not None:
        schedule = list(continuation_schedule(c, opt.steps))
        adaptive = False
        dt = 1.0 / opt.steps
    else:
        adaptive = True
        dt = float(continuation_schedule(c, None, max_log_step=opt.max_log_step)[0])
    t, strain, steps, retries = 0.0, 0.0, 0, 0
    while t < 1.0:
        t_new = schedule[steps] if not adaptive else (1.0 if t + 1.5 * dt >= 1.0 else t + dt)
        ct = c ** t_new
        # Each intermediate metric is rescaled to area 4π: only the shape changes from step to step.
        lengths = target_edge_lengths(sphere, ct, system.edges) * np.sqrt(4.0 * np.pi / (ct @ area))
        system.precondition(lengths)
        damping, n_hist = system.damping, len(history)
        y, _ = _iterate(system, x, lengths, opt.pressure, opt.iterations, opt, history, stats)
        r = system.residual(y, lengths)
        new_strain = float(np.sqrt(np.mean(r * r)))
        if (adaptive and new_strain > max(opt.continuation_strain, 2.0 * strain)
                and t_new - t > opt.min_step * 1.0001):
            # Undo: the iterations did not catch up with this much change of the metric.
            del history[n_hist:]
            system.damping = damping
            dt = max(opt.min_step, 0.5 * (t_new - t))
            retries += 1
            continue
        dt = min(2.0 * (t_new - t), 1.0)
        x, t, strain = y, t_new, new_strain
        steps += 1
    return x, lengths, steps, retries


def embed(sphere: TriangleMesh, factors, options: EmbedOptions | None = None) -> EmbedResult:
    """Embed the metric c·g₀ of a unit-sphere mesh in R³.

    Parameters
    ----------
    sphere : TriangleMesh
        Mesh with vertices on the unit sphere, n vertices (e.g. :attr:`CMCFResult.sphere`).
    factors : (n,) array, ConformalFactor, SHCoeffs, cilm array or (N,) coefficients
        Per-vertex conformal factors c > 0 (target area per unit-sphere area, e.g. :attr:`CMCFResult.factors`),
        or a harmonic ρ, sampled at the vertices (see :func:`vertex_factors`).
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
    c = vertex_factors(sphere, factors)
    start, cpu = time.perf_counter(), time.process_time()
    if opt.smoothing > 0:
        c = smooth_factors(sphere, c, opt.smoothing)
    system = EmbedSystem(sphere, opt.damping, opt.ridge)
    a = vertex_areas(sphere)
    history: list[float] = []
    stats = {"nnz": 0, "cg": 0}
    x, lengths, steps, retries = _continuation(system, sphere, c, a, sphere.vertices.copy(), opt, history, stats)
    x, converged = _iterate(system, x, lengths, 0.0, opt.final_iterations, opt, history, stats)
    scale = np.sqrt((c @ a) / (4.0 * np.pi))
    x = (x - x.mean(axis=0)) * scale
    mesh = sphere.with_vertices(x)
    target = target_edge_lengths(sphere, c, system.edges)
    rms, emax = edge_length_error(mesh, system.edges, target)
    folds = folded_faces(mesh)
    inter = self_intersections(mesh) if opt.check_intersections else -1
    return EmbedResult(mesh=mesh, edges=system.edges, target_lengths=target, edge_error_rms=rms,
                       edge_error_max=emax, folded_faces=folds, self_intersections=inter, steps=steps,
                       iterations=len(history), cg_iterations=stats["cg"], energy=np.array(history),
                       system_nnz=int(stats["nnz"]),
                       converged=bool(converged), success=bool(converged and folds == 0 and inter <= 0),
                       seconds=time.perf_counter() - start, cpu_seconds=time.process_time() - cpu,
                       rejected_iterations=int(stats.get("rejected", 0)), continuation_retries=retries,
                       final_damping=float(system.damping))
