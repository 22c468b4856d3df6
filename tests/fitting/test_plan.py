"""The plan of a fit is the library's: ``prepare_fit`` then ``fit(plan)`` is what ``shspec fit`` runs, bit for bit;
each choice carries its reason; what cannot be planned is refused by name."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from shspec import fit, prepare_fit
from shspec.cli import main
from shspec.errors import InvalidArgumentError, ShortSpectrumError
from shspec.fitting import FitPlan, FitRequest, blob_factor, harmonic_target, initial_parameters, read_initial
from shspec.galerkin import HarmonicModel, LogHarmonicModel
from shspec.inverse import FitOptions, Target, write_result
from shspec.sphere.grid import evaluate_on_grid, glq_grid


@pytest.mark.slow
def test_the_documented_python_fit_of_a_shipped_mesh_is_the_cli_fit(tmp_path):
    plan = prepare_fit("mesh:pebble")           # the guide's three lines
    result = fit(plan)
    write_result(result, tmp_path / "python")
    assert main(["fit", "--target", "mesh:pebble", "--out", str(tmp_path / "cli"), "--quiet"]) == 0
    py, cli = (json.loads((tmp_path / d / "summary.json").read_text()) for d in ("python", "cli"))
    assert py["plan"] == cli["plan"] and py["surface_plan"] == cli["surface_plan"]
    assert py["expected_error"] == cli["expected_error"] and py["model"] == cli["model"]
    assert [s["energy"] for s in py["starts"]] == [s["energy"] for s in cli["starts"]]
    with h5py.File(tmp_path / "python" / "result.h5") as a, h5py.File(tmp_path / "cli" / "result.h5") as b:
        assert np.array_equal(a["target/eigenvalues"][()], b["target/eigenvalues"][()])
        assert np.array_equal(a["solution"][()], b["solution"][()])  # the same rho, to the bit
    # and the plan heard the pebble: a success within the errors it predicted
    assert result.success_count >= 1 and py["surface"]["factor_error"] < 3 * plan.expected_error
    assert {"model", "lmax_factor", "numeig", "lmax", "reg"} <= set(py["plan"])


def test_every_choice_says_why_and_the_statement_says_it_before_the_fit(capsys):
    plan = prepare_fit("blob", lmax_factor=6, lmax=12, numeig=40, workers=1,
                       options=FitOptions(starts=1, max_iter=3, basin_hops=0), schedule="none")
    assert isinstance(plan, FitPlan) and plan.target.numeig == 40 and plan.model.describe() == "harmonic Lb=12 La=6"
    assert plan.choice("numeig").reason == "as asked" and plan.choice("reg").value == 0.0
    result = fit(plan)
    err = capsys.readouterr().err
    assert err.index("fitting blob: 40 eigenvalues") < err.index("start 0")  # said before it runs
    assert result.plan["plan"]["lmax_factor"] == {"value": 6, "reason": "as asked"}
    with pytest.raises(InvalidArgumentError, match="only resume and executor"):
        fit(plan, HarmonicModel(12, 6))


def test_a_spectrum_with_errors_of_its_own_refuses_a_noise_too(tmp_path):
    lam = harmonic_target(blob_factor(), 10, 30).eigenvalues
    path = tmp_path / "with_errors.csv"
    np.savetxt(path, np.c_[lam, np.r_[0.0, 1e-6 * lam[1:]]], delimiter=",", header="eigenvalue,error", comments="")
    plan = prepare_fit(f"spectrum:{path}", lmax_factor=4, numeig=30, progress=False)
    assert np.allclose(plan.target.errors[1:], 1e-6 * lam[1:])  # the file's errors are the target's
    with pytest.raises(InvalidArgumentError, match="error column.*noise"):
        prepare_fit(f"spectrum:{path}", lmax_factor=4, numeig=30, noise=0.5, progress=False)
    assert main(["fit", "--target", f"spectrum:{path}", "--lmax-factor", "4", "--numeig", "30", "--noise", "1e-6",
                 "--out", str(tmp_path / "out")]) == 1


def test_a_spectrum_shorter_than_its_degree_needs_is_refused_with_the_degree_it_supports(tmp_path, capsys):
    lam = harmonic_target(blob_factor(), 16, 74).eigenvalues
    # 1.5 per coefficient at degree 6: the plan asks for 2.5 * 49 = 122; 74 support (La + 1)^2 <= 29.6, La = 4
    with pytest.raises(ShortSpectrumError, match="has 74 eigenvalues; the plan of degree 6 asks for 122") as caught:
        prepare_fit(lam, lmax_factor=6, progress=False)
    assert caught.value.supported_degree == 4 and isinstance(caught.value, InvalidArgumentError)
    assert "--lmax-factor auto" in str(caught.value) and "--allow-short-spectrum" in str(caught.value)
    # what the fit of the degree asked can expect is said beside it: the benchmark's run at 1.5 per coefficient
    assert "with 1.5 eigenvalues per coefficient" in str(caught.value)
    plan = prepare_fit(lam, lmax_factor=6, allow_short_spectrum=True, progress=False)
    assert plan.target.numeig == 74 and plan.choice("lmax_factor").value == 6
    said = [n for n in plan.notes if n.startswith("warning: the target has 74") and "support degree 4" in n]
    assert len(said) == 1
    path = tmp_path / "spectrum.txt"
    np.savetxt(path, lam)
    assert main(["fit", "--target", f"spectrum:{path}", "--lmax-factor", "6", "--out", str(tmp_path / "out"),
                 "--quiet"]) == 1
    assert "support degree 4" in capsys.readouterr().err and not (tmp_path / "out" / "summary.json").exists()
    # a default degree (15) is refused alike; too few for any degree says how many degree 2 needs
    with pytest.raises(ShortSpectrumError, match="support degree 4"):
        prepare_fit(lam, progress=False)
    with pytest.raises(ShortSpectrumError, match="at least 22 eigenvalues") as caught:
        prepare_fit(lam[:10], lmax_factor="auto", progress=False)
    assert caught.value.supported_degree == 1


@pytest.mark.parametrize("fields, words", [
    ({"target": "blob", "numeig": "auto"}, "needs a mesh target"),
    ({"target": "blob", "model": "mesh", "numeig": 20, "lmax_factor": 4}, "needs a mesh target"),
    ({"target": "blob", "model": "spline"}, "model must be one of"),
    ({"target": "blob", "noise": -1.0}, "noise"),
    ({"target": 3.0}, "a target is a string"),
    ({"target": np.arange(4.0), "errors": None, "lmax_factor": 2, "numeig": 4, "reg": 0.1,
      "options": FitOptions(reg=0.2)}, "disagree"),
])
def test_what_cannot_be_planned_is_refused_by_name(fields, words):
    with pytest.raises(InvalidArgumentError, match=words):
        prepare_fit(**{"progress": False, **fields})


def test_a_path_must_say_what_it_holds(tmp_path):
    with pytest.raises(InvalidArgumentError, match="spectrum:"):
        FitRequest(tmp_path / "x.txt")


def _rho_on_grid(coefficients, degree=20):
    return evaluate_on_grid(coefficients, glq_grid(degree))


def test_a_start_is_converted_to_the_model_that_reads_it(tmp_path):
    """rho's coefficients start a log-rho fit as log rho (and back); nothing is read as the other."""
    rho = blob_factor().coefficients
    model = LogHarmonicModel(16, 12)
    u = initial_parameters(rho, "rho", model)
    assert np.max(np.abs(np.exp(_rho_on_grid(u)) / _rho_on_grid(rho) - 1)) < 2e-3  # log rho cut to degree 12
    target = harmonic_target(blob_factor(), 16, 36)
    start = model.eigenvalues(u, 36)
    assert np.max(np.abs(start[1:] / target.eigenvalues[1:] - 1)) < 5e-3  # close to the truth, not 5.88 away
    # a summary.json (rho's cilm) given to the log model, and a log fit's result.h5 given to the harmonic model
    summary = tmp_path / "summary.json"
    summary.write_text(json.dumps({"cilm": blob_factor().to_cilm().tolist()}))
    assert np.array_equal(read_initial(summary, model), u)
    result = tmp_path / "result.h5"
    with h5py.File(result, "w") as f:
        f["solution"] = u
        f.attrs["model"] = model.describe()
    back = read_initial(result, HarmonicModel(16, 12))
    assert np.max(np.abs(_rho_on_grid(back) / _rho_on_grid(rho) - 1)) < 5e-3
    with pytest.raises(InvalidArgumentError, match="holds no values"):
        empty = tmp_path / "empty.txt"
        empty.write_text("")
        read_initial(empty, model)
    with pytest.raises(InvalidArgumentError, match="per-vertex factors"):
        initial_parameters(np.ones(642), "factors", model)


