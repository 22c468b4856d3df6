"""shspec: spectral geometry of genus-0 surfaces g = ρ·g₀ in the spherical-harmonic basis and on triangle meshes.

The public API is a few verbs over a few value objects:

* value objects: :class:`ConformalFactor` (ρ), :class:`TriangleMesh`, :class:`GauntTable`, :class:`FitResult`;
* verbs: :func:`spectrum` (forward), :func:`convergence`, :func:`prepare_fit` and :func:`fit` (inverse: plan a fit
  from a mesh, a spectrum or a ρ, then run it), :func:`align` (compare up to
  Möbius and O(3)), :func:`cmcf` (mesh → sphere), :func:`embed` (factors → surface);
* the engine underneath: :func:`wigner3j`, :func:`real_gaunt`, :func:`get_table`.
"""

from ._version import __version__
from .embed import EmbedOptions, EmbedResult, embed
from .errors import *  # noqa: F401,F403
from .errors import __all__ as _errors_all
from .galerkin import HarmonicModel, LogHarmonicModel, SpectrumResult, convergence, convergence_in_factor, spectrum
from .gaunt import GauntTable, get_table, real_gaunt, wigner3j
from .fitting import FitPlan, FitRequest, prepare_fit
from .inverse import FitOptions, FitResult, Stage, Target, align, fit
from .mesh import CMCFOptions, CMCFResult, MeshModel, TriangleMesh, cmcf, load_mesh, mesh_spectrum, save_mesh
from .sphere import ConformalFactor, cilm_to_vector, degree_order, flat_index, ncoeffs, vector_to_cilm, vector_to_shcoeffs


__all__ = [
    *_errors_all,
    # conventions
    "cilm_to_vector", "vector_to_cilm", "vector_to_shcoeffs", "degree_order", "flat_index", "ncoeffs",
    # engine
    "wigner3j", "real_gaunt", "GauntTable", "get_table",
    # forward
    "ConformalFactor", "HarmonicModel", "LogHarmonicModel", "SpectrumResult", "spectrum", "convergence", "convergence_in_factor",
    # inverse
    "FitOptions", "FitResult", "Stage", "Target", "fit", "align", "prepare_fit", "FitPlan", "FitRequest",
    # meshes and re-embedding
    "TriangleMesh", "load_mesh", "save_mesh", "mesh_spectrum", "MeshModel", "cmcf", "CMCFOptions", "CMCFResult",
    "embed", "EmbedOptions", "EmbedResult",
    "__version__",
]
