"""The piecewise-linear mesh path: meshes, shapes, cotan spectra, cMCF, Möbius centering of meshes and the harmonic bridge.

Pipeline: :func:`load_mesh` (validated) → :func:`cmcf` (sphere mesh + per-vertex conformal factors) →
:func:`fit_harmonic` (factors as harmonic coefficients ρ) or :class:`MeshModel` (factors as parameters of the
cotan spectrum, for the inverse solver); :func:`mesh_spectrum` gives any mesh's cotan spectrum.
"""

from .bridge import HarmonicFit, fit_harmonic
from .builtin import BUILTIN_MESHES, builtin_mesh_path
from .cmcf import CMCFOptions, CMCFResult, cmcf, roundness
from .cotan import cotan_stiffness, mass_matrix, vertex_areas
from .eigen import EigenOptions, eigenpairs, mesh_spectrum
from .implicit import euler_characteristic, implicit_surface, ring_chain
from .mesh_files import load_mesh, save_mesh
from .mobius import MeshCentering, center_mesh
from .model import MeshModel
from .plot import plot_hammer
from .shapes import BLOB_COEFFICIENTS, blob, icosphere, star_surface
from .triangle_mesh import TriangleMesh
from .validate import validate_mesh

__all__ = [
    "TriangleMesh", "load_mesh", "save_mesh", "validate_mesh", "BUILTIN_MESHES", "builtin_mesh_path",
    "icosphere", "star_surface", "blob", "BLOB_COEFFICIENTS", "implicit_surface", "ring_chain",
    "euler_characteristic",
    "cotan_stiffness", "mass_matrix", "vertex_areas",
    "EigenOptions", "eigenpairs", "mesh_spectrum", "MeshModel",
    "CMCFOptions", "CMCFResult", "cmcf", "roundness",
    "MeshCentering", "center_mesh",
    "HarmonicFit", "fit_harmonic",
    "plot_hammer",
]
