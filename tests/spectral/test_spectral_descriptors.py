"""Shape-DNA, heat trace and heat kernel signature, and the files they are written to."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from shspec.errors import InvalidArgumentError
from shspec.fitting.targets import read_spectrum
from shspec.mesh.cotan import cotan_stiffness, mass_matrix
from shspec.mesh.eigen import mesh_spectrum
from shspec.mesh.shapes import blob
from shspec.spectral import heat_trace
from shspec.spectral.descriptors import heat_kernel_signature, hks_times, shape_dna
from shspec.spectral.descriptor_files import read_eigenvalues, write_descriptors


@pytest.fixture(scope="module")
def small():
    mesh = blob(1)  # 42 vertices: every eigenpair, densely
    lam, vec = sla.eigh(cotan_stiffness(mesh).toarray(), mass_matrix(mesh).toarray())
    lam[0] = 0.0
    return mesh, lam, vec


def test_shape_dna_is_lapys_normalization(small):
    lapy = pytest.importorskip("lapy")
    from lapy.shapedna import normalize_ev, reweight_ev

    mesh, lam, _ = small
    tria = lapy.TriaMesh(mesh.vertices, mesh.faces)
    np.testing.assert_allclose(shape_dna(lam, mesh.area()), normalize_ev(tria, lam, method="geometry"), rtol=1e-13)
    np.testing.assert_allclose(shape_dna(lam, mesh.area(), reweight=True),
                               reweight_ev(normalize_ev(tria, lam, method="geometry")), rtol=1e-13)


def test_hks_is_the_diagonal_of_the_heat_kernel(small):
    # With all n eigenpairs, Σ e^{-λt} φφᵀ = expm(-t M⁻¹L) M⁻¹ (lumped M is diagonal).
    mesh, lam, vec = small
    L, m = cotan_stiffness(mesh).toarray(), mass_matrix(mesh).diagonal()
    t = np.array([0.01, 0.3])
    hks = heat_kernel_signature(lam, vec, t)
    for j, tj in enumerate(t):
        kernel = sla.expm(-tj * L / m[:, None]) / m[None, :]
        np.testing.assert_allclose(hks[:, j], np.diag(kernel), rtol=1e-9)


def test_mass_weighted_hks_is_the_heat_trace():
    # Σ_x M_xx φ_n(x)² = 1 for M-orthonormal φ_n, so Σ_x M_xx HKS(x, t) = Z(t).
    mesh = blob(3)
    spec = mesh_spectrum(mesh, 60)
    lam, vec = spec.eigenvalues[:60], spec.eigenvectors[:, :60]
    t = hks_times(lam, 5)
    np.testing.assert_allclose(mass_matrix(mesh).diagonal() @ heat_kernel_signature(lam, vec, t), heat_trace(lam, t),
                               rtol=1e-10)


def test_hks_times_follow_sun_et_al():
    t = hks_times([0.0, 2.0, 6.0, 12.0], 3)
    np.testing.assert_allclose(t, [4 * np.log(10) / 12, 4 * np.log(10) / np.sqrt(24), 4 * np.log(10) / 2])


def test_files_are_read_by_numpy_and_read_spectrum(small, tmp_path):
    mesh, lam, vec = small
    paths = write_descriptors(tmp_path, "blob", lam, mesh.area(), eigenvectors=vec, source="blob(1)")
    np.testing.assert_array_equal(read_spectrum(paths["eigenvalues"]), lam)
    np.testing.assert_array_equal(np.loadtxt(paths["eigenvalues"]), lam)
    np.testing.assert_allclose(np.loadtxt(paths["shapedna"]), lam * mesh.area(), rtol=1e-15)
    trace = np.loadtxt(paths["heat_trace"])
    np.testing.assert_allclose(trace[:, 1], heat_trace(lam, trace[:, 0]), rtol=1e-14)
    hks = np.loadtxt(paths["hks"])
    assert hks.shape == (mesh.nvertices, trace.shape[0])
    np.testing.assert_allclose(hks, heat_kernel_signature(lam, vec, trace[:, 0]), rtol=1e-9)
    assert paths["eigenvalues"].read_text().startswith("# ")


def test_two_column_spectra(tmp_path):
    lam = np.array([0.0, 2.0, 2.0, 2.0, 6.0])
    path = tmp_path / "two.txt"
    np.savetxt(path, np.stack([np.arange(5), lam], 1))
    np.testing.assert_array_equal(read_eigenvalues(path), lam)
    np.savetxt(path, np.stack([np.arange(1, 5), lam[1:]], 1))  # without λ₀: prepended
    np.testing.assert_array_equal(read_eigenvalues(path), lam)
    np.savetxt(path, lam)
    np.testing.assert_array_equal(read_eigenvalues(path), lam)
    np.savetxt(path, np.ones((4, 3)))
    with pytest.raises(InvalidArgumentError, match="3 columns"):
        read_eigenvalues(path)


def test_bad_descriptor_arguments(small):
    mesh, lam, vec = small
    with pytest.raises(InvalidArgumentError, match="area"):
        shape_dna(lam, 0.0)
    with pytest.raises(InvalidArgumentError, match="shape"):
        heat_kernel_signature(lam, vec[:, :5], 1.0)
    with pytest.raises(InvalidArgumentError, match="positive"):
        heat_kernel_signature(lam, vec, -1.0)
    with pytest.raises(InvalidArgumentError, match="components"):
        hks_times([0.0, 0.0, 1.0])
