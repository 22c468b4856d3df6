"""The meshes shipped with shspec: the Stanford bunny, Spot and Blub, closed and of genus 0, at full resolution and
decimated to 1200 and 600 vertices (provenance and licences: ``shspec/data/meshes/README.md``)."""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

__all__ = ["BUILTIN_MESHES", "builtin_mesh_path", "resolve_mesh_path"]

#: Names of the shipped meshes (each is ``<name>.obj`` in the package data).
BUILTIN_MESHES = ("bunny", "bunny_1200", "bunny_600", "spot", "spot_1200", "spot_600",
                  "blub", "blub_1200", "blub_600", "pebble")


def builtin_mesh_path(name: str) -> Path:
    """The file of the shipped mesh ``name`` (one of :data:`BUILTIN_MESHES`).

    Raises
    ------
    KeyError
        If ``name`` is not a shipped mesh.

    Examples
    --------
    >>> from shspec.mesh import builtin_mesh_path
    >>> builtin_mesh_path("pebble").name
    'pebble.obj'
    """
    if name not in BUILTIN_MESHES:
        raise KeyError(name)
    return Path(str(resources.files("shspec") / "data" / "meshes" / f"{name}.obj"))


def resolve_mesh_path(path: str | os.PathLike) -> Path:
    """``path`` itself, or the shipped mesh it names when it is a bare built-in name (no suffix) and no such file
    exists in the working directory."""
    p = Path(path)
    if not p.suffix and not p.exists() and str(path) in BUILTIN_MESHES:
        return builtin_mesh_path(str(path))
    return p
