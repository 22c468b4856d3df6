"""Matplotlib pictures of meshes (no OpenGL): flat-shaded triangles sorted back to front."""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError
from ..mesh.triangle_mesh import TriangleMesh

__all__ = ["render_mesh"]


def render_mesh(mesh: TriangleMesh, *, ax=None, view: tuple[float, float] = (20.0, -60.0), color="#b0c4de",
                values=None, cmap="viridis", title: str | None = None, up: str = "z", vmin: float | None = None,
                vmax: float | None = None):
    """Draw a triangle mesh with Lambert shading from a light at the camera.

    Parameters
    ----------
    mesh : TriangleMesh
        n vertices, m faces.
    ax : matplotlib 3-D Axes, optional
        Default: a new 5 × 5 inch figure.
    view : (elev, azim)
        Camera elevation and azimuth in degrees (matplotlib's convention).
    color : matplotlib colour
        Base colour when ``values`` is None.
    values : (n,) or (m,) array, optional
        Per-vertex values coloured with ``cmap`` (face colour: the mean of its vertices), or per-face values
        (categories, which a mean would blend into another category).
    cmap : str or matplotlib Colormap
        Colormap of ``values``.
    vmin, vmax : float, optional
        Values at the ends of the colormap (default: the faces' own range), so that a colour means the same
        value in every figure (a category, say).
    title : str, optional
    up : {"x", "y", "z"}
        Axis of the mesh drawn vertically (the bunny's is "y").

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from shspec.embed import render_mesh
    >>> from shspec.mesh import blob
    >>> fig = render_mesh(blob(2), title="blob")
    >>> type(fig).__name__
    'Figure'
    """
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    if up not in ("x", "y", "z"):
        raise InvalidArgumentError(f"up must be 'x', 'y' or 'z', got {up!r}")
    # Cyclic permutation (a rotation, so orientation and shading stay right) that puts ``up`` on z.
    perm = {"z": [0, 1, 2], "y": [2, 0, 1], "x": [1, 2, 0]}[up]
    v = mesh.vertices[:, perm]
    p = v[mesh.faces]
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1), 1e-300)[:, None]
    elev, azim = np.radians(view)
    eye = np.array([np.cos(elev) * np.cos(azim), np.cos(elev) * np.sin(azim), np.sin(elev)])
    shade = 0.25 + 0.75 * np.abs(nrm @ eye)
    base = _face_colours(mesh, color, values, cmap, vmin, vmax)
    if ax is None:
        fig = plt.figure(figsize=(5, 5))
        ax = fig.add_subplot(projection="3d")
    coll = Poly3DCollection(p, facecolors=np.clip(base * shade[:, None], 0, 1), edgecolors="none")
    ax.add_collection3d(coll)
    center = 0.5 * (v.min(axis=0) + v.max(axis=0))
    half = 0.5 * np.ptp(v, axis=0).max()
    ax.set_xlim(center[0] - half, center[0] + half)
    ax.set_ylim(center[1] - half, center[1] + half)
    ax.set_zlim(center[2] - half, center[2] + half)
    ax.set_box_aspect((1, 1, 1), zoom=1.35)
    ax.view_init(*view)
    ax.set_axis_off()
    if title:
        ax.set_title(title)
    return ax.figure


def _face_colours(mesh: TriangleMesh, color, values, cmap, vmin, vmax) -> np.ndarray:
    """(m, 3) RGB of the faces before shading: ``color`` everywhere, or ``values`` (per vertex or face) coloured."""
    from matplotlib import colormaps
    from matplotlib.colors import Normalize, to_rgb

    if values is None:
        return np.tile(to_rgb(color), (mesh.nfaces, 1))
    f = np.asarray(values, dtype=float)
    if f.shape not in ((mesh.nvertices,), (mesh.nfaces,)) or not np.all(np.isfinite(f)):
        raise InvalidArgumentError(f"values must be a finite array of shape ({mesh.nvertices},) or ({mesh.nfaces},)")
    fv = f[mesh.faces].mean(axis=1) if f.shape == (mesh.nvertices,) else f
    colours = colormaps[cmap] if isinstance(cmap, str) else cmap
    norm = Normalize(fv.min() if vmin is None else vmin, fv.max() if vmax is None else vmax)
    return colours(norm(fv))[:, :3]