def test_a_target_given_as_an_array_keeps_its_errors():
    lam = harmonic_target(blob_factor(), 10, 20).eigenvalues
    plan = prepare_fit(lam, errors=np.r_[0.0, 1e-4 * lam[1:]], lmax_factor=2, numeig=20, progress=False)
    assert isinstance(plan.target, Target) and plan.expected_error is not None and plan.expected_error > 0
    assert plan.record()["expected_error"] == plan.expected_error


def test_the_summary_names_the_one_error_of_rho_to_read():
    from shspec.inverse import summary
    from shspec.sphere.factor import ConformalFactor
    from shspec.sphere.random import random_centred_coefficients

    truth = ConformalFactor(random_centred_coefficients(1, 2, 0.2))
    exact = harmonic_target(truth, 10, 30)
    plan = prepare_fit(exact, lmax_factor=2, numeig=30, lmax=10, progress=False,
                       options=FitOptions(starts=1, basin_hops=0))
    result = fit(plan)
    error = summary(result)["rho_error"]
    assert result.best.success and error["value"] == result.identifiability().error_estimate
    assert "final residual" in error["meaning"] and error["value"] < 1e-8
    noisy = prepare_fit(exact.eigenvalues, noise=1e-4, lmax_factor=2, numeig=30, lmax=10, progress=False,
                        options=FitOptions(starts=1, basin_hops=0))
    error = summary(fit(noisy))["rho_error"]
    assert "target's own errors" in error["meaning"] and 0 < error["value"] < 1e-2
    few = prepare_fit(exact.eigenvalues[:6], lmax_factor=4, numeig=6, lmax=10, progress=False,
                      options=FitOptions(starts=1, max_iter=5, basin_hops=0))
    error = summary(fit(few))["rho_error"]  # 6 eigenvalues, 17 directions: whatever the residual, no error
    assert error["value"] is None and error["meaning"].startswith("unknown: ")


