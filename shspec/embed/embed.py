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

Scale
-----
The factors are divided by their area-weighted mean c̄ first and the result is scaled by √c̄ at the end (the
metric's scale is a similarity): the solver always works at area 4π, and factors of 1e300 neither overflow nor
underflow.  Constant factors are the round sphere itself, returned at once (no continuation, no pressure).

Code
----
Options and result in :mod:`.options`, the sparse system and its CG solver in :mod:`.system`, the elimination
order in :mod:`.ordering`, the Levenberg–Marquardt loop and the continuation in :mod:`.solver` (with the damping
rule of :mod:`shspec.core.damping`), the coercion of the input factors in :mod:`.inputs`.

Limitations
-----------
The metric fixes the shape only up to isometric deformations, and a triangle mesh's edge lengths do not fix its
bending either: a region can be reflected through the plane of its boundary at little cost.  The pressure prior
picks bumps; a true dip is recovered only when the surrounding metric forces it.  The result is defined up to a
rigid motion (its centroid is put at the origin) and a reflection.
"""

from __future__ import annotations

import time

import numpy as np

from ..core.checks import check_options
from ..errors import InvalidArgumentError
from ..mesh.cotan import vertex_areas
from ..mesh.triangle_mesh import TriangleMesh
from ..core.threads import reproducible_call
from .inputs import vertex_factors
from .lengths import check_sphere, smooth_factors, target_edge_lengths
from .options import EmbedOptions, EmbedResult
from .quality import edge_length_error, folded_faces, self_intersections
from .solver import lm_iterate, run_continuation
from .system import EmbedSystem

__all__ = ["EmbedOptions", "EmbedResult", "embed"]


@reproducible_call
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
    InvalidArgumentError
        Factors whose ratio max/min overflows (> 1e308).

    Examples
    --------
    >>> from shspec.embed import embed, surface_distance
    >>> from shspec.mesh import blob, cmcf
    >>> surface = blob(2)
    >>> flow = cmcf(surface)                 # sphere mesh and per-vertex conformal factors
    >>> result = embed(flow.sphere, flow.factors)
    >>> result.success, result.folded_faces, surface_distance(result.mesh, surface).hausdorff_relative < 0.05
    (True, 0, True)
    """
    opt = check_options(options, EmbedOptions)
    sphere = check_sphere(sphere)
    c = vertex_factors(sphere, factors)
    start, cpu = time.perf_counter(), time.process_time()
    if opt.smoothing > 0:
        c = smooth_factors(sphere, c, opt.smoothing)
    system = EmbedSystem(sphere, opt.damping, opt.ridge)
    a = vertex_areas(sphere)
    # the mean of log c, not of c: it cannot overflow, and c/mean then spans at most the range of the input
    unit = np.exp(np.log(c) @ a / a.sum())
    c = c / unit
    if not np.all(np.isfinite(c)):
        raise InvalidArgumentError(f"the factors span more than the float range (max/min = "
                                   f"{np.max(np.log10(c * unit)) - np.min(np.log10(c * unit)):.0f} decades)")
    scale = np.sqrt(unit * (c @ a) / (4.0 * np.pi))
    history: list[float] = []
    stats = {"nnz": 0, "cg": 0}
    if np.ptp(np.log(c)) <= 4 * np.finfo(float).eps:
        # the sphere's own lengths, in the frame of area 4π that ``scale`` undoes
        x, steps, retries, converged = sphere.vertices * np.sqrt(4.0 * np.pi / (c @ a)), 0, 0, True
    else:
        x, lengths, steps, retries = run_continuation(system, sphere, c, a, sphere.vertices.copy(), opt, history,
                                                      stats)
        x, converged = lm_iterate(system, x, lengths, 0.0, opt.final_iterations, opt, history, stats)
    x = (x - x.mean(axis=0)) * scale
    mesh = sphere.with_vertices(x)
    target = target_edge_lengths(sphere, c, system.edges) * np.sqrt(unit)
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
                       final_damping=float(system.damping), factorizations=int(stats.get("factorizations", 0)))
