"""What a spectrum tells before any fit: heat trace, Weyl area, Euler characteristic and genus, and descriptors.

* :mod:`~shspec.spectral.heat`: the heat trace Z(t) and Weyl's tail of a truncated spectrum;
* :mod:`~shspec.spectral.weyl`: the area from the counting function;
* :mod:`~shspec.spectral.topology`: χ, genus (with a confidence statement) and area from the heat-trace
  asymptotics, and :func:`check_genus_zero`, the guard of genus-0 fits;
* :mod:`~shspec.spectral.descriptors`: Shape-DNA (area-normalized eigenvalues) and the heat kernel signature;
* :mod:`~shspec.spectral.descriptor_files`: descriptor files (text that numpy and ``shspec fit`` read);
* :mod:`~shspec.spectral.batch`: all of it for many meshes, one job per mesh on an Executor
  (:func:`shspec.core.parallel.make_executor`).
"""

from .batch import MeshJobResult, collect_meshes, mesh_job, run_batch
from .descriptors import heat_kernel_signature, hks_times, shape_dna
from .heat import as_eigenvalues, heat_trace, spectral_tail
from .descriptor_files import read_eigenvalues, write_descriptors, write_values
from .topology import MIN_EIGENVALUES, TopologyEstimate, TopologyOptions, check_genus_zero, estimate_topology
from .weyl import TopDensity, WeylFit, top_density, weyl_area, weyl_fit

__all__ = [
    "as_eigenvalues", "heat_trace", "spectral_tail", "WeylFit", "weyl_fit", "weyl_area", "TopDensity", "top_density",
    "TopologyOptions", "TopologyEstimate", "estimate_topology", "check_genus_zero", "MIN_EIGENVALUES",
    "shape_dna", "hks_times", "heat_kernel_signature", "read_eigenvalues", "write_values", "write_descriptors",
    "MeshJobResult", "mesh_job", "collect_meshes", "run_batch",
]
