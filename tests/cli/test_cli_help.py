"""The command line's own surface: --version, defaults in the help, the embed summary file."""

import json
import subprocess
import sys

import numpy as np
import pytest

import shspec
from shspec.cli import build_parser, main
from shspec.embed.options import EmbedOptions
from shspec.mesh.cmcf import CMCFOptions
from shspec.mesh.mesh_files import save_mesh
from shspec.mesh.shapes import icosphere


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0 and capsys.readouterr().out.strip() == f"shspec {shspec.__version__}"


def _help(*command):
    sub = build_parser()._subparsers._group_actions[0].choices
    return " ".join(sub[command[0]].format_help().split())


@pytest.mark.parametrize("command, expected", [
    ("cmcf", [f"stalls above it (default {CMCFOptions.tol:g})", f"(default {CMCFOptions.max_iter})"]),
    ("embed", [f"(default {EmbedOptions.pressure:g})", f"filter (default {EmbedOptions.smoothing:g})"]),
    ("report", ["(default report.html)"]),
    ("precompute", ["(default build)", "(default 2000)"]),
])
def test_help_states_defaults(command, expected):
    text = _help(command)
    for phrase in expected:
        assert phrase in text
    assert "(default: None)" not in text


def test_embed_writes_its_summary_with_the_inputs(tmp_path, capsys):
    sphere = icosphere(2)
    save_mesh(sphere, tmp_path / "s.obj")
    np.savetxt(tmp_path / "c.txt", np.full(sphere.nvertices, 4.0))
    code = main(["embed", str(tmp_path / "s.obj"), str(tmp_path / "c.txt"), "--out", str(tmp_path / "e.obj"),
                 "--summary", str(tmp_path / "e.json")])
    assert code == 0
    summary = json.loads((tmp_path / "e.json").read_text())
    assert summary["factors"] == str(tmp_path / "c.txt") and summary["pressure"] == EmbedOptions.pressure
    assert summary["success"] is True and "factorizations" in summary


@pytest.mark.slow
def test_precompute_runs_as_a_subcommand_of_the_installed_entry_point(tmp_path):
    out = subprocess.run([sys.executable, "-m", "shspec", "precompute", "list", "--cache-dir", str(tmp_path)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "(--cache-dir;" in out.stdout


def _subparsers():
    return build_parser()._subparsers._group_actions[0].choices


def test_fit_help_fits_a_terminal_and_every_option_states_what_it_does(monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    text = _subparsers()["fit"].format_help()
    assert len(text.splitlines()) <= 80
    fit_parser = _subparsers()["fit"]
    for action in fit_parser._actions:
        if action.dest != "help":
            assert action.help and len(action.help) > 10, action.dest


@pytest.mark.parametrize("command", sorted(build_parser()._subparsers._group_actions[0].choices))
def test_no_help_cites_a_benchmark_file_or_a_result(command, monkeypatch):
    monkeypatch.setenv("COLUMNS", "100")
    text = _subparsers()[command].format_help()
    assert "benchmarks/" not in text and "bench_" not in text
