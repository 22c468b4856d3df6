"""Re-embedding: from a spherical mesh with conformal factors back to a surface in R³ (see :mod:`.embed`)."""

from .ambiguity import AmbiguityOptions, AmbiguityReport, Cap, angle_defects, detect_ambiguity
from .continuation import continuation_schedule
from .distances import SurfaceDistance, rigid_align, surface_distance
from .embed import embed
from .inputs import vertex_factors
from .options import EmbedOptions, EmbedResult
from .ordering import nested_dissection
from .system import EmbedSystem
from .lengths import mesh_edges, smooth_factors, target_edge_lengths
from .quality import edge_length_error, folded_faces, self_intersections
from .render import render_mesh

__all__ = ["AmbiguityOptions", "AmbiguityReport", "Cap", "angle_defects", "detect_ambiguity", "continuation_schedule",
           "SurfaceDistance", "rigid_align", "surface_distance", "EmbedOptions", "EmbedResult", "EmbedSystem", "embed",
           "nested_dissection", "vertex_factors", "mesh_edges", "smooth_factors", "target_edge_lengths", "edge_length_error",
           "folded_faces", "self_intersections", "render_mesh"]
