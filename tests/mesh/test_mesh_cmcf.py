"""Conformalized mean-curvature flow: an exact axisymmetric conformal map, invariances, real meshes."""

from __future__ import annotations


import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation
from scipy.special import eval_legendre

from shspec.errors import InvalidArgumentError, MeshError
from shspec.mesh.cmcf import CMCFOptions, cmcf, quasiconformal_distortion, roundness
from shspec.mesh.cotan import vertex_areas
from shspec.mesh.mesh_files import load_mesh
from shspec.mesh.shapes import icosphere, star_surface
from shspec.mesh.triangle_mesh import TriangleMesh



def exact_axisymmetric_map(l, p, npts=100001):
    """Centred conformal map of r(θ) = 1 + p|Y_l^0(θ)| onto the sphere: θ grid, polar angle ψ(θ), factor ρ(θ).

    A surface of revolution is conformal to the sphere by θ ↦ ψ(θ), φ ↦ φ with dψ/sin ψ = √(r² + r'²)/(r sin θ) dθ,
    i.e. ln tan(ψ/2) = ln tan(θ/2) + ∫₀^θ (√(1 + (r'/r)²) − 1)/sin t dt + C; the boost C is fixed by Möbius
    centering, ∫ cos ψ dA = 0, and ρ = (r sin θ / sin ψ)² (metric r² sin²θ dφ² = ρ sin²ψ dφ²).
    """
    th = np.linspace(0.0, np.pi, npts)
    r = 1.0 + p * np.abs(np.sqrt((2 * l + 1) / (4 * np.pi)) * eval_legendre(l, np.cos(th)))
    dr = np.gradient(r, th)
    inner = slice(1, -1)
    g = np.zeros_like(th)
    g[inner] = (np.sqrt(1 + (dr[inner] / r[inner]) ** 2) - 1) / np.sin(th[inner])
    base = np.log(np.tan(th[inner] / 2)) + cumulative_trapezoid(g, th, initial=0)[inner]
    area_density = r * np.sqrt(r ** 2 + dr ** 2) * np.sin(th)

    def psi(C):
        out = np.empty_like(th)
        out[0], out[-1] = 0.0, np.pi
        out[inner] = 2 * np.arctan(np.exp(base + C))
        return out

    ps = psi(brentq(lambda C: np.trapezoid(np.cos(psi(C)) * area_density, th), -5, 5))
    rho = np.empty_like(th)
    rho[inner] = (r[inner] * np.sin(th[inner]) / np.sin(ps[inner])) ** 2
    rho[0], rho[-1] = rho[1], rho[-2]
    return th, ps, rho


def test_exact_axisymmetric_conformal_map():
    th, ps, rho = exact_axisymmetric_map(2, 0.5)
    errors = []
    for s in (3, 4):
        res = cmcf(star_surface(2, 0, 0.5, s))
        assert res.success and res.flips == 0
        theta = np.arccos(icosphere(s).vertices[:, 2])
        psi = np.arccos(np.clip(res.sphere.vertices[:, 2], -1, 1))
        w = vertex_areas(res.sphere)
        rel = res.factors / np.interp(theta, th, rho) - 1
        errors.append((np.abs(psi - np.interp(theta, th, ps)).max(), np.sqrt(w @ rel ** 2 / w.sum())))
    errors = np.array(errors)
    # Measured: angle 9.3e-3 -> 5.2e-3 rad, factor 2.2 % -> 1.0 % (first order: |Y| has kinks).
    assert errors[1, 0] < 7e-3 and errors[1, 1] < 0.015
    assert np.all(errors[0] / errors[1] > 1.6)


def test_invariant_to_rigid_motion_and_scale():
    mesh = star_surface(3, 2, 0.4, 3)
    opt = CMCFOptions(cg_tol=1e-13)
    ref = cmcf(mesh, opt)
    R = Rotation.from_euler("xyz", [0.3, -1.1, 2.0]).as_matrix()
    scale = 3.7
    moved = TriangleMesh(scale * mesh.vertices @ R.T + [1.0, -2.0, 0.5], mesh.faces)
    res = cmcf(moved, opt)
    assert res.iterations == ref.iterations
    np.testing.assert_allclose(res.factors, scale ** 2 * ref.factors, rtol=1e-7)
    np.testing.assert_allclose(res.sphere.vertices, ref.sphere.vertices @ R.T, atol=1e-7)


def test_sphere_stays_a_sphere():
    # An icosphere is round but not exactly a fixed point of the discrete flow: it moves by the discretization.
    res = cmcf(icosphere(3))
    assert res.success and res.flips == 0
    np.testing.assert_allclose(res.factors, 1.0, atol=5e-3)
    assert res.distortion_max < 1.02


@pytest.mark.parametrize("name", ["bunny_600", "spot_600"])
def test_real_meshes(shared_meshes, name):
    mesh = load_mesh(shared_meshes / f"{name}.obj")
    res = cmcf(mesh)
    assert res.success and res.flips == 0
    # the coarse mesh cannot get round to 1e-4: the flow says it stopped where the roundness stalled
    assert res.roundness > CMCFOptions().tol and res.stop_reason == "stalled"
    assert cmcf(mesh, CMCFOptions(max_iter=3)).stop_reason == "max_iter"
    # As round as lapy's flow with its defaults (30 steps here), measured the same way: both sit on the flow's
    # discrete fixed point, where the roundness varies by a few per cent from step to step.
    lapy = pytest.importorskip("lapy")
    from lapy.diffgeo import tria_mean_curvature_flow

    flowed = tria_mean_curvature_flow(lapy.TriaMesh(mesh.vertices, mesh.faces))
    assert res.roundness < 1.05 * roundness(flowed.v, vertex_areas(mesh.with_vertices(flowed.v)))
    assert res.centering_residual <= 1e-10
    np.testing.assert_allclose(np.linalg.norm(res.sphere.vertices, axis=1), 1.0, atol=1e-14)
    assert res.factors @ vertex_areas(res.sphere) == pytest.approx(mesh.area(), rel=1e-12)
    assert 1 <= res.distortion_mean < res.distortion_max


def test_helpers_and_errors():
    ico = icosphere(2)
    w = vertex_areas(ico)
    assert roundness(ico.vertices, w) < 1e-12
    assert roundness(ico.vertices * [1, 1, 1.1], w) > 0.05
    # A uniform scaling is conformal; a stretch along x by 2 has distortion exactly 2 on faces normal to z... and
    # at most 2 anywhere.
    stretched = TriangleMesh(ico.vertices * [2.0, 1.0, 1.0], ico.faces)
    np.testing.assert_allclose(quasiconformal_distortion(ico, ico.with_vertices(3 * ico.vertices)), 1.0)
    qc = quasiconformal_distortion(ico, stretched)
    assert qc.max() <= 2 + 1e-12 and qc.max() > 1.9
    with pytest.raises(InvalidArgumentError, match="step"):
        CMCFOptions(step=-1.0)
    with pytest.raises(MeshError):
        cmcf(TriangleMesh(ico.vertices, ico.faces[1:]))
