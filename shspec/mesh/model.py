"""The mesh discretization behind the :class:`~shspec.spectral_model.SpectralModel` interface.

Parameters are per-vertex conformal factors c (n,), dimensionless: the metric is scaled by c_j near vertex j, so
that the mass is M(c) = diag(c)·M_lumped while the cotan stiffness L, conformally invariant, stays fixed
(:doc:`/theory`).
With M-orthonormal eigenvectors, ∂λ_i/∂c_j = −λ_i v_i[j]² m_j, m = diag(M_lumped) the vertex areas.

For a fit the optimizer's variables are c itself (``transform="identity"``) or s = log c (``transform="exp"``):
factors that span decades (the bunny's cMCF factors: 1e-3 … 3e4) stay positive for free in log form, and the
regularizer then smooths s.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..core.atomic import atomic_output
from ..core.checks import check_options, finite_array
from ..errors import InvalidArgumentError, MeshError, NotPositiveError
from ..spectral_model import TRANSFORMS, SpectralModel, Spectrum, regularization_weight
from ..sphere.evaluate import sample_harmonic
from ..sphere.factor import ConformalFactor
from ..sphere.random import random_coefficients
from ..core.threads import reproducible_call
from .bridge import fit_harmonic, mesh_band_limit
from .cotan import cotan_stiffness, vertex_areas
from .eigen import EigenOptions, eigenpairs
from .mesh_files import save_mesh
from .refine import align_vertex_field
from .figures import plot_spectra_validation, plot_vertex_factors
from .triangle_mesh import TriangleMesh

__all__ = ["MeshModel", "REGULARIZER_KINDS", "dirichlet_root"]

#: Smoothness penalties of a mesh fit on its variables u (c, or s = log c): "bilaplacian", R (Lu)ᵀ M₀⁻¹ (Lu) (the
#: continuum R ∫ (Δu)² dA); "dirichlet", R uᵀ L u / 2 = (R/2) ∫ |∇u|² dA; or "cotan-squared", R ‖L u‖² / 2, the
#: study's own penalty: ``eigencost.m`` of levincoolxyz/invspec adds reg·sᵀL²s/2 with its cotan weight matrix L
#: (from late June 2016 on, so in every version behind its 2017 figures; an earlier one that month used the
#: Dirichlet form reg·sᵀ(−L)s/2).  The Dirichlet and cotan-squared forms are dimensionless (the cotan weights and
#: s are), so their R does not depend on the mesh's scale; the bi-Laplacian's scales as 1/area.  The study's R
#: means the same here only with "cotan-squared" on a mesh of area 4π (its ``makeUnitArea(v, f)·sqrt(4π)``).
REGULARIZER_KINDS = ("bilaplacian", "dirichlet", "cotan-squared")

#: Largest ratio of two vertex masses c_j m_j for which the pencil L v = λ diag(c m) v is solved at all: at
#: 1/ε ≈ 4.5e15 no accuracy is left.  Legitimate metrics come close: the constant start on blub_600's cMCF sphere has
#: masses spanning 1.3e10 (its sphere's vertex areas).
_MAX_MASS_SPREAD = 1e14
#: Above this spread a pencil the solver finds broken (a negative eigenvalue, e.g. λ₀ ≈ −1e-8·λ_max on a 42-vertex
#: sphere at a log-factor trial step) is blamed on the masses: a rejected point, not an error of the mesh.
_SUSPECT_MASS_SPREAD = 1e8


def dirichlet_root(mesh: TriangleMesh) -> sp.csr_matrix:
    """G (2m, n) with ‖G u‖² = uᵀ L u = ∫ |∇u|² dA for the piecewise-linear interpolant u of vertex values.

    Rows 2f and 2f + 1 are √A_f times the two components of the (constant) gradient on face f in an orthonormal
    frame of its plane: ∇φ_k = n̂ × e_k / (2A_f), e_k the edge opposite corner k.  Unlike the edge form
    Σ w_ij (u_i − u_j)², this is a real square root on every mesh, obtuse angles (negative cotan weights) included.
    """
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    p = mesh.vertices[mesh.faces]
    e = np.stack([p[:, 2] - p[:, 1], p[:, 0] - p[:, 2], p[:, 1] - p[:, 0]], axis=1)  # (m, 3 corners, 3)
    cross = np.cross(e[:, 0], e[:, 1])
    dbl = np.linalg.norm(cross, axis=1)
    if np.any(dbl <= 0):
        raise MeshError(f"face {int(np.flatnonzero(dbl <= 0)[0])} has zero area: its gradient is undefined")
    nrm = cross / dbl[:, None]
    t1 = e[:, 2] / np.linalg.norm(e[:, 2], axis=1)[:, None]
    t2 = np.cross(nrm, t1)
    grad = np.cross(nrm[:, None, :], e) / dbl[:, None, None]  # (m, 3, 3): ∇φ_k = n̂ × e_k / (2A)
    scale = np.sqrt(0.5 * dbl)[:, None]
    comp = [scale * np.einsum("fkd,fd->fk", grad, t) for t in (t1, t2)]  # (m, 3) each
    m = mesh.nfaces
    rows = np.concatenate([np.repeat(2 * np.arange(m) + j, 3) for j in range(2)])
    cols = np.concatenate([mesh.faces.ravel()] * 2)
    vals = np.concatenate([c.ravel() for c in comp])
    return sp.csr_matrix((vals, (rows, cols)), shape=(2 * m, mesh.nvertices))


class MeshModel(SpectralModel):
    """Cotan Laplace–Beltrami operator of a fixed mesh with per-vertex conformal factors as parameters.

    Parameters
    ----------
    mesh : TriangleMesh
        The reference mesh, n vertices (typically the cMCF sphere of a surface, :attr:`CMCFResult.sphere`).
    options : EigenOptions, optional
        Passed to :func:`~shspec.mesh.eigen.eigenpairs`.
    transform : {"identity", "exp"}
        The variables of a fit: the factors c, or their logarithms s (c = exp(s)).
    lmax_factor : int, optional
        Degree of the harmonic expansion of fitted factors (:meth:`to_factor`); default and cap: the largest the
        mesh determines (:func:`~shspec.mesh.bridge.mesh_band_limit`).
    reg_kind : {"bilaplacian", "dirichlet"}
        The smoothness penalty :meth:`regularizer` puts on the variables, see :data:`REGULARIZER_KINDS`.

    Attributes
    ----------
    nparams : int
        n, one conformal factor per vertex.
    stiffness : (n, n) sparse matrix
        Cotan L (dimensionless).
    vertex_areas : (n,) array
        Lumped areas m_j of the reference mesh (length unit squared).

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.mesh import MeshModel, icosphere
    >>> model = MeshModel(icosphere(2))      # per-vertex factors c on this sphere mesh
    >>> model.nparams, abs(model.eigenvalues(np.ones(model.nparams), 4).round(2))
    (162, array([0., 2., 2., 2.]))
    """

    #: L-BFGS: at 600 vertices and every eigenvalue it reached LM's point in 11 s against 16 s; at 1200 vertices
    #: LM's dense normal equations diverged (measured: the benchmarks page of the docs)
    default_optimizer = "lbfgs"

    def __init__(self, mesh: TriangleMesh, options: EigenOptions | None = None, *, transform: str = "identity",
                 lmax_factor: int | None = None, reg_kind: str = "bilaplacian"):
        if not isinstance(mesh, TriangleMesh):
            raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
        options = check_options(options, EigenOptions)
        if transform not in TRANSFORMS:
            raise InvalidArgumentError(f"transform must be one of {TRANSFORMS}, got {transform!r}")
        if reg_kind not in REGULARIZER_KINDS:
            raise InvalidArgumentError(f"reg_kind must be one of {REGULARIZER_KINDS}, got {reg_kind!r}")
        self.transform = transform
        self.reg_kind = reg_kind
        self.lmax_factor = mesh_band_limit(mesh.nvertices, lmax_factor)
        self.mesh = mesh
        self.options = options
        self.stiffness = cotan_stiffness(mesh).tocsr()
        self.vertex_areas = vertex_areas(mesh)
        self.nparams = mesh.nvertices
        self._bilaplacian = None

    def _factors(self, c) -> np.ndarray:
        try:
            c = np.asarray(c, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidArgumentError(f"conformal factors must be numeric: {exc}") from None
        if c.shape != (self.nparams,):
            raise InvalidArgumentError(f"conformal factors must have shape ({self.nparams},), got {c.shape}")
        if not np.all(np.isfinite(c)):
            raise InvalidArgumentError(f"conformal factor at vertex {int(np.flatnonzero(~np.isfinite(c))[0])} "
                                       "is NaN or inf")
        if np.any(c <= 0):
            bad = np.flatnonzero(c <= 0)
            raise NotPositiveError(f"{bad.size} conformal factors are <= 0 (first: vertex {bad[0]}, "
                                   f"c = {c[bad[0]]:.3g}); a metric needs c > 0")
        mass = c * self.vertex_areas
        if mass.max() > _MAX_MASS_SPREAD * mass.min():
            # A log-factor step can reach factors whose masses differ by more than the precision can carry: the
            # pencil's eigenvalues are then rounding noise (even negative).  Not a usable metric: a rejected trial.
            raise NotPositiveError(f"the vertex masses c_j m_j span {mass.max() / mass.min():.3g} > "
                                   f"{_MAX_MASS_SPREAD:g}: the eigenproblem cannot be solved in double precision")
        return c

    def mass(self, c) -> sp.csr_matrix:
        """M(c) = diag(c · vertex_areas), (n, n), length unit squared."""
        return sp.diags(self._factors(c) * self.vertex_areas).tocsr()

    @reproducible_call
    def spectrum(self, params, k: int, *, start: Spectrum | None = None) -> Spectrum:
        """First k eigenpairs of L v = λ M(c) v (exactly k; see :mod:`shspec.mesh.eigen` on cut multiplets).

        Parameters
        ----------
        params : (n,) array
            Conformal factors c > 0.
        k : int
            Number of eigenpairs, 1 ≤ k < n.
        start : Spectrum, optional
            Ignored: the sparse shift-invert solve gains nothing from it (see :meth:`SpectralModel.spectrum`).

        Returns
        -------
        Spectrum
            Eigenvalues (k,) ascending in 1/(length unit)², eigenvectors (n, k) with VᵀM(c)V = I.

        Raises
        ------
        NotPositiveError
            If some c_j ≤ 0.
        """
        mass = self.mass(params)
        try:
            return eigenpairs(self.stiffness, mass, k, self.options)
        except InvalidArgumentError as exc:
            m = mass.diagonal()
            if m.max() > _SUSPECT_MASS_SPREAD * m.min():
                raise NotPositiveError(f"the vertex masses span {m.max() / m.min():.3g}, and the eigenproblem "
                                       f"failed there: {exc}") from None
            raise

    def _check_spec(self, spec: Spectrum) -> None:
        if not isinstance(spec, Spectrum):
            raise InvalidArgumentError(f"expected a Spectrum, got {type(spec).__name__}")
        if spec.eigenvectors.shape != (self.nparams, spec.k):
            raise InvalidArgumentError(f"spectrum eigenvectors must have shape ({self.nparams}, {spec.k}), got "
                                       f"{spec.eigenvectors.shape}")

    @reproducible_call
    def jacobian(self, spec: Spectrum) -> np.ndarray:
        """∂λ_i/∂c_j = −λ_i v_i[j]² m_j as a (k, n) array (1/area, per unit of c)."""
        self._check_spec(spec)
        V = spec.eigenvectors
        return -(spec.eigenvalues[:, None] * (V.T ** 2)) * self.vertex_areas[None, :]

    @reproducible_call
    def contract(self, spec: Spectrum, coef) -> np.ndarray:
        """Σ_i coef_i ∂λ_i/∂c, shape (n,), for coef (k,): the adjoint gradient, O(n k)."""
        self._check_spec(spec)
        coef = np.asarray(coef, dtype=float)
        if coef.shape != (spec.k,):
            raise InvalidArgumentError(f"coef must have shape ({spec.k},), got {coef.shape}")
        V = spec.eigenvectors
        return -((V ** 2) @ (coef * spec.eigenvalues)) * self.vertex_areas

    def bilaplacian_penalty(self, params, weight: float) -> tuple[float, np.ndarray]:
        """Smoothness regularizer R(c) = w ∫ (Δc)² dA and its gradient, on the reference mesh.

        Discretized as R = w (Lc)ᵀ M₀⁻¹ (Lc), M₀ the lumped reference mass and Δc = M₀⁻¹ L c the cotan Laplacian;
        ∇R = 2 w Lᵀ M₀⁻¹ L c.  It vanishes on constants.

        Parameters
        ----------
        params : (n,) array
            Conformal factors c (any sign is accepted here: the penalty is a quadratic form).
        weight : float
            w ≥ 0; R has the unit of w divided by area.

        Returns
        -------
        value : float
        gradient : (n,) array
        """
        c = finite_array(params, "params", (self.nparams,))
        weight = float(weight)
        if not np.isfinite(weight) or weight < 0:
            raise InvalidArgumentError(f"weight must be finite and >= 0, got {weight}")
        Bc = self.bilaplacian() @ c
        return weight * float(c @ Bc), 2.0 * weight * Bc

    def bilaplacian(self) -> sp.csr_matrix:
        """The symmetric semi-definite (n, n) matrix B = Lᵀ M₀⁻¹ L, so that R(c) = w cᵀBc (Hessian 2wB)."""
        if self._bilaplacian is None:
            # Built on first use: Δ = M₀⁻¹L with the reference lumped mass, and Lᵀ M₀⁻¹ L is symmetric.
            self._bilaplacian = (self.stiffness.T @ sp.diags(1.0 / self.vertex_areas) @ self.stiffness).tocsr()
        return self._bilaplacian

    # -- what the inverse solver asks of a model (shspec.spectral_model.SpectralModel) -------------------------------------

    def describe(self) -> str:
        return (f"mesh n={self.nparams} area={np.round(self.vertex_areas.sum(), 12)}"
                + ("" if self.transform == "identity" else f" {self.transform}")
                + ("" if self.reg_kind == "bilaplacian" else f" reg={self.reg_kind}"))

    def identity(self) -> str:
        """The description, the degree of the escape moves, the eigensolver's options and a hash of the sphere mesh
        (its vertices and faces): two meshes of as many vertices and the same area are two fits."""
        h = hashlib.sha256(np.ascontiguousarray(self.mesh.vertices, dtype=float).tobytes())
        h.update(np.ascontiguousarray(self.mesh.faces, dtype=np.int64).tobytes())
        return f"{self.describe()} La={self.lmax_factor} {self.options!r} mesh sha256 {h.hexdigest()[:16]}"

    def scaled(self, params: np.ndarray, factor: float) -> np.ndarray:
        """factor·c: the factors scale the mass linearly."""
        return np.asarray(params, dtype=float) * factor

    def free_parameters(self, fit_area: bool) -> np.ndarray:
        """Every vertex factor (their sum sets the area, so ``fit_area`` has no separate parameter)."""
        return np.arange(self.nparams)

    def random_start(self, rng: np.random.Generator, amplitude: float, area: float, level: int | None = None,
                     ) -> np.ndarray:
        """Constant factors of the given total area times 1 + a smooth random field of degrees 2 … 4 (RMS ∝
        amplitude/l), halved until it stays above −0.75."""
        self.restrict(level)
        c0 = area / self.vertex_areas.sum()
        field = sample_harmonic(random_coefficients(rng, 4, amplitude), self.mesh.vertices)
        while np.min(field) < -0.75:
            field = field * 0.5
        return c0 * (1.0 + field)

    def regularizer(self, reg: float):
        """The square root D of the penalty on the variables u (c or s), by :attr:`reg_kind`:

        * "bilaplacian": D = √(2R) M₀^{-1/2} L, ½‖Du‖² = R (Lu)ᵀ M₀⁻¹ (Lu) (:meth:`bilaplacian_penalty` with the
          reference vertex areas M₀), (n, n);
        * "dirichlet": D = √R G (:func:`dirichlet_root`), ½‖Du‖² = (R/2) uᵀ L u, (2m, n);
        * "cotan-squared": D = √R L, ½‖Du‖² = (R/2) ‖L u‖², (n, n): the study's reg·sᵀL²s/2.
        """
        reg = regularization_weight(reg)
        if reg == 0:
            return None
        if self.reg_kind == "dirichlet":
            return (np.sqrt(reg) * dirichlet_root(self.mesh)).tocsr()
        if self.reg_kind == "cotan-squared":
            return (np.sqrt(reg) * self.stiffness).tocsr()
        return (sp.diags(np.sqrt(2 * reg / self.vertex_areas)) @ self.stiffness).tocsr()

    def to_factor(self, params: np.ndarray) -> ConformalFactor:
        """The factors expanded in harmonics of degree :attr:`lmax_factor` on the reference mesh (which must lie on
        the unit sphere, as a cMCF sphere does)."""
        c = self._factors(params)
        return ConformalFactor(fit_harmonic(self.mesh, c, self.lmax_factor).coefficients, name="fit (harmonic)")

    def error_root(self, params: np.ndarray) -> np.ndarray:
        """R = diag(√m) / ‖c‖_m (n, n): ‖R δc‖ is the area-weighted relative L2 error of the factors, as
        :meth:`compare` measures it (m the vertex areas)."""
        c = self._factors(params)
        return np.diag(np.sqrt(self.vertex_areas) / np.sqrt(self.vertex_areas @ c ** 2))

    def compare(self, params: np.ndarray, target) -> dict:
        """With the target's per-vertex truth (``target.factors`` on ``target.sphere``, its cMCF factors): the
        area-weighted relative L2 error of the factors, the RMS and the Pearson correlation of their logarithms over
        the vertices, and both ranges.

        On the target's own sphere (same vertex count and positions) the factors are compared vertex by vertex: the
        fit lives on that mesh, no alignment applies.  On another sphere mesh (adaptive refinement, a generic
        icosphere) the fitted log factors are first moved by the Möbius map and element of O(3) that fit the truth's
        best and interpolated at its vertices (:func:`~shspec.mesh.refine.align_vertex_field`).  ``aligned`` says
        which was done, and then ``log_rms_centred`` is the RMS with the canonical centring alone and
        ``mobius_translation`` the size |c| of the translation the fit added to it."""
        truth = getattr(target, "factors", None)
        sphere = getattr(target, "sphere", None)
        if truth is None or sphere is None or np.shape(truth) != (sphere.nvertices,):
            return {}
        c, truth = self._factors(params), np.asarray(truth, dtype=float)
        lt = np.log(truth)
        same = self._on(sphere)
        extra = {}
        if same:
            lc, w = np.log(c), self.vertex_areas
        else:
            al = align_vertex_field(self.mesh, np.log(c), sphere, lt)
            lc, w = al.values, vertex_areas(sphere)
            extra = {"log_rms_centred": al.centred_rms, "mobius_translation": float(np.linalg.norm(al.translation))}
        ct = np.exp(lc)
        return {"factor_error": float(np.sqrt(w @ (ct - truth) ** 2 / (w @ truth ** 2))),
                "log_rms": float(np.sqrt(w @ (lc - lt) ** 2 / w.sum())),
                "log_correlation": float(np.corrcoef(lc, lt)[0, 1]),
                "aligned": not same, **extra,
                "fitted_range": [float(c.min()), float(c.max())], "truth_range": [float(truth.min()), float(truth.max())]}

    def _on(self, sphere) -> bool:
        """Whether ``sphere`` is this model's own mesh (same vertices in the same order)."""
        return (isinstance(sphere, TriangleMesh) and sphere.nvertices == self.nparams
                and np.allclose(sphere.vertices, self.mesh.vertices, atol=1e-12))

    def write_files(self, params: np.ndarray, directory) -> list:
        """Write the fitted per-vertex factors (factors.txt, one per line, vertex order of the model's mesh: a valid
        ``--init`` file) and the model's sphere mesh (sphere.obj) into ``directory``; returns the file names."""
        c = self._factors(params)
        directory = Path(directory)
        with atomic_output(directory / "factors.txt") as tmp:
            np.savetxt(tmp, c, fmt="%.17g",
                       header=f"per-vertex conformal factors c of {self.describe()}, vertex order of sphere.obj")
        save_mesh(self.mesh, directory / "sphere.obj")
        return ["factors.txt", "sphere.obj"]

    def figures(self, params: np.ndarray, target) -> dict:
        """Hammer maps of the fitted factors (with the truth and their ratio when the target has per-vertex
        factors), and the study's validation of spectra when the target has its mesh."""
        truth = getattr(target, "factors", None)
        truth = truth if truth is not None and self._on(getattr(target, "sphere", None)) else None
        out = {"vertex_factors.png": plot_vertex_factors(self.mesh, self._factors(params), truth)}
        if truth is not None and getattr(target, "mesh", None) is not None:
            k = min(np.size(target.eigenvalues), self.nparams - 1)
            out["validation.png"] = plot_spectra_validation(self, params, target.mesh, truth, k)[0]
        return out
