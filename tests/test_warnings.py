"""Issue 50, item 22: shspec's warnings are attributed to the caller's line (they pointed at shspec/threads.py:150,
the wrapper of every reproducible call), the command line prints every warning in one line, and an input file
without numbers is named instead of leaking NumPy's "input contained no data" warning."""

from __future__ import annotations

import warnings

import pytest

from shspec.cli import _warnings_as_lines, main
from shspec.errors import TruncationWarning
from shspec.galerkin.solver import spectrum
from shspec.mesh.eigen import mesh_spectrum
from shspec.mesh.mesh_files import save_mesh
from shspec.mesh.shapes import icosphere
from shspec.sphere.factor import ConformalFactor


def test_a_truncation_warning_points_at_the_callers_line():
    with pytest.warns(TruncationWarning) as caught:
        spectrum(ConformalFactor.mobius_boost(2.0, 8), 8, 36)
    assert [w.filename for w in caught] == [__file__]


def test_a_cut_degenerate_group_warning_points_at_the_callers_line():
    with pytest.warns(RuntimeWarning, match="form one degenerate group") as caught:
        mesh_spectrum(icosphere(1), 2, whole_multiplets=False)  # lambda_1..3 are one exact triple
    assert [w.filename for w in caught] == [__file__]


def test_the_command_line_prints_every_warning_in_one_line(capsys):
    with _warnings_as_lines("forward"):
        warnings.warn_explicit("Mean of empty slice", RuntimeWarning, "/numpy/core/_methods.py", 121)
        warnings.warn_explicit("may be off by 1 %", TruncationWarning, "/x.py", 1)
    assert capsys.readouterr().err.splitlines() == [
        "shspec forward: warning: RuntimeWarning: Mean of empty slice (/numpy/core/_methods.py:121)",
        "shspec forward: warning: may be off by 1 %"]


@pytest.mark.parametrize("text", ["", "# no coefficients here\n\n"])
def test_an_input_file_without_numbers_is_named(tmp_path, capsys, text):
    empty = tmp_path / "empty.txt"
    empty.write_text(text)
    sphere = tmp_path / "sphere.obj"
    save_mesh(icosphere(1), sphere)
    for argv in (["forward", "--rho", str(empty), "--lmax", "4", "--numeig", "4"],
                 ["embed", str(sphere), str(empty), "--out", str(tmp_path / "out.obj")]):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # NumPy's "input contained no data" included
            assert main(argv) == 1
        [line] = capsys.readouterr().err.splitlines()
        assert f"{empty} holds no numbers (it is empty or only comments)" in line, line
