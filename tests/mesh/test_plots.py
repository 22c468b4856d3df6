"""Hammer maps are readable: tick labels do not overlap each other or the title; log colour bars have labels."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from shspec.mesh.plot import plot_hammer  # noqa: E402
from shspec.mesh.shapes import icosphere  # noqa: E402
from shspec.sphere.factor import ConformalFactor  # noqa: E402


def _boxes(fig, texts):
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    return [t.get_window_extent(renderer) for t in texts if t.get_visible() and t.get_text()]


def _overlaps(boxes):
    return [(a, b) for i, a in enumerate(boxes) for b in boxes[i + 1:] if a.overlaps(b)]


def _map(kind, width):
    sphere = icosphere(2)
    values = np.exp(0.3 * sphere.vertices[:, 0])  # a range of less than one decade
    fig = plt.figure(figsize=(width, width * 0.55))
    ax = fig.add_subplot(projection="hammer")
    if kind == "mesh":
        plot_hammer(sphere, values, ax=ax, log=True, title="a title of some length")
    else:
        ConformalFactor.mobius_boost(2.0, 8).plot(ax=ax, title="a title of some length")
    return fig, ax


@pytest.mark.parametrize("kind", ["mesh", "factor"])
@pytest.mark.parametrize("width", [5.0, 8.0])
def test_tick_labels_overlap_neither_each_other_nor_the_title(kind, width):
    fig, ax = _map(kind, width)
    lon = _boxes(fig, [t for t in ax.texts if t.get_text().endswith("°")])  # longitudes: below the map
    lat = _boxes(fig, ax.get_yticklabels())
    title = _boxes(fig, [ax.title])
    assert len(lon) >= 3 and not _overlaps(lon) and not _overlaps(lat)
    assert not _overlaps(lon + title) and not _overlaps(lat + title)
    plt.close(fig)


def test_a_narrow_log_colour_bar_has_several_labels_and_a_name():
    fig, ax = _map("mesh", 8.0)
    bar_ax = [a for a in fig.axes if a is not ax][0]
    fig.canvas.draw()
    labels = [t.get_text() for t in bar_ax.get_xticklabels() if t.get_text()]
    assert len(labels) >= 3
    assert bar_ax.get_xlabel()  # "value (log scale)" by default
    plt.close(fig)