def test_a_mesh_fits_error_is_the_one_measured_against_its_factors_and_says_when_its_bar_fails():
    """A 10k star fitted at La 7 within its errors lay 9 % from its cMCF factors against a bar of 1.7 %: another basin
    within the target's errors, which the linearized bar cannot see.  The measured error is the one to read."""
    from types import SimpleNamespace

    from shspec.inverse.output import rho_error

    ident = SimpleNamespace(converged=True, underdetermined=False, noise_error=0.015, error_estimate=None)
    far = rho_error(ident, {"floor": 0.012, "error_bar": 0.017, "factor_error": 0.091})
    assert far["value"] == 0.091 and "measured after" in far["meaning"]
    assert "0.017" in far["meaning"] and "this one is not" in far["meaning"]
    near = rho_error(ident, {"floor": 0.012, "error_bar": 0.017, "factor_error": 0.03})
    assert near["value"] == 0.03 and "0.017" in near["meaning"] and "this one is not" not in near["meaning"]
    unaligned = rho_error(ident, {"floor": 0.012, "error_bar": 0.017, "skipped": "no alignment: ..."})
    assert unaligned["value"] == 0.017 and "expected" in unaligned["meaning"]
    stalled = rho_error(SimpleNamespace(**{**vars(ident), "converged": False}),
                        {"floor": 0.012, "error_bar": 0.017, "factor_error": 0.091})
    assert stalled["value"] is None and stalled["meaning"].startswith("unknown: ")


