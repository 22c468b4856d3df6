"""Distances, bump/dip ambiguity, the validation pipeline and the embed/validate commands."""

from __future__ import annotations

import dataclasses
import json

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from shspec.cli import main
from shspec.embed import AmbiguityOptions, angle_defects, detect_ambiguity, embed, render_mesh, surface_distance
from shspec.errors import InvalidArgumentError
from shspec.mesh.cmcf import cmcf
from shspec.mesh.eigen import mesh_spectrum
from shspec.mesh.mesh_files import load_mesh, save_mesh
from shspec.mesh.shapes import blob, icosphere
from shspec.pipeline import ValidationOptions, validate_target, write_report


def test_distance_is_zero_for_a_moved_mirror_image():
    mesh = blob(2)
    R = Rotation.from_euler("zyx", [0.3, -1.1, 2.0]).as_matrix() @ np.diag([1.0, -1.0, 1.0])
    moved = mesh.with_vertices(mesh.vertices @ R.T + [0.5, -2.0, 1.0])
    d = surface_distance(moved, mesh)
    assert d.correspondence and d.reflected
    assert d.hausdorff_relative < 1e-9
    # Without a vertex correspondence ICP finds it too, up to the sampling.
    d2 = surface_distance(icosphere(3).with_vertices(icosphere(3).vertices @ R.T), icosphere(2))
    assert not d2.correspondence and d2.hausdorff_relative < 0.03


def test_distance_sees_a_real_difference():
    a, b = icosphere(3), icosphere(3)
    d = surface_distance(a.with_vertices(a.vertices * [1.2, 1.0, 1.0]), b)
    assert d.hausdorff_relative > 0.03


def test_angle_defects_sum_to_4pi():
    assert angle_defects(blob(2)).sum() == pytest.approx(4 * np.pi, rel=1e-10)


def test_convex_blob_has_no_cap_and_a_lone_bump_is_flagged():
    flow = cmcf(blob(3))
    res = embed(flow.sphere, flow.factors)
    report = detect_ambiguity(flow.sphere, res)
    # Elliptic everywhere (Cauchy rigidity): no proper cap, nothing ambiguous.
    assert report.candidates == 0 and not report.ambiguous
    # A sphere with a narrow Gaussian bump: the bump is a cap; mirrored into a dip it fits the lengths as well.
    sphere = icosphere(3)
    u = sphere.vertices
    r = 1.0 + 0.25 * np.exp(-np.sum((u - [0, 0, 1]) ** 2, axis=1) / 0.08)
    bumpy = sphere.with_vertices(u * r[:, None])
    flow = cmcf(bumpy)
    res = embed(flow.sphere, flow.factors)
    report = detect_ambiguity(flow.sphere, res, AmbiguityOptions(max_caps=2))
    assert report.caps and report.caps[0].kind == "bump"
    assert report.ambiguous
    with pytest.raises(InvalidArgumentError):
        detect_ambiguity(icosphere(2), res)


def test_validation_pipeline_and_report(tmp_path):
    opt = ValidationOptions(numeig=8, lmax=6, lmax_factor=3, fit=False)
    result = validate_target(blob(2), opt, name="blob2")
    s = result.summary
    assert s["status"]["fit"] == "skipped: disabled"
    assert s["hausdorff_relative"] < 0.05 and s["edge_length_error"] < 0.01
    assert set(result.spectra) == {"target_pl", "cmcf_pl", "cmcf_harmonic", "embedded_pl"}
    # The re-embedded mesh and the sphere with the cMCF factors have nearly the target mesh's cotan spectrum (the
    # same discretization: the summary's target is extrapolated to the surface, 5 % away on 162 vertices)
    own = mesh_spectrum(blob(2), 8, whole_multiplets=False).eigenvalues
    for key in ("embedded_pl", "cmcf_pl"):
        assert np.max(np.abs(result.spectra[key][1:] / own[1:] - 1)) < 0.04
    assert 0.02 < s["spectral_error"]["embedded_pl"] < 0.1
    report = write_report(result, tmp_path / "out")
    text = report.read_text()
    assert "Hausdorff" in text and "![spectra](spectra.png)" in text
    for name in ("summary.json", "meshes.png", "spectra.png", "factors.png"):
        assert (tmp_path / "out" / name).stat().st_size > 0
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["hausdorff_relative"] == s["hausdorff_relative"]
    # the re-embedded surface is kept, and the summary names the basis it used
    assert np.allclose(load_mesh(tmp_path / "out" / "embedded.obj").vertices, result.embedding.mesh.vertices)
    assert s["lmax"] == 6 and s["lmax_factor"] == 3


