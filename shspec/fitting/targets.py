"""The builders of targets: from a harmonic ρ, from a mesh (its :class:`MeshTarget`), from a spectrum file, and from
the command-line syntax ``blob | star:l,m,p | mesh:PATH | spectrum:FILE`` (:func:`parse_target`).

A mesh's cMCF factors are its truth; its target is its PL spectrum, the PL spectrum of its cMCF sphere carrying the
factors, or the harmonic spectrum of the factors' expansion (:data:`TARGET_SOURCES`).  A mesh's eigenvalues carry
their discretization error, which :func:`refined_target` estimates from the mesh's 4-to-1 subdivisions.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.ndimage import maximum_filter1d

from ..core.checks import check_int, real_array
from ..errors import InvalidArgumentError
from ..galerkin.model import HarmonicModel
from ..inverse.target import Target, estimate_area
from ..mesh.bridge import fit_harmonic, mesh_band_limit
from ..mesh.cmcf import CMCFResult, cmcf
from ..mesh.cotan import cotan_stiffness, vertex_areas
from ..mesh.eigen import eigenpairs, mesh_spectrum
from ..mesh.builtin import resolve_mesh_path
from ..mesh.mesh_files import load_mesh
from ..mesh.refine import refined_eigenvalues
from ..mesh.shapes import star_surface
from ..mesh.triangle_mesh import TriangleMesh
from ..sphere.factor import ConformalFactor
from ..sphere.harmonics import flat_index, ncoeffs
from ..spectrum_file import check_spectrum_path, read_spectrum, read_spectrum_file

__all__ = ["BLOB_HARMONIC", "blob_factor", "Target", "MeshTarget", "harmonic_target", "mesh_target", "spectrum_target",
           "read_spectrum", "estimate_area", "parse_target", "TARGET_SOURCES", "subdivision_spectra",
           "subdivision_changes", "with_discretization_errors", "refined_target", "refinement_levels",
           "RICHARDSON_FACTOR", "REFINED_VERTICES"]

#: The built-in harmonic blob: ρ = Σ a_lm Y_lm with these coefficients, (l, m) -> a_lm, mean value 1 (area 4π).
#: Degree 6, every degree but 1 present (a_1m = 0: it is Möbius-centred), orders of both signs so that it has no
#: symmetry plane, amplitudes falling with the degree so that it is smooth; min ρ ≈ 0.55, max ρ ≈ 1.9.
BLOB_HARMONIC = {
    (0, 0): float(np.sqrt(4.0 * np.pi)),
    (2, 0): 0.40,
    (2, 2): 0.25,
    (2, -1): -0.10,
    (3, 1): -0.22,
    (3, -2): 0.16,
    (4, 3): 0.11,
    (4, 0): 0.08,
    (5, -4): 0.06,
    (5, 2): -0.04,
    (6, 5): 0.03,
    (6, -1): 0.02,
}

#: Where a mesh target's spectrum comes from: the cotan spectrum of the mesh ("pl"); the cotan spectrum of its cMCF
#: sphere carrying the cMCF factors, M = diag(c)·M_sphere ("cmcf": exactly what a per-vertex fit on that sphere
#: can represent, a zero-residual test of the solver); or the Galerkin spectrum of its cMCF factors expanded in
#: harmonics of degree La ("harmonic").
TARGET_SOURCES = ("pl", "cmcf", "harmonic")


def blob_factor(lmax: int = 6) -> ConformalFactor:
    """The built-in blob ρ (:data:`BLOB_HARMONIC`), zero-padded to degree ``lmax`` ≥ 6.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.fitting import blob_factor
    >>> rho = blob_factor()
    >>> rho.lmax, round(rho.area / (4 * np.pi), 12)     # degree 6, the unit sphere's area
    (6, 1.0)
    """
    lmax = check_int(lmax, "lmax (the blob has degree 6)", minimum=6)
    a = np.zeros(ncoeffs(lmax))
    for (l, m), value in BLOB_HARMONIC.items():
        a[int(flat_index(l, m))] = value
    return ConformalFactor(a, name="blob")


@dataclass(frozen=True)
class MeshTarget(Target):
    """The target of a mesh: a :class:`~shspec.inverse.Target` with the mesh's cMCF.

    Attributes
    ----------
    sphere : TriangleMesh
        The cMCF sphere, n vertices, vertex i over the mesh's vertex i.
    factors : (n,) array
        The per-vertex cMCF factors: the PL truth.
    mesh : TriangleMesh or None
        The target surface (None: a target made on the sphere alone, e.g. a synthetic one).
    source : str
        Which spectrum of the mesh the eigenvalues are, one of :data:`TARGET_SOURCES`.

    Examples
    --------
    >>> from shspec.fitting import mesh_target
    >>> from shspec.mesh import load_mesh
    >>> t = mesh_target(load_mesh("spot_600"), lmax=20, numeig=30, lmax_factor=6)
    >>> type(t).__name__, t.source, t.numeig, t.sphere.nvertices == t.factors.size
    ('MeshTarget', 'pl', 30, True)
    """

    sphere: TriangleMesh = field(default=None, repr=False)
    factors: np.ndarray = field(default=None, repr=False)
    mesh: TriangleMesh | None = field(default=None, repr=False)
    source: str = "pl"

    def __post_init__(self):
        super().__post_init__()
        if not isinstance(self.sphere, TriangleMesh):
            raise InvalidArgumentError(f"a mesh target's sphere is a TriangleMesh, got {type(self.sphere).__name__}")
        c = real_array(self.factors, "a mesh target's factors")
        if c.shape != (self.sphere.nvertices,) or not np.all(c > 0):
            raise InvalidArgumentError(f"a mesh target's factors are ({self.sphere.nvertices},) positive values, one "
                                       f"per vertex of its sphere; got shape {c.shape}")
        object.__setattr__(self, "factors", c)
        if self.mesh is not None and not isinstance(self.mesh, TriangleMesh):
            raise InvalidArgumentError(f"a mesh target's mesh is a TriangleMesh, got {type(self.mesh).__name__}")
        if self.source not in TARGET_SOURCES:
            raise InvalidArgumentError(f"a mesh target's source is one of {TARGET_SOURCES}, got {self.source!r}")

    def factor_samples(self) -> tuple:
        """(the sphere's vertices (n, 3), their areas (n,), the cMCF factors (n,))."""
        return self.sphere.vertices, vertex_areas(self.sphere), self.factors


def harmonic_target(rho, lmax: int, numeig: int, *, name: str | None = None) -> Target:
    """The first ``numeig`` Galerkin eigenvalues of a harmonic ρ at basis band limit ``lmax``.

    Examples
    --------
    >>> from shspec.fitting import blob_factor, harmonic_target
    >>> target = harmonic_target(blob_factor(), lmax=10, numeig=16)
    >>> target.numeig, target.source, target.eigenvalues[:4].round(4)
    (16, 'harmonic', array([0.    , 1.8044, 1.9847, 2.2321]))
    """
    factor = rho if isinstance(rho, ConformalFactor) else ConformalFactor(rho)
    model = HarmonicModel(lmax, factor.lmax)
    lam = model.spectrum(factor, numeig).eigenvalues
    return Target(name or factor.name, lam, area=factor.area, truth=factor)


def mesh_target(mesh, lmax: int, numeig: int, lmax_factor: int, *, source: str = "pl", name: str = "mesh",
                flow: CMCFResult | None = None) -> Target:
    """A target from a triangle mesh: cMCF gives the true factors; the spectrum is PL or harmonic.

    Parameters
    ----------
    mesh : TriangleMesh
        Closed genus-0 mesh.
    lmax : int
        Basis band limit Lb of the harmonic spectrum (source "harmonic").
    numeig : int
        Number of eigenvalues.
    lmax_factor : int
        Degree La of the harmonic expansion of the cMCF factors (the harmonic truth).
    source : {"pl", "cmcf", "harmonic"}
        See :data:`TARGET_SOURCES`.
    name : str
        Name of the target (and of its truth, "NAME (cMCF)").
    flow : CMCFResult, optional
        The mesh's cMCF (:func:`~shspec.mesh.cmcf.cmcf`) when the caller has it already (several targets of one
        mesh); None: computed here.

    Raises
    ------
    InvalidArgumentError
        If ``mesh`` is not a TriangleMesh, ``source`` is unknown, or ``flow`` is not a CMCFResult of this mesh's
        faces.

    Examples
    --------
    >>> from shspec.fitting import mesh_target
    >>> from shspec.mesh import load_mesh
    >>> target = mesh_target(load_mesh("pebble"), lmax=12, numeig=20, lmax_factor=4)
    >>> target.numeig, target.source, target.truth.lmax       # its cotan spectrum; the cMCF factors, expanded
    (20, 'pl', 4)
    """
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    if source not in TARGET_SOURCES:
        raise InvalidArgumentError(f"source must be one of {TARGET_SOURCES}, got {source!r}")
    if flow is None:
        flow = cmcf(mesh)
    elif not isinstance(flow, CMCFResult):
        raise InvalidArgumentError(f"flow must be a CMCFResult, got {type(flow).__name__}")
    elif not np.array_equal(flow.sphere.faces, mesh.faces):
        raise InvalidArgumentError("flow is the cMCF of another mesh: its faces differ from the mesh's")
    la = mesh_band_limit(mesh.nvertices, lmax_factor)
    truth = ConformalFactor(fit_harmonic(flow.sphere, flow.factors, la).coefficients, name=f"{name} (cMCF)")
    if source in ("pl", "cmcf"):
        if source == "pl":
            lam = mesh_spectrum(mesh, numeig, whole_multiplets=False).eigenvalues
        else:
            lam = eigenpairs(cotan_stiffness(flow.sphere), sp.diags(flow.factors * vertex_areas(flow.sphere)),
                             numeig).eigenvalues
        lam[0] = 0.0  # the solver's λ₀ is 0 to rounding; the target's must be exactly 0
    else:
        lam = HarmonicModel(lmax, la).spectrum(truth, numeig).eigenvalues
    return MeshTarget(name, lam, area=mesh.area(), truth=truth, mesh=mesh, sphere=flow.sphere,
                      factors=flow.factors, source=source)


#: For second-order convergence (the cotan eigenvalues: λ_h − λ ≈ C h²) the error of an eigenvalue on the mesh is
#: 4/3 of its change under one 4-to-1 subdivision (Richardson).
RICHARDSON_FACTOR = 4.0 / 3.0

#: The most vertices the finest mesh of :func:`refined_target` may have by default: two subdivisions (16 n
#: vertices) up to n = 12,500, one beyond.
REFINED_VERTICES = 200_000


#: The neighbours on either side whose extrapolation changes bound an extrapolated eigenvalue's error.
_NEIGHBOURS = 3


def refinement_levels(nvertices: int) -> int:
    """Subdivisions of a refined mesh target of n vertices: 2 while 16 n <= :data:`REFINED_VERTICES`, else 1."""
    return 2 if 16 * check_int(nvertices, "nvertices", minimum=4) <= REFINED_VERTICES else 1


def subdivision_spectra(target: Target, levels: int | None = None) -> np.ndarray:
    """The eigenvalues (levels, k) of a mesh target after 1 … ``levels`` 4-to-1 subdivisions: of its mesh (source
    "pl") or of its cMCF sphere carrying the cMCF factors ("cmcf"), by
    :func:`~shspec.mesh.refine.refined_eigenvalues`; ``levels`` None: :func:`refinement_levels` of that mesh.

    Raises
    ------
    InvalidArgumentError
        For a target without a mesh spectrum.
    """
    if isinstance(target, MeshTarget) and target.source == "pl" and target.mesh is not None:
        mesh, factors = target.mesh, None
    elif isinstance(target, MeshTarget) and target.source == "cmcf":
        mesh, factors = target.sphere, target.factors
    else:
        raise InvalidArgumentError(f"the target {target.name!r} (source {target.source!r}) is not a mesh's cotan "
                                   "spectrum: no discretization error to estimate")
    levels = refinement_levels(mesh.nvertices) if levels is None else levels
    return refined_eigenvalues(mesh, target.numeig, levels, factors=factors)[1:]


def subdivision_changes(target: Target, fine=None) -> np.ndarray:
    """The relative changes |λ_i − λ_i'| / λ_i (k,) of a mesh target's cotan eigenvalues under one 4-to-1
    subdivision (``fine``: the first subdivision's eigenvalues when already computed, :func:`subdivision_spectra`)."""
    fine = subdivision_spectra(target, 1)[0] if fine is None else np.asarray(fine, dtype=float)
    out = np.zeros(target.numeig)
    out[1:] = np.abs(target.eigenvalues[1:] - fine[1:]) / target.eigenvalues[1:]
    return out


def refined_target(target: Target, fine=None) -> Target:
    """A mesh target whose eigenvalues are those of the same surface on finer meshes, with their estimated errors.

    For second-order convergence λ_h − λ ≈ C h², with λ' and λ'' the eigenvalues after one and two 4-to-1
    subdivisions (h/2, h/4):

    * one subdivision: λ' with error ``|λ − λ'| / 3``, four times smaller than that of λ;
    * two: the Richardson extrapolations R₁ = (4λ' − λ)/3 and R₂ = (4λ'' − λ')/3, each sorted (eigenvalues that
      cross between meshes swap places), R₂ with error the largest change ``|R₂ − R₁|`` among the eigenvalue and
      its three neighbours on either side.  Measured against a third subdivision's extrapolation R₃ on the star of
      ``benchmarks/bench_surface.py`` (10242 vertices, 300 eigenvalues): ``|R₃ − R₂|`` stays below 0.66 of this
      error at every eigenvalue, which is a median 0.26 of the one-level error of λ''; the change alone, without
      the neighbours, is exceeded at 9 of 299 (near-degenerate pairs), by up to 4.4×.

    Every error is at least 1e-12 relative.

    Parameters
    ----------
    target : Target
        A mesh target (source "pl" or "cmcf").
    fine : (k,) or (levels, k) array, optional
        The spectra of its subdivisions when already computed (:func:`subdivision_spectra`); None: computed, with
        :func:`refinement_levels` subdivisions.

    Raises
    ------
    InvalidArgumentError
        For a target without a mesh spectrum, or ``fine`` of the wrong shape.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.fitting import mesh_target, refined_target
    >>> from shspec.mesh.shapes import star_surface
    >>> coarse = mesh_target(star_surface(2, 1, 0.3, 1), lmax=10, numeig=12, lmax_factor=4)
    >>> fine = refined_target(coarse)        # two subdivisions, Richardson-extrapolated
    >>> fine.numeig, bool(np.all(fine.errors[1:] > 0)), bool(np.all(fine.errors[1:] < 0.1 * fine.eigenvalues[1:]))
    (12, True, True)
    """
    fine = np.atleast_2d(np.asarray(subdivision_spectra(target) if fine is None else fine, dtype=float))
    if fine.shape[1] != target.numeig or fine.shape[0] not in (1, 2):
        raise InvalidArgumentError(f"fine must be ({target.numeig},) or (levels, {target.numeig}) with 1 or 2 levels, "
                                   f"got shape {fine.shape}")
    if fine.shape[0] == 1:
        lam, errors = fine[0].copy(), np.abs(target.eigenvalues - fine[0]) / 3.0
    else:
        first = np.sort((4.0 * fine[0] - target.eigenvalues) / 3.0)
        lam = np.sort((4.0 * fine[1] - fine[0]) / 3.0)
        errors = maximum_filter1d(np.abs(lam - first), 2 * _NEIGHBOURS + 1, mode="nearest")
    return dataclasses.replace(target, eigenvalues=lam, errors=np.maximum(errors, 1e-12 * lam))


def with_discretization_errors(target: Target, changes=None) -> Target:
    """A mesh target (source "pl" or "cmcf") with :attr:`Target.errors`: the estimated discretization error of
    each eigenvalue, :data:`RICHARDSON_FACTOR` times its change under one 4-to-1 subdivision (``changes``, from
    :func:`subdivision_changes` when not given), at least 1e-12 relative.  A harmonic model fitted to a mesh's
    spectrum then weighs, stops and reports its error bar by the mesh's own error (a mesh model shares the mesh's
    discretization and needs none).

    Raises
    ------
    InvalidArgumentError
        For a target without a mesh spectrum.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.fitting import mesh_target, with_discretization_errors
    >>> from shspec.mesh.shapes import star_surface
    >>> target = with_discretization_errors(mesh_target(star_surface(2, 1, 0.3, 2), lmax=10, numeig=12,
    ...                                                  lmax_factor=4))
    >>> bool(np.all(target.errors[1:] > 0)), target.errors[0]
    (True, 0.0)
    """
    changes = subdivision_changes(target) if changes is None else np.asarray(changes, dtype=float)
    return dataclasses.replace(target, errors=np.maximum(RICHARDSON_FACTOR * changes, 1e-12) * target.eigenvalues)


def spectrum_target(path, numeig: int | None = None) -> Target:
    """A target read from a spectrum file (:func:`shspec.spectrum_file.read_spectrum_file`: every format of that
    module), its first ``numeig`` eigenvalues (λ₀ = 0 included; default and cap: all of them), with their errors when
    the file has an error column; area and truth unknown.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.fitting import blob_factor, harmonic_target, spectrum_target
    >>> np.savetxt("blob.txt", harmonic_target(blob_factor(), lmax=10, numeig=16).eigenvalues)
    >>> target = spectrum_target("blob.txt", numeig=9)
    >>> target.name, target.numeig, target.errors is None, target.area is None
    ('blob', 9, True, True)
    """
    data = read_spectrum_file(path)
    target = Target(Path(path).stem, data.eigenvalues, errors=data.errors)
    if numeig is None:
        return target
    return target.first(min(check_int(numeig, "numeig", minimum=2), target.numeig))


def check_target_text(text: str) -> None:
    """Refuse a target text that :func:`parse_target` cannot read, before any long work: an unknown scheme, a
    malformed star, a missing mesh or spectrum file.

    Raises
    ------
    InvalidArgumentError
        With what was expected.
    """
    if not isinstance(text, str):
        raise InvalidArgumentError(f"a target is a string, got {text!r}")
    scheme, _, arg = text.partition(":")
    if scheme == "blob" and not arg:
        return
    if scheme == "star" and len(arg.split(",")) == 3:
        return
    if scheme == "mesh" and arg:
        path = resolve_mesh_path(arg)
        if path.is_dir():
            raise InvalidArgumentError(f"mesh target {arg!r} is a directory; name a mesh file in it")
        if not path.is_file():
            raise InvalidArgumentError(f"mesh target {arg!r}: no such file, nor a mesh shipped with shspec")
        return
    if scheme == "spectrum" and arg:
        check_spectrum_path(arg)  # a directory, a missing file or a dangling link, named as such
        return
    raise InvalidArgumentError(f"unknown target {text!r}: use blob, star:l,m,p, mesh:PATH or spectrum:FILE")


def parse_target(text: str, *, lmax: int, numeig: int, lmax_factor: int, source: str = "pl",
                 subdivisions: int = 3) -> Target:
    """A target from the command-line syntax.

    Parameters
    ----------
    text : str
        ``blob`` (the harmonic :func:`blob_factor`), ``star:l,m,p`` (the study's star surface r = 1 + p|Y_l^m| on
        an icosphere), ``mesh:PATH`` (a mesh file) or ``spectrum:FILE``.
    lmax, numeig, lmax_factor : int
        Basis band limit, number of eigenvalues, factor degree.
    source : {"pl", "cmcf", "harmonic"}
        Spectrum of mesh targets (star, mesh), see :data:`TARGET_SOURCES`.
    subdivisions : int
        Icosphere subdivisions of star surfaces.

    Examples
    --------
    >>> from shspec.fitting import parse_target
    >>> star = parse_target("star:2,1,0.3", lmax=10, numeig=20, lmax_factor=4, subdivisions=1)
    >>> type(star).__name__, star.name, star.numeig, star.mesh
    ('MeshTarget', 'star(2,1,0.3)', 20, TriangleMesh(42 vertices, 80 faces))
    """
    if not isinstance(text, str):
        raise InvalidArgumentError(f"a target is a string, got {text!r}")
    scheme, _, arg = text.partition(":")
    if scheme == "blob" and not arg:
        return harmonic_target(blob_factor(max(6, lmax_factor)).truncated(6), lmax, numeig, name="blob")
    if scheme == "star":
        try:
            l, m, p = arg.split(",")
            l, m, p = int(l), int(m), float(p)
        except ValueError:
            raise InvalidArgumentError(f"a star target is 'star:l,m,p', got {text!r}") from None
        return mesh_target(star_surface(l, m, p, subdivisions), lmax, numeig, lmax_factor, source=source,
                           name=f"star({l},{m},{p:g})")
    if scheme == "mesh" and arg:
        return mesh_target(load_mesh(arg), lmax, numeig, lmax_factor, source=source, name=Path(arg).stem)
    if scheme == "spectrum" and arg:
        return spectrum_target(arg, numeig)
    raise InvalidArgumentError(f"unknown target {text!r}: use blob, star:l,m,p, mesh:PATH or spectrum:FILE")
