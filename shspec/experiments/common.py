"""Helpers shared by the experiments: reference factors, the shared meshes and figure handling."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.atomic import save_figure as atomic_save_figure
from ..errors import InvalidArgumentError
from ..mesh import TriangleMesh, load_mesh
from ..sphere.factor import ConformalFactor
from ..sphere.random import random_coefficients


def centred_random_factor(lmax_factor: int, amplitude: float, seed: int) -> ConformalFactor:
    """A smooth random ρ of area 4π with a_1m = 0 (Möbius-centred gauge), drawn by the one law of
    :func:`~shspec.sphere.random.random_coefficients` (degree l's RMS ∝ 1/l).

    ``amplitude`` is the RMS of the non-constant part relative to the mean (exactly: the draw is rescaled to it);
    the result is checked to be positive.
    """
    a = random_coefficients(np.random.default_rng(seed), lmax_factor, 1.0)
    a *= amplitude * np.sqrt(4 * np.pi) / np.linalg.norm(a)
    a[0] = np.sqrt(4 * np.pi)
    rho = ConformalFactor(a, name=f"random(La={lmax_factor}, seed={seed})")
    rho.check_positive()
    return rho


#: Where the experiments take their meshes by default: "", the meshes shipped with shspec
#: (:data:`~shspec.mesh.builtin.BUILTIN_MESHES`); a config file may name a folder of ``<name>.obj`` files instead.
MESH_DIR = ""


def load_mesh_area_4pi(mesh_dir, name: str) -> TriangleMesh:
    """``mesh_dir/name.obj`` (``mesh_dir`` empty: the shipped mesh ``name``) scaled to area 4π, so that its mean
    conformal factor over a unit sphere is 1 (the study's ``makeUnitArea(v, f)·sqrt(4π)``).

    Raises
    ------
    InvalidArgumentError
        If ``mesh_dir`` is not a directory (the experiments' ``mesh_dir`` setting names it).
    MeshError
        If the mesh is missing or invalid.
    """
    if not mesh_dir:
        mesh = load_mesh(name)
    elif not Path(mesh_dir).is_dir():
        raise InvalidArgumentError(f"mesh_dir {str(mesh_dir)!r} is not a directory (from {Path.cwd()}); leave it "
                                   "unset for the meshes shipped with shspec")
    else:
        mesh = load_mesh(Path(mesh_dir) / f"{name}.obj")
    return mesh.with_vertices(mesh.vertices * np.sqrt(4 * np.pi / mesh.area()))


def figure(rows: int, cols: int, width: float = 12, height: float | None = None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(rows, cols, figsize=(width, height or 4.2 * rows), squeeze=False)
    return fig, axes.ravel()


def save_figure(fig, path) -> None:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    try:
        atomic_save_figure(fig, path, dpi=110)  # a failure names the figure
    finally:
        plt.close(fig)
