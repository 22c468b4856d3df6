"""Maps of per-vertex values on a spherical mesh, in the Hammer equal-area projection."""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError
from ..plotstyle import log_colorbar_ticks, style_hammer
from .cotan import vertex_areas
from .triangle_mesh import TriangleMesh

__all__ = ["plot_hammer"]


def plot_hammer(sphere: TriangleMesh, values, *, ax=None, cmap: str = "viridis", title: str | None = None,
                label: str | None = None, log: bool = False, percentiles: tuple[float, float] = (1.0, 99.0)):
    """Draw per-vertex values of a spherical mesh on a Hammer projection (longitude from +x, latitude from z = 0).

    Parameters
    ----------
    sphere : TriangleMesh
        Mesh with vertices on (or near) the unit sphere; only their directions are used.
    values : (n,) array
        One value per vertex, linearly interpolated over each face (Gouraud shading).
    ax : matplotlib Axes with ``projection="hammer"``, optional
        Default: a new figure.
    cmap : str
        Matplotlib colormap name.
    title, label : str, optional
        Axes title and colour-bar label (default "value", or "value (log scale)").
    log : bool
        Colour by log10 of the values (they must then be > 0).
    percentiles : (float, float)
        The colour range spans these percentiles of the values, weighted by the sphere's vertex areas (i.e. of what
        the map shows), so that a few extreme vertices do not flatten the rest: the conformal factors of a bunny's
        ear tips reach 1e6 times the median, on a tiny part of the sphere.  (0, 100) shows the full range.

    Returns
    -------
    matplotlib.figure.Figure

    Notes
    -----
    Faces that straddle the ±180° meridian are left out (a thin gap there) rather than smeared across the map.
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm, Normalize
    from matplotlib.tri import Triangulation

    if not isinstance(sphere, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(sphere).__name__}")
    f = np.asarray(values, dtype=float)
    if f.shape != (sphere.nvertices,) or not np.all(np.isfinite(f)):
        raise InvalidArgumentError(f"values must be a finite array of shape ({sphere.nvertices},)")
    if log and np.any(f <= 0):
        raise InvalidArgumentError("log colouring needs values > 0")
    lo, hi = percentiles
    if not 0 <= lo < hi <= 100:
        raise InvalidArgumentError(f"percentiles must satisfy 0 <= lo < hi <= 100, got {percentiles}")
    order = np.argsort(f)
    cumulative = np.cumsum(vertex_areas(sphere)[order])
    vmin, vmax = np.interp(np.array([lo, hi]) / 100 * cumulative[-1], cumulative, f[order])
    x = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1)[:, None]
    lon = np.arctan2(x[:, 1], x[:, 0])
    lat = np.arcsin(np.clip(x[:, 2], -1.0, 1.0))
    tri = Triangulation(lon, lat, sphere.faces)
    span = np.ptp(lon[sphere.faces], axis=1)
    tri.set_mask(span > np.pi)
    if ax is None:
        fig = plt.figure(figsize=(8, 4.5))
        ax = fig.add_subplot(projection="hammer")
    fig = ax.figure
    norm = LogNorm(vmin, vmax) if log else Normalize(vmin, vmax)
    art = ax.tripcolor(tri, f, shading="gouraud", cmap=cmap, norm=norm)
    style_hammer(ax)
    if label is None:
        label = "value (log scale)" if log else "value"
    bar = fig.colorbar(art, ax=ax, orientation="horizontal", shrink=0.6, pad=0.06, label=label, extend="both")
    if log:
        log_colorbar_ticks(bar, vmin, vmax)
    if title:
        ax.set_title(title, pad=10)
    return fig
