"""Options and result of :func:`~shspec.embed.embed.embed`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.checks import check_float, check_int
from ..errors import InvalidArgumentError
from ..mesh.triangle_mesh import TriangleMesh

__all__ = ["EmbedOptions", "EmbedResult"]


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
        relative, or leaves an rms strain below ``strain_tol``.  The default 2 % stops when only the slow drift along near-isometric (soft) deformations is left:
        on the blob the strain is then ~5e-4, ten times below the 5e-3 at which the original mesh itself matches the
        cMCF target lengths.
    strain_tol : float
        An rms strain this small counts as exact (10⁻⁹: far below any discretization error of factors, far above
        rounding); a phase that reaches it has converged, however slowly the energy still decreases.
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

    Examples
    --------
    >>> from shspec.embed import EmbedOptions, embed
    >>> from shspec.mesh import blob, cmcf
    >>> flow = cmcf(blob(2))
    >>> result = embed(flow.sphere, flow.factors, EmbedOptions(final_iterations=20, check_intersections=False))
    >>> result.self_intersections            # -1: not checked
    -1
    """

    steps: int | None = None
    max_log_step: float = 1.4
    continuation_strain: float = 0.05
    min_step: float = 1e-3
    iterations: int = 4
    final_iterations: int = 100
    tol: float = 2e-2
    strain_tol: float = 1e-9
    pressure: float = 0.01
    damping: float = 1e-3
    min_damping: float | None = None
    ridge: float = 1e-8
    smoothing: float = 0.0
    cg_tol: float = 1e-2
    cg_maxiter: int = 200
    check_intersections: bool = True

    def __post_init__(self):
        check_int(self.steps, "EmbedOptions.steps", minimum=1, allow_none=True)
        for name in ("iterations", "final_iterations", "cg_maxiter"):
            value = getattr(self, name)
            check_int(value, f"EmbedOptions.{name}", minimum=1)
        for name in ("max_log_step", "continuation_strain", "tol", "strain_tol", "damping", "ridge", "cg_tol"):
            check_float(getattr(self, name), f"EmbedOptions.{name}", positive=True)
        for name in ("pressure", "smoothing"):
            check_float(getattr(self, name), f"EmbedOptions.{name}", minimum=0.0)
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
        Accepted continuation steps (0 for constant factors, whose answer is the scaled sphere itself).
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
    factorizations : int
        Sparse factorizations of the preconditioner (once per continuation step, and when μ moved by more than 4×).

    Examples
    --------
    >>> from shspec.embed import embed
    >>> from shspec.mesh import blob, cmcf
    >>> flow = cmcf(blob(2))
    >>> result = embed(flow.sphere, flow.factors)
    >>> result.mesh, result.edge_error_rms < 0.01, result.converged
    (TriangleMesh(162 vertices, 320 faces), True, True)
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
    factorizations: int = 0