def test_commands(tmp_path, capsys):
    mesh = blob(2)
    path = save_mesh(mesh, tmp_path / "blob.obj")
    assert main(["validate", "--target", f"mesh:{path}", "--out", str(tmp_path / "v"), "--numeig", "8",
                 "--lmax", "6", "--lmax-factor", "3", "--no-fit"]) == 0
    assert (tmp_path / "v" / "report.md").exists()
    flow = cmcf(mesh)
    save_mesh(flow.sphere, tmp_path / "sphere.obj")
    np.savetxt(tmp_path / "factors.txt", flow.factors)
    capsys.readouterr()
    assert main(["embed", str(tmp_path / "sphere.obj"), str(tmp_path / "factors.txt"),
                 "--out", str(tmp_path / "e.obj")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["edge_length_error"] < 0.01 and (tmp_path / "e.obj").exists()
    assert main(["validate", "--target", "spectrum:x", "--out", str(tmp_path / "w")]) == 1
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert main(["validate", "--target", f"mesh:{tmp_path / 'e.obj'}", "--out", str(blocker)]) == 1
    assert "is a file" in capsys.readouterr().err


def test_validate_exits_nonzero_when_a_step_failed(tmp_path, monkeypatch, capsys):
    import shspec.cli.embed as cli_embed
    from shspec.mesh.mesh_files import save_mesh

    real = cli_embed.validate_target

    def failing(*args, **kwargs):
        result = real(*args, **kwargs)
        result.summary["status"]["fit"] = "failed: a fit that went wrong"
        return result

    monkeypatch.setattr(cli_embed, "validate_target", failing)
    save_mesh(blob(1), tmp_path / "b.obj")
    assert main(["validate", "--target", f"mesh:{tmp_path / 'b.obj'}", "--out", str(tmp_path / "v"), "--no-fit",
                 "--numeig", "10"]) == 1
    assert "step fit failed" in capsys.readouterr().err


def test_render_draws_every_face_coloured_by_the_values():
    mesh = blob(1)
    fig = render_mesh(mesh, values=mesh.vertices[:, 2].copy(), up="y")
    (coll,) = fig.axes[0].collections
    colours = coll.get_facecolor()
    assert len(colours) == mesh.nfaces
    # faces at the top and at the bottom get different colours (values are the height z)
    zc = mesh.vertices[mesh.faces].mean(axis=1)[:, 2]
    assert not np.allclose(colours[np.argmax(zc)], colours[np.argmin(zc)])
    plain = render_mesh(mesh, up="y").axes[0].collections[0].get_facecolor()
    assert len(plain) == mesh.nfaces
    with pytest.raises(InvalidArgumentError):
        render_mesh(blob(1), up="w")


@pytest.mark.slow
def test_recursive_refinement_keeps_residual_and_distance_and_bounds_the_spectral_error():
    """The study's Section 3.2.3 on a 162-vertex blob: fit, re-embed, fit again on the re-embedded surface's sphere."""
    from shspec.fitting import mesh_target
    from shspec.fitting import RecursiveOptions, recursive_fit

    target = mesh_target(blob(2), lmax=8, numeig=40, lmax_factor=4)
    result = recursive_fit(target, options=RecursiveOptions(passes=2))
    first, second = result.passes
    assert result.final is second and second.sphere is not first.sphere
    assert second.fit_residual <= first.fit_residual
    assert second.hausdorff_relative <= first.hausdorff_relative
    # Measured 0.54 % then 1.16 %: the second pass's metric reaches the sphere through the cMCF of a coarse
    # re-embedded surface, accurate to ~1 %; bounded here, not improved.
    assert first.spectral_rms_error < 0.01 and second.spectral_rms_error < 0.02
    assert second.embedding.edge_error_rms < 0.01
    with pytest.raises(InvalidArgumentError):
        recursive_fit(target, options=RecursiveOptions(passes=0))


@pytest.mark.slow
def test_validate_keeps_the_fitted_rho_and_both_surfaces(tmp_path):
    assert main(["validate", "--target", "mesh:pebble", "--out", str(tmp_path / "v")]) == 0
    s = json.loads((tmp_path / "v" / "summary.json").read_text())
    assert s["status"]["fit"] == "ok" and s["lmax"] == s["plan"]["lmax"] and s["lmax_factor"] == s["plan"]["lmax_factor"]
    rho = np.array(s["fit"]["rho_cilm"])
    assert rho.ndim == 3 and rho.shape[0] == 2 and rho[0, 0, 0] > 0  # the aligned rho (Möbius maps raise its degree)
    for name in ("embedded.obj", "fit_embedded.obj"):
        assert load_mesh(tmp_path / "v" / name).nvertices == s["nvertices"]
    assert s["fit_embedding"]["hausdorff_relative"] < 0.05  # the pebble is heard: its surface comes back


@pytest.mark.slow
def test_a_truth_that_cannot_be_aligned_is_not_called_a_failed_fit(tmp_path):
    """spot's cMCF factors span 1:19000; their degree-16 expansion dips below 0, so no fit can be Moebius-aligned
    with it.  The fit itself reached its target: validate says what was skipped and why, and exits 0."""
    assert main(["validate", "--target", "mesh:spot_600", "--numeig", "20", "--lmax", "10", "--lmax-factor", "6",
                 "--out", str(tmp_path / "v")]) == 0
    status = json.loads((tmp_path / "v" / "summary.json").read_text())["status"]["fit"]
    assert status.startswith("ok; its alignment with the cMCF factors and its re-embedding skipped: the cMCF "
                             "factors' expansion of degree 16 is not positive")


@pytest.mark.slow
def test_validations_fit_races_its_starts_on_processes_with_a_serial_runs_result():
    """shspec validate fits one start per usable core on as many processes (its single start on one core ran past
    15 min on a 10k star whose fit from two racing starts took 2 min); the pool's fit is the serial one's."""
    opt = ValidationOptions(numeig=12, lmax=8, lmax_factor=2, fit_starts=2, ambiguity=False)
    serial, pooled = (validate_target(blob(2), dataclasses.replace(opt, fit_workers=w), name="blob2").summary["fit"]
                      for w in (1, 2))
    for key in ("factor_error", "residual_chi2_reached", "log_correlation"):
        assert serial[key] == pooled[key]
    with pytest.raises(InvalidArgumentError, match="fit_workers"):
        ValidationOptions(fit_workers=0)
