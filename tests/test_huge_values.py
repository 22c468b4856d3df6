"""Huge values and NaN targets give an error that names the problem, not an overflow deep inside (issue 34)."""

from __future__ import annotations

import numpy as np
import pytest

import shspec
from shspec.cli import main
from shspec.embed import vertex_factors
from shspec.errors import InvalidArgumentError, MeshError, ShspecError
from shspec.galerkin import HarmonicModel
from shspec.fitting import blob_factor
from shspec.mesh import TriangleMesh, cmcf, icosphere
from shspec.spectral import estimate_topology


def _sphere_spectrum(k=100):
    l = np.arange(20)
    return np.repeat(l * (l + 1.0), 2 * l + 1)[:k]


def test_energy_with_a_nan_target_is_refused():
    model = HarmonicModel(8, 6)
    target = model.spectrum(blob_factor().coefficients, 10).eigenvalues.copy()
    target[4] = np.nan  # used to give energy NaN and carry on
    with pytest.raises(InvalidArgumentError, match="index 4"):
        model.energy(blob_factor().coefficients, target)


def test_a_huge_factor_is_named_not_nan_to_integer():
    a = blob_factor().coefficients * 1e300
    with pytest.raises(InvalidArgumentError, match="rescale rho"):
        shspec.spectrum(a, 8, 5)
    with pytest.raises(InvalidArgumentError, match="rescale rho"):
        HarmonicModel(8, 6).spectrum(a, 5)


def test_cli_huge_values_exit_1_with_one_line(tmp_path, capsys):
    assert main(["forward", "--rho", "sphere:1e308", "--lmax", "4", "--cache-dir", str(tmp_path)]) == 1
    assert "the area 1e+308 exceeds" in capsys.readouterr().err
    spectrum = tmp_path / "s.txt"
    np.savetxt(spectrum, _sphere_spectrum())
    assert main(["topology", "--target", f"spectrum:{spectrum}", "--area", "1e308"]) == 1
    assert "Weyl's law" in capsys.readouterr().err


def test_topology_of_huge_eigenvalues_or_area_is_refused():
    lam = _sphere_spectrum()
    assert estimate_topology(lam, 4 * np.pi).genus == 0
    with pytest.raises(InvalidArgumentError, match="largest eigenvalue 1e\\+308"):
        estimate_topology(np.r_[0.0, np.full(40, 1e308)])  # used to be "SVD did not converge"
    with pytest.raises(InvalidArgumentError, match="Weyl's law"):
        estimate_topology(lam, 1e308)  # used to be "cannot convert float NaN to integer"


def test_embedding_factors_spanning_1e300_are_refused():
    sphere = icosphere(2)
    c = np.ones(sphere.nvertices)
    c[5] = 1e300  # made the Gauss-Newton preconditioner "exactly singular"
    with pytest.raises(InvalidArgumentError, match="factors span 1e\\+300"):
        vertex_factors(sphere, c)


@pytest.mark.parametrize("scale", [1e200, 1e-200])
def test_cmcf_of_an_astronomic_mesh_names_its_size(scale):
    ico = icosphere(2)
    mesh = TriangleMesh(ico.vertices * scale * np.array([1.0, 1.2, 0.8]), ico.faces)
    with pytest.raises(MeshError, match="rescale it") as info:
        cmcf(mesh)
    assert isinstance(info.value, ShspecError)
