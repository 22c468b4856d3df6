"""The value object of the mesh path: a triangle mesh with float64 positions and int64 faces.

Only array shapes and types are checked here; the topological checks (closed, manifold, genus 0, ...) live in
:mod:`shspec.mesh.validate` so that intermediate meshes can be built without paying for them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.checks import real_array
from ..errors import MeshError

__all__ = ["TriangleMesh"]


@dataclass(frozen=True, eq=False)
class TriangleMesh:
    """A triangle mesh.

    Attributes
    ----------
    vertices : (n, 3) float64 array
        Vertex positions (any length unit; areas are in that unit squared).
    faces : (m, 3) int64 array
        Vertex indices of each triangle, counter-clockwise seen from outside for an outward-oriented mesh.

    Raises
    ------
    MeshError
        If the arrays do not have these shapes, or an index is out of range.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.mesh import TriangleMesh
    >>> tetra = TriangleMesh(np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float),
    ...                      np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]))
    >>> tetra
    TriangleMesh(4 vertices, 4 faces)
    >>> round(tetra.area(), 4)   # four equilateral faces of side 2√2
    13.8564
    """

    vertices: np.ndarray
    faces: np.ndarray

    def __post_init__(self):
        v = real_array(self.vertices, "vertices", error=MeshError).copy()
        try:
            f = np.array(self.faces)
        except (TypeError, ValueError) as exc:
            raise MeshError(f"faces must be a numeric array: {exc}") from None
        if f.dtype.kind not in "biuf":
            raise MeshError(f"faces must hold integer vertex indices, got an array of {f.dtype}")
        if v.ndim != 2 or v.shape[1] != 3:
            raise MeshError(f"vertices must have shape (n, 3), got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise MeshError(f"faces must have shape (m, 3), got {f.shape}")
        if f.size and not np.issubdtype(f.dtype, np.integer):
            if not np.all(np.isfinite(f)) or np.any(f != np.round(f)):
                raise MeshError("faces must hold integer vertex indices")
        f = f.astype(np.int64)
        if f.size and (f.min() < 0 or f.max() >= v.shape[0]):
            bad = int(np.flatnonzero((f < 0).any(1) | (f >= v.shape[0]).any(1))[0])
            raise MeshError(f"face {bad} = {f[bad].tolist()} refers to a vertex outside 0..{v.shape[0] - 1}")
        v.setflags(write=False)
        f.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)

    def __repr__(self) -> str:
        # the arrays run to thousands of rows: say what the mesh is instead
        return f"TriangleMesh({self.nvertices} vertices, {self.nfaces} faces)"

    @property
    def nvertices(self) -> int:
        """Number of vertices n."""
        return self.vertices.shape[0]

    @property
    def nfaces(self) -> int:
        """Number of triangles m."""
        return self.faces.shape[0]

    def face_areas(self) -> np.ndarray:
        """(m,) array of triangle areas (length unit squared)."""
        return 0.5 * np.linalg.norm(self.face_normals_unnormalized(), axis=1)

    def face_normals_unnormalized(self) -> np.ndarray:
        """(m, 3) array of (p1 − p0) × (p2 − p0): the normal times twice the area."""
        p = self.vertices[self.faces]
        return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])

    def area(self) -> float:
        """Total surface area (length unit squared)."""
        return float(self.face_areas().sum())

    def signed_volume(self) -> float:
        """Enclosed volume, positive when the faces are oriented outward (length unit cubed)."""
        p = self.vertices[self.faces]
        return float(np.einsum("ij,ij->", p[:, 0], np.cross(p[:, 1], p[:, 2])) / 6.0)

    def with_vertices(self, vertices) -> "TriangleMesh":
        """The same connectivity with new positions (n, 3)."""
        vertices = np.asarray(vertices, dtype=np.float64)
        if vertices.shape != self.vertices.shape:
            raise MeshError(f"new vertices must have shape {self.vertices.shape}, got {vertices.shape}")
        return TriangleMesh(vertices, self.faces)
