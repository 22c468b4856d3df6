"""Maps of per-vertex values on a spherical mesh, in the Hammer equal-area projection."""

from __future__ import annotations

import numpy as np

from ..core.checks import finite_array
from ..errors import InvalidArgumentError
from ..core.plotstyle import linear_colorbar_ticks, log_colorbar_ticks, style_hammer
from .cotan import vertex_areas
from .triangle_mesh import TriangleMesh

__all__ = ["plot_hammer", "area_percentiles"]


def area_percentiles(sphere: TriangleMesh, values, percentiles) -> np.ndarray:
    """Percentiles of per-vertex ``values`` weighted by the sphere's vertex areas (of what a map shows)."""
    f = np.asarray(values, dtype=float)
    order = np.argsort(f)
    cumulative = np.cumsum(vertex_areas(sphere)[order])
    return np.interp(np.asarray(percentiles, dtype=float) / 100 * cumulative[-1], cumulative, f[order])


def _seam_triangulation(lon, lat, faces, values):
    """A (lon, lat) triangulation in which each face across the ±180° meridian appears twice, once with its western
    vertices moved east by 2π and once with its eastern vertices moved west: each copy covers its side of the seam
    up to the map's edge (the part beyond is outside the Hammer ellipse and clipped), so no wedge stays white."""
    from matplotlib.tri import Triangulation

    cross = np.ptp(lon[faces], axis=1) > np.pi
    lons, lats, vals, tris = [lon], [lat], [values], [faces[~cross]]
    idx = faces[cross].ravel()
    for shift in (2 * np.pi, -2 * np.pi):
        moved = lon[idx] + np.where(np.sign(lon[idx]) == -np.sign(shift), shift, 0.0)
        tris.append(sum(a.size for a in lons) + np.arange(idx.size).reshape(-1, 3))
        lons.append(moved)
        lats.append(lat[idx])
        vals.append(values[idx])
    return Triangulation(np.concatenate(lons), np.concatenate(lats), np.concatenate(tris)), np.concatenate(vals)


def plot_hammer(sphere: TriangleMesh, values, *, ax=None, cmap: str = "viridis", title: str | None = None,
                label: str | None = None, log: bool = False, percentiles: tuple[float, float] = (1.0, 99.0),
                vmin: float | None = None, vmax: float | None = None):
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
        ear tips reach 1e6 times the median, on a tiny part of the sphere.  (0, 100) shows the full range.  When
        the range cuts values off, the colour-bar label gives the values' full range.
    vmin, vmax : float, optional
        A fixed colour range instead (several maps on one scale); either may be given alone.

    Returns
    -------
    matplotlib.figure.Figure

    Notes
    -----
    Faces that straddle the ±180° meridian are drawn on both sides of the map, each copy clipped at the edge.

    Examples
    --------
    >>> from shspec.mesh import icosphere, plot_hammer
    >>> sphere = icosphere(2)
    >>> fig = plot_hammer(sphere, sphere.vertices[:, 2], title="z", label="height")
    >>> type(fig).__name__
    'Figure'
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm, Normalize
    if not isinstance(sphere, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(sphere).__name__}")
    f = finite_array(values, "values", (sphere.nvertices,))
    if log and np.any(f <= 0):
        raise InvalidArgumentError("log colouring needs values > 0")
    lo, hi = percentiles
    if not 0 <= lo < hi <= 100:
        raise InvalidArgumentError(f"percentiles must satisfy 0 <= lo < hi <= 100, got {percentiles}")
    plo, phi = area_percentiles(sphere, f, [lo, hi])
    vmin = plo if vmin is None else float(vmin)
    vmax = phi if vmax is None else float(vmax)
    x = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1)[:, None]
    lon = np.arctan2(x[:, 1], x[:, 0])
    lat = np.arcsin(np.clip(x[:, 2], -1.0, 1.0))
    tri, shown = _seam_triangulation(lon, lat, sphere.faces, f)
    if ax is None:
        fig = plt.figure(figsize=(8, 4.5))
        ax = fig.add_subplot(projection="hammer")
    fig = ax.figure
    norm = LogNorm(vmin, vmax) if log else Normalize(vmin, vmax)
    art = ax.tripcolor(tri, shown, shading="gouraud", cmap=cmap, norm=norm)
    style_hammer(ax)
    if label is None:
        label = "value (log scale)" if log else "value"
    if f.min() < vmin or f.max() > vmax:  # the arrows alone would not say how far the values go
        label += f"; values span {f.min():.3g} to {f.max():.3g}"
    bar = fig.colorbar(art, ax=ax, orientation="horizontal", shrink=0.6, pad=0.1, label=label,
                       extend=_extend(f, vmin, vmax))
    if log:
        log_colorbar_ticks(bar, vmin, vmax)
    else:
        linear_colorbar_ticks(bar)
    if title:
        ax.set_title(title, pad=10)
    return fig


def _extend(values, vmin: float, vmax: float) -> str:
    """The colour bar's arrows: on the sides where values lie outside the range."""
    low, high = values.min() < vmin, values.max() > vmax
    return {(True, True): "both", (True, False): "min", (False, True): "max"}.get((low, high), "neither")
