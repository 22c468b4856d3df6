"""Shared styling of shspec's figures: readable Hammer maps and log colour bars (matplotlib imported lazily)."""

from __future__ import annotations

import numpy as np

__all__ = ["style_hammer", "log_colorbar_ticks", "linear_colorbar_ticks"]

#: Grid lines of a Hammer map, degrees: every 60° of longitude and 30° of latitude.  Denser labels overlap each
#: other at the usual figure widths (and the ±75° parallels ran into the title).
LON_TICKS = (-120, -60, 0, 60, 120)
LAT_TICKS = (-60, -30, 0, 30, 60)


def style_hammer(ax, *, fontsize: float = 7.0) -> None:
    """Grid and tick labels of a Hammer-projection Axes that neither overlap each other nor the title."""
    ax.set_longitude_grid(60)
    ax.set_latitude_grid(30)
    ax.set_xticks(np.radians(LON_TICKS))
    ax.set_yticks(np.radians(LAT_TICKS))
    # Longitude labels go below the map, each under the point where its meridian crosses the equator: on the map
    # (matplotlib's place) they hide the data they sit on.  Axes coordinates of the projection do not change when
    # the figure is laid out again, so the positions hold after tight_layout or bbox_inches="tight".
    ax.set_xticklabels([])
    to_axes = ax.transProjection + ax.transAffine
    for d in LON_TICKS:
        x, _ = to_axes.transform((np.radians(d), 0.0))
        ax.text(x, -0.03, f"{d}°", transform=ax.transAxes, ha="center", va="top", fontsize=fontsize + 1,
                color="0.2")
    ax.set_yticklabels([f"{d}°" for d in LAT_TICKS], fontsize=fontsize + 1, color="0.2")
    ax.grid(True, alpha=0.35)


def log_colorbar_ticks(bar, vmin: float, vmax: float) -> None:
    """At least three labelled ticks on a log colour bar, plain numbers, whatever the range.

    Matplotlib's default labels only the powers of ten, which leaves one label (or none) on a bar spanning less
    than two decades.
    """
    from matplotlib.ticker import FixedLocator, FuncFormatter, LogLocator, NullFormatter, NullLocator

    axis = bar.ax.xaxis if bar.orientation == "horizontal" else bar.ax.yaxis
    decades = np.log10(vmax / vmin)
    if decades <= 2:
        ticks = np.geomspace(vmin, vmax, 5)
        ticks = np.array([float(f"{t:.2g}") for t in ticks])
        ticks = np.unique(ticks[(ticks >= vmin) & (ticks <= vmax)])
        axis.set_major_locator(FixedLocator(ticks))
    else:
        axis.set_major_locator(LogLocator(base=10, subs=(1.0,) if decades > 5 else (1.0, 3.0), numticks=8))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:.3g}"))
    axis.set_minor_locator(NullLocator())
    axis.set_minor_formatter(NullFormatter())


def linear_colorbar_ticks(bar) -> None:
    """At most five ticks on a linear colour bar, with a common power of ten moved to the bar's end, so that labels
    of small differences (1e-7) do not run into each other."""
    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    axis = bar.ax.xaxis if bar.orientation == "horizontal" else bar.ax.yaxis
    axis.set_major_locator(MaxNLocator(nbins=4, steps=[1, 2, 2.5, 5, 10],
                                       symmetric=bool(np.isclose(-bar.vmin, bar.vmax))))
    formatter = ScalarFormatter(useMathText=True)
    formatter.set_powerlimits((-2, 3))
    axis.set_major_formatter(formatter)
