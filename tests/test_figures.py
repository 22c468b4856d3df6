"""Issue 34, item 21: the figures say what their tables say (residuals, ambiguity, vertex factors, factors,
history).  Each was also looked at after the fix."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from shspec.galerkin import HarmonicModel  # noqa: E402
from shspec.inverse import FitOptions, Stage, fit
from shspec.fitting import blob_factor, harmonic_target  # noqa: E402
from shspec.inverse.plots import RESIDUAL_FLOOR, plot_history, plot_residuals  # noqa: E402
from shspec.mesh.figures import plot_vertex_factors  # noqa: E402
from shspec.mesh.plot import plot_hammer  # noqa: E402
from shspec.mesh.shapes import blob, icosphere  # noqa: E402
from shspec.sphere.factor import ConformalFactor  # noqa: E402


@pytest.fixture(scope="module")
def staged():
    target = harmonic_target(blob_factor(), lmax=8, numeig=16)
    options = FitOptions(starts=1, max_iter=4, basin_hops=0, progress=False,
                         schedule=(Stage(lmax_factor=2, numeig=9), Stage(lmax_factor=4, numeig=16)))
    return fit(target, HarmonicModel(8, 4), options)


def test_one_exact_eigenvalue_does_not_stretch_the_residual_axis(staged):
    best = staged.best
    lam = best.eigenvalues.copy()
    lam[3] = staged.target.eigenvalues[3]  # residual exactly 0 (the log axis went down to 1e-314)
    result = dataclasses.replace(staged, starts=[dataclasses.replace(best, eigenvalues=lam)], solutions=[0])
    fig = plot_residuals(result)
    try:
        assert fig.axes[0].get_ylim()[0] >= RESIDUAL_FLOOR / 10
        assert any("rounding" in t.get_text() for t in fig.axes[0].get_legend().get_texts())
    finally:
        plt.close(fig)


def test_history_does_not_join_stages_and_labels_them(staged):
    fig = plot_history(staged)
    try:
        stages = np.unique(staged.starts[0].history[:, 0]).size
        assert stages == 2
        assert len(fig.axes[0].get_lines()) >= stages + 1  # one line per stage, plus the stage marker
        labels = [t.get_text() for t in fig.axes[0].texts]
        assert "stage 0: La 2, K 9" in labels and "stage 1: La 4, K 16" in labels
    finally:
        plt.close(fig)


def test_vertex_factor_maps_share_one_colour_range_and_have_no_seam_gap():
    sphere = icosphere(2)
    rng = np.random.default_rng(0)
    truth = np.exp(rng.normal(0.0, 0.5, sphere.nvertices))
    fitted = truth * np.exp(rng.normal(0.0, 0.1, sphere.nvertices))
    fig = plot_vertex_factors(sphere, fitted, truth)
    try:
        maps = [ax for ax in fig.axes if ax.name == "hammer"]
        norms = [ax.collections[0].norm for ax in maps]
        assert (norms[0].vmin, norms[0].vmax) == (norms[1].vmin, norms[1].vmax)
        assert norms[2].vmin == -norms[2].vmax  # the log ratio is centred on 0 (white: fit = target)
        drawn = maps[0].collections[0]._triangulation.get_masked_triangles().shape[0]
        assert drawn >= sphere.nfaces  # faces across the ±180° meridian drawn (twice), not masked
    finally:
        plt.close(fig)


def test_longitude_labels_sit_below_the_map_not_on_it():
    fig = plot_hammer(icosphere(1), np.ones(42) + np.arange(42.0))
    try:
        ax = fig.axes[0]
        assert all(t.get_text() == "" for t in ax.get_xticklabels())
        below = [t for t in ax.texts if t.get_text().endswith("°")]
        assert len(below) == 5 and all(t.get_position()[1] < 0 for t in below)
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        bar = fig.axes[-1].get_tightbbox(renderer)
        assert not any(t.get_window_extent(renderer).overlaps(bar) for t in below)  # nor on the colour bar
    finally:
        plt.close(fig)


def test_a_clipped_colour_bar_says_how_far_the_values_go():
    sphere = blob(2)
    values = np.ones(sphere.nvertices)
    values[:3] = [2300.0, 1e-3, 50.0]  # a few extreme vertices, as a bunny's ear tips
    fig = plot_hammer(sphere, values, log=True, label="c")
    try:
        label = fig.axes[-1].get_xlabel()
        assert "values span 0.001 to 2.3e+03" in label
    finally:
        plt.close(fig)


def test_difference_colour_bar_labels_do_not_run_together():
    rng = np.random.default_rng(1)
    for scale in (0.2, 3e-7):  # the difference of a rough fit, and of a good one
        fig = plt.figure(figsize=(5.3, 4.8))  # one panel of factors.png
        try:
            ConformalFactor(rng.normal(0.0, scale, 16)).plot(ax=fig.add_subplot(projection="hammer"))
            fig.canvas.draw()
            labels = [t.get_text().replace("$\\mathdefault{", "").replace("}$", "")
                      for t in fig.axes[-1].get_xticklabels() if t.get_text()]
            assert len(labels) <= 5 and max(len(s) for s in labels) <= 5, labels
        finally:
            plt.close(fig)


def test_ambiguity_colours_follow_the_table_not_the_data_range():
    from shspec.pipeline.validation import _ambiguity_figure

    mesh = icosphere(1)
    caps = [SimpleNamespace(vertices=np.arange(0, 10), ambiguous=True),
            SimpleNamespace(vertices=np.arange(20, 30), ambiguous=True)]
    result = SimpleNamespace(target=mesh, embedding=SimpleNamespace(mesh=mesh))
    fig = _ambiguity_figure(result, SimpleNamespace(caps=caps), "z")
    try:
        colours = fig.axes[0].collections[0].get_facecolors()[:, :3]
        assert not np.any(colours[:, 2] > colours[:, 0] + 0.1)  # every cap ambiguous: nothing blue ("decided")
        assert "2 tested caps: 2 ambiguous, 0 decided" in fig.axes[0].get_title()
    finally:
        plt.close(fig)
