"""Convergence studies and the forward command line."""

import json
import subprocess
import sys

import numpy as np
import pytest

from shspec import ConformalFactor
from shspec.cli import main
from shspec.galerkin.convergence import convergence, convergence_in_factor
from shspec.mesh.factor_spectrum import pl_spectrum_of_factor
from shspec.errors import InvalidArgumentError


def test_convergence_in_lmax_is_from_above_and_exponential():
    rho = ConformalFactor.mobius_boost(1.8, 16, (0, 1, 0))
    study = convergence(rho, [4, 6, 8, 10, 12, 16], 16)
    lam = study.eigenvalues
    assert np.all(np.diff(lam, axis=0) <= 1e-12)  # Galerkin: non-increasing in the basis
    rates = study.rates()
    assert np.all(rates[np.isfinite(rates)] > 0.5)
    assert study.group_change()[-2].max() < study.group_change()[0].max() * 1e-4
    rows = study.table()
    assert rows[0]["lmax"] == 4 and "group_l3" in rows[0]


def test_convergence_in_the_factor_band_limit():
    rho = ConformalFactor.mobius_boost(2.0, 20)
    study = convergence_in_factor(rho, [4, 8, 12, 20], lmax=16, k=16)
    change = study.group_change().max(axis=1)
    assert change[0] > change[1] > change[2]


def test_pl_spectrum_converges_from_below():
    rho = ConformalFactor.mobius_boost(1.5, 12)
    exact = np.array([0, 2, 2, 2, 6, 6, 6, 6, 6], dtype=float)
    coarse = pl_spectrum_of_factor(rho, 9, 2)
    fine = pl_spectrum_of_factor(rho, 9, 3)
    assert np.all(coarse[1:] < exact[1:]) and np.all(fine[1:] < exact[1:])
    assert np.all(np.abs(fine - exact)[1:] < np.abs(coarse - exact)[1:])


def test_needs_two_values():
    with pytest.raises(InvalidArgumentError, match="two distinct"):
        convergence(ConformalFactor.sphere(lmax=2), [6, 6], 4)


def test_forward_cli_json_and_files(tmp_path, capsys):
    assert main(["forward", "--lmax", "24", "--numeig", "9", "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["max_relative_error_vs_exact"] < 1e-10 and len(record["eigenvalues"]) == 9
    coef = ConformalFactor.mobius_boost(1.5, 6).coefficients
    np.save(tmp_path / "rho.npy", coef)
    out = tmp_path / "spec.h5"
    assert main(["forward", "--rho", str(tmp_path / "rho.npy"), "--lmax", "10", "--numeig", "4",
                 "--out", str(out)]) == 0
    import h5py

    with h5py.File(out) as f:
        assert f["eigenvectors"].shape == (121, 4) and f.attrs["lmax"] == 10


@pytest.mark.slow
def test_forward_cli_errors(tmp_path):
    def run(*args):
        return subprocess.run([sys.executable, "-m", "shspec", *args], capture_output=True, text=True, timeout=300)

    bad = run("forward", "--rho", "nonsense")
    assert bad.returncode == 1 and "neither a built-in" in bad.stderr
    big = run("forward", "--lmax", "3", "--numeig", "30")
    assert big.returncode == 1 and "raise lmax" in big.stderr
    help_ = run("forward", "--help")
    assert help_.returncode == 0 and "--rho" in help_.stdout and "boost" in help_.stdout


def test_convergence_cli(tmp_path):
    assert main(["convergence", "--lmax-values", "4,6,8", "--numeig", "9", "--factor-values", "2,4",
                 "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "convergence.json").read_text())
    assert [s["parameter"] for s in summary["studies"]] == ["lmax", "lmax_factor"]
    assert (tmp_path / "convergence_lmax.png").stat().st_size > 10000
    assert (tmp_path / "convergence_lmax.csv").read_text().startswith("lmax,max_relative_change")


def test_a_convergence_study_that_cannot_write_a_figure_leaves_the_previous_folder(tmp_path, monkeypatch, capsys):
    """The study's files are one unit (issue 50): a full disk on the figure kept the new table beside the old figure."""
    import errno

    from matplotlib.figure import Figure

    command = ["convergence", "--lmax-values", "4,6", "--numeig", "9", "--out", str(tmp_path)]
    assert main(command) == 0
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}

    def full(self, path, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(Figure, "savefig", full)
    assert main([*command[:2], "4,8", *command[3:]]) == 1
    assert "convergence_lmax.png: the disk is full" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
