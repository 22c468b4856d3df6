"""What a spectrum tells before any fit: heat trace, Weyl area, Euler characteristic and genus, and descriptors.

* :mod:`~shspec.spectral.heat`: the heat trace Z(t) and Weyl's tail of a truncated spectrum;
* :mod:`~shspec.spectral.weyl`: the area from the counting function;
* :mod:`~shspec.spectral.topology`: χ, genus (with a confidence statement) and area from the heat-trace
  asymptotics, and :func:`check_genus_zero`, the guard of genus-0 fits;
"""

from .heat import as_eigenvalues, heat_trace, weyl_tail
from .topology import MIN_EIGENVALUES, TopologyEstimate, TopologyOptions, check_genus_zero, estimate_topology
from .weyl import WeylFit, weyl_area, weyl_fit

__all__ = [
    "as_eigenvalues", "heat_trace", "weyl_tail", "WeylFit", "weyl_fit", "weyl_area",
    "TopologyOptions", "TopologyEstimate", "estimate_topology", "check_genus_zero", "MIN_EIGENVALUES",
]