def test_a_folder_given_as_a_spectrum_or_a_mesh_is_named_as_a_folder(tmp_path, capsys):
    for scheme in ("spectrum", "mesh"):
        assert main(["fit", "--target", f"{scheme}:{tmp_path}", "--out", str(tmp_path / "out")]) == 1
        assert "is a directory" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_noise_beside_errors_is_refused_before_any_planning(monkeypatch):
    import shspec.fitting.plan as fit_plan

    def no_planning(*args, **kwargs):  # planning K for La = 15 takes most of a minute
        raise AssertionError("planned before the noise was checked")

    monkeypatch.setattr(fit_plan, "plan_fit", no_planning)
    lam = harmonic_target(blob_factor(), 10, 30).eigenvalues
    target = Target("t", lam, errors=np.r_[0.0, 1e-6 * lam[1:]])
    for given in ({"target": target}, {"target": lam, "errors": target.errors}):
        with pytest.raises(InvalidArgumentError, match="give one"):
            prepare_fit(**given, noise=1e-3, progress=False)


def test_lmax_factor_auto_takes_the_degree_the_given_spectrum_supports(tmp_path):
    lam = harmonic_target(blob_factor(), 16, 60).eigenvalues
    plan = prepare_fit(lam, lmax_factor="auto", progress=False)
    # 60 eigenvalues at 2.5 per coefficient: (La + 1)^2 <= 24, La = 3; its plan asks for 40 of them
    assert plan.choice("lmax_factor").value == 3 and "60 eigenvalues support" in plan.choice("lmax_factor").reason
    assert plan.target.numeig == 40 and not any("only" in n for n in plan.notes)
    path = tmp_path / "spectrum.txt"
    np.savetxt(path, lam)
    args = ["fit", "--target", f"spectrum:{path}", "--lmax-factor", "auto", "--starts", "1", "--max-iter", "2",
            "--basin-hops", "0", "--schedule", "none", "--out", str(tmp_path / "out"), "--quiet"]
    assert main(args) == 0
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["plan"]["lmax_factor"]["value"] == 3
    with pytest.raises(InvalidArgumentError, match="picks the degree a given spectrum supports"):
        prepare_fit("blob", lmax_factor="auto", progress=False)


@pytest.mark.slow
def test_a_second_fit_into_a_running_fits_folder_is_refused_at_once(tmp_path, capsys):
    import subprocess
    import sys
    import time

    out = tmp_path / "fit"
    slow = ["fit", "--target", "blob", "--lmax", "12", "--lmax-factor", "6", "--numeig", "40", "--starts", "1",
            "--max-iter", "200", "--quiet", "--out", str(out)]
    first = subprocess.Popen([sys.executable, "-m", "shspec", *slow], stderr=subprocess.PIPE, text=True)
    try:
        for _ in range(600):  # its lock, taken once its arguments are checked
            if (out / ".shspec-fit.owner").exists() or first.poll() is not None:
                break
            time.sleep(0.1)
        assert first.poll() is None, first.stderr.read()
        assert main(slow) == 1
        assert "another fit is writing into" in capsys.readouterr().err
    finally:
        first.terminate()
        first.wait()


def test_an_empty_output_folder_is_refused_not_taken_as_the_current_one(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit):
        main(["fit", "--target", "blob", "--out", ""])
    assert "the output directory is empty" in capsys.readouterr().err and list(tmp_path.iterdir()) == []
