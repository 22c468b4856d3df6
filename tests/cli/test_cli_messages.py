"""Issue 34, item 18: messages that sent the user the wrong way (the mesh ones are in test_reliability_meshes)."""

from __future__ import annotations

import numpy as np
import pytest

import shspec
from shspec.cli import build_parser, main
from shspec.errors import CacheLocationError, InvalidArgumentError, NotPositiveError
from shspec.mesh.eigen import mesh_spectrum
from shspec.mesh.shapes import icosphere
from shspec.fitting.targets import Target


@pytest.mark.parametrize("rho", [np.zeros(4), -np.ones(1)])
def test_a_zero_or_negative_mean_rho_is_not_called_a_truncation(rho):
    with pytest.raises(NotPositiveError, match="mean value") as info:
        shspec.spectrum(rho, 4, 4)
    assert "probably the truncation" not in str(info.value)


@pytest.mark.parametrize("argv, words", [
    (["fit", "--target", "blob", "--lmax-factor", "-1", "--out", "x"], "--lmax-factor: must be >= 1"),
    (["fit", "--target", "blob", "--lmax-factor", "0", "--out", "x"], "--lmax-factor: must be >= 1"),
    (["precompute", "--samples", "-1", "list"], "--samples: must be >= 1"),
])
def test_option_bounds_are_named_by_their_option(argv, words, capsys):
    with pytest.raises(SystemExit):
        main(argv)
    err = capsys.readouterr().err
    assert words in err and "band limits" not in err and "free must be" not in err


def test_nan_is_not_reported_as_a_shape():
    with pytest.raises(InvalidArgumentError, match="eigenvalue 2 is nan") as info:
        Target("t", np.array([0.0, 2.0, np.nan, 6.0]))
    assert "shape" not in str(info.value)


@pytest.mark.parametrize("subdivisions", [0, 2])
def test_mesh_spectrum_at_the_allowed_maximum_is_not_refused(subdivisions):
    ico = icosphere(subdivisions)  # its top eigenvalues form one group that ends with the last pair of the mesh
    for k in (ico.nvertices - 1, ico.nvertices - 2):
        assert mesh_spectrum(ico, k).eigenvalues.size == ico.nvertices


def test_cache_dir_help_names_every_default_and_bad_cache_dirs_are_named(tmp_path, monkeypatch):
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    for command in ("forward", "precompute"):
        help_text = next(a.help for a in sub[command]._actions if a.dest == "cache_dir")
        assert "$SHSPEC_CACHE" in help_text and "checkout" in help_text and "XDG_CACHE_HOME" in help_text
    monkeypatch.chdir(tmp_path)
    with pytest.raises(CacheLocationError, match="non-empty path"):
        shspec.get_table(2, 2, cache_dir="")
    assert not list(tmp_path.iterdir())  # nothing written into the current folder
    link = tmp_path / "cache"
    link.symlink_to(tmp_path / "gone")
    with pytest.raises(CacheLocationError, match="symbolic link to .*gone, which does not exist"):
        shspec.get_table(2, 2, cache_dir=link)


def test_forward_with_one_eigenvalue_prints_no_nan_or_inf(capsys):
    assert main(["forward", "--lmax", "4", "--numeig", "1"]) == 0
    out = capsys.readouterr().out
    assert "nan" not in out and "inf" not in out and "not estimated" in out


def test_the_first_run_notice_appears_only_when_a_table_is_built(tmp_path):
    from types import SimpleNamespace

    from shspec.cli.forward import _working_message
    from shspec.sphere.factor import ConformalFactor

    args = SimpleNamespace(lmax=3, lmax_factor=None, cache_dir=str(tmp_path))
    rho = ConformalFactor.sphere()
    assert "building the Gaunt table" in _working_message(args, rho)
    shspec.get_table(3, 3, cache_dir=tmp_path)
    assert _working_message(args, rho) == "shspec forward: working..."


def test_identifiability_does_not_offer_a_spectrum_file(capsys):
    assert main(["identifiability", "--lmax-factor", "2", "--target", "spectrum:s.txt"]) == 1
    err = capsys.readouterr().err
    assert "a spectrum file has none" in err and "or spectrum:FILE" not in err


def test_a_failed_embedding_says_why(tmp_path, capsys, monkeypatch):
    import shspec.cli.embed as cli_embed
    from shspec.mesh.mesh_files import save_mesh

    ico = icosphere(1)
    save_mesh(ico, tmp_path / "s.obj")
    np.savetxt(tmp_path / "c.txt", np.ones(ico.nvertices))
    real = cli_embed.embed

    def folded(*args, **kwargs):
        import dataclasses

        return dataclasses.replace(real(*args, **kwargs), folded_faces=3, success=False)

    monkeypatch.setattr(cli_embed, "embed", folded)
    assert main(["embed", str(tmp_path / "s.obj"), str(tmp_path / "c.txt"), "--out", str(tmp_path / "e.obj")]) == 1
    err = capsys.readouterr().err
    assert "the embedding failed: 3 faces are folded" in err


def test_a_nan_starting_point_is_named_as_nan_not_as_a_shape():
    from shspec.galerkin import HarmonicModel
    from shspec.inverse import FitOptions, fit
    from shspec.fitting import blob_factor, harmonic_target

    model = HarmonicModel(6, 6)
    init = np.zeros(model.nparams)
    init[3] = np.nan
    with pytest.raises(InvalidArgumentError, match=r"entry 3 is nan") as info:
        fit(harmonic_target(blob_factor(), lmax=6, numeig=9), model, FitOptions(starts=1), init=init)
    assert "shape" not in str(info.value)


def test_a_mistyped_target_is_named_before_any_planning(tmp_path, capsys, monkeypatch):
    import shspec.fitting.plan as fit_plan

    def no_planning(*args, **kwargs):  # planning K for La = 15 takes a minute: a typo must not wait for it
        raise AssertionError("planned before the target was checked")

    monkeypatch.setattr(fit_plan, "plan_fit", no_planning)
    for target, words in (("blobb", "unknown target 'blobb'"), ("mesh:nonexistent_mesh", "no such file"),
                          ("spectrum:" + str(tmp_path / "none.txt"), "no such spectrum file")):
        assert main(["fit", "--target", target, "--out", str(tmp_path / "out")]) == 1
        assert words in capsys.readouterr().err


def test_shspec_warnings_are_one_line_each(tmp_path, capsys):
    import h5py

    from shspec.gaunt.cache import get_table, table_path

    get_table(6, 4, cache_dir=tmp_path)
    with h5py.File(table_path(6, 4, tmp_path), "r+") as f:
        f.attrs["format_version"] = 1  # an outdated table: rebuilt with a ShspecWarning
    assert main(["forward", "--lmax", "6", "--lmax-factor", "4", "--numeig", "9", "--cache-dir", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert "shspec forward: warning: rebuilding the Gaunt table" in err
    assert "ShspecWarning" not in err and ".py:" not in err  # not Python's file:line form
