"""The sparse least-squares system of one re-embedding and its preconditioned CG solver.

See :mod:`shspec.embed.embed` for the energy, the damping and why the preconditioner is factored in a
nested-dissection order (:mod:`shspec.embed.ordering`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..errors import InvalidArgumentError
from ..mesh.cotan import cotan_stiffness, vertex_areas
from ..mesh.triangle_mesh import TriangleMesh
from .lengths import mesh_edges
from .ordering import nested_dissection

__all__ = ["EmbedSystem"]


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

    Examples
    --------
    >>> from shspec.embed import EmbedSystem
    >>> from shspec.mesh import icosphere
    >>> system = EmbedSystem(icosphere(1), damping=1e-3, ridge=1e-8)
    >>> system.n, system.edges.shape
    (42, (120, 2))
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
        if not np.any(rhs):
            return x, 0  # at a stationary point: the step is 0 (and CG's first ratio would be 0/0)
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
