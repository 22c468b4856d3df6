"""The inverse solver end to end: recovery to rounding, mirror images, determinism, exact resume, positivity,
schedules, the PL path on the study's star surfaces, and the command line."""

from __future__ import annotations

import json
import time
from dataclasses import replace

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest

from shspec import ConformalFactor, HarmonicModel
from shspec.errors import InvalidArgumentError
from shspec.cli import main
from shspec.inverse import FitOptions, Stage, align, default_schedule, fit
from shspec.fitting import blob_factor, harmonic_target
from shspec.sphere.random import random_centred_coefficients
from shspec.inverse import optimize as optimize_module
from shspec.inverse.energy import Objective, eigenvalue_weights
from shspec.inverse.parametrization import Parametrization
from shspec.inverse.optimize import make_optimizer
from shspec.sphere.rotate import mirror_coefficients, power_spectrum



@pytest.fixture(scope="module")
def recovered():
    """Lb = 20, La = 4, 120 eigenvalues; the best of three symmetry-broken starts (all three, not only up to the
    first success)."""
    truth = random_centred_coefficients(1, 4, 0.15)
    target = harmonic_target(truth, 20, 120)
    result = fit(target, HarmonicModel(20, 4), FitOptions(starts=3, seed=1, schedule=(), basin_hops=0,
                                                          stop_at_success=False))
    return truth, target, result


@pytest.mark.slow
def test_best_start_recovers_spectrum_and_factor(recovered):
    truth, target, result = recovered
    assert result.best.relative_residual <= 1e-10
    # the search ran on a smaller basis, which cannot reach the tolerance; the polish on Lb did
    hist = result.best.history
    assert set(hist[:, 0]) == {0, 1} and hist[hist[:, 0] == 0][-1, 2] > 1e-9
    assert result.success_count >= 1
    assert len(result.starts) == 3 and set(result.solutions) <= {0, 1, 2}
    al = align(result.factor(), truth)
    assert al.relative_error <= 1e-6
    assert al.power_error <= 1e-6


@pytest.mark.slow
def test_mirror_image_is_a_match(recovered):
    truth, _, result = recovered
    direct, mirrored = align(result.factor(), truth), align(result.factor(), mirror_coefficients(truth))
    # The spectrum cannot tell a surface from its mirror image: the fit matches one of them up to a rotation, the
    # other up to a reflection, both to rounding.
    assert direct.mirrored != mirrored.mirrored
    assert max(direct.relative_error, mirrored.relative_error) <= 1e-6


def test_distinct_solutions_group_starts_by_energy_and_invariant():
    from shspec.inverse import StartResult, distinct_solutions

    model = HarmonicModel(8, 4)
    a = random_centred_coefficients(3, 4, 0.2)
    b = random_centred_coefficients(4, 4, 0.2)

    def start(i, params, energy):
        return StartResult(i, params, energy, 0.0, 0, 0.0, "x", np.zeros((1, 3)), np.zeros(2))

    turned = model.escape_moves(a)[0]  # a half-turn of one degree block: the same per-degree power as a
    starts = [start(0, b, 3e-3), start(1, a, 1e-3), start(2, turned, 1e-3 * (1 + 1e-7)), start(3, a, 2e-3)]
    # 1 and 2: same energy and invariant, one solution; 3 has another energy; 0 another invariant and energy
    assert distinct_solutions(starts, model, 1e-4) == [1, 3, 0]
    assert distinct_solutions(starts, model, 1e-9) == [1, 2, 3, 0]


@pytest.fixture(scope="module")
def small():
    target = harmonic_target(blob_factor(), 8, 20)
    return target, HarmonicModel(8, 6)


def test_fit_is_deterministic_under_a_seed(small):
    target, model = small
    opts = FitOptions(starts=2, seed=5, max_iter=4, schedule=(Stage(2), Stage(4), Stage(6)), basin_hops=1,
                      hop_iter=2)
    r1, r2 = fit(target, model, opts), fit(target, model, opts)
    for a, b in zip(r1.starts, r2.starts):
        np.testing.assert_array_equal(a.params, b.params)
        np.testing.assert_array_equal(a.history, b.history)
    other = fit(target, model, FitOptions(starts=1, seed=6, max_iter=4, schedule=opts.schedule, basin_hops=0))
    assert not np.array_equal(other.starts[0].params, r1.starts[0].params)


def test_schedule_raises_degree_and_breaks_parity(small):
    target, model = small
    r = fit(target, model, FitOptions(starts=1, max_iter=3, schedule=(Stage(2, 9), Stage(4, 16), Stage(6))))
    h = r.starts[0].history
    assert list(np.unique(h[:, 0])) == [0, 1, 2]
    assert power_spectrum(r.best.params)[3] > 0 and power_spectrum(r.best.params)[5] > 0
    assert np.all(r.best.params[1:4] == 0)  # the Möbius gauge


def test_degree_ramp_raises_degree_and_count_together():
    from shspec.inverse import degree_ramp

    stages = degree_ramp(120, 6)
    assert [(s.lmax_factor, s.numeig) for s in stages] == [(2, 16), (3, 25), (4, 36), (5, 49), (6, 64), (6, 100),
                                                           (6, 120)]
    assert [(s.lmax_factor, s.numeig) for s in degree_ramp(20, 6)] == [(2, 16), (6, 20)]
    big = degree_ramp(300, 15)
    degrees_ = [s.lmax_factor for s in big]
    assert degrees_ == sorted(degrees_) and degrees_[-1] == 15 and big[-1].numeig == 300
    assert all(s.numeig > (s.lmax_factor + 1) ** 2 for s in big)  # every stage overdetermined
    assert all(s.max_iter is None for s in stages)
    capped = degree_ramp(120, 6, stage_max_iter=7)
    assert [(s.lmax_factor, s.numeig) for s in capped] == [(s.lmax_factor, s.numeig) for s in stages]
    assert [s.max_iter for s in capped] == [7] * 6 + [None]  # the last stage runs to convergence
    assert not any(s.hops for s in capped)
    hopping = degree_ramp(120, 6, stage_max_iter=7, hop_degree=4)
    assert [(s.lmax_factor, s.numeig) for s in hopping] == [(s.lmax_factor, s.numeig) for s in stages]
    # the stage that reaches degree 4 runs to convergence and hops; the others are as before
    assert [(s.max_iter, s.hops) for s in hopping] == [(7, False)] * 2 + [(None, True)] + [(7, False)] * 3 + [
        (None, False)]
    assert not any(s.hops for s in degree_ramp(40, 6, hop_degree=6))  # 6:64 is beyond 40 eigenvalues
    with pytest.raises(InvalidArgumentError):
        FitOptions(schedule=(Stage(6), Stage(4)))
    with pytest.raises(InvalidArgumentError):
        degree_ramp(120, 6, stage_max_iter=0)
    with pytest.raises(InvalidArgumentError):
        degree_ramp(120, 6, hop_degree=1)
    with pytest.raises(InvalidArgumentError):
        Stage(6, 16, hops="yes")


def test_escape_moves_keep_power_and_gauge_and_undo_themselves():
    model = HarmonicModel(8, 6)
    a = blob_factor().coefficients
    moves = model.escape_moves(a)
    assert len(moves) == 3 * 5 + 4 * 2  # three half-turns per block l = 2..6, four more (signs) for l = 3 and 5
    for q in moves:
        np.testing.assert_allclose(power_spectrum(q), power_spectrum(a), rtol=1e-12, atol=1e-15)
        assert np.all(q[1:4] == 0) and q[0] == a[0]
    # a half-turn applied twice is the identity: the moves of a moved state include the original
    assert min(np.max(np.abs(q - a)) for q in model.escape_moves(moves[4])) < 1e-13


def _state_at(problem, params, stage=0):
    """A start's progress resting at ``params`` on ``stage`` of ``problem``, and its evaluation there."""
    from shspec.inverse.problem import StartProgress

    obj = problem.objective(stage, params)
    ev = obj.evaluate(obj.initial())
    return StartProgress(0, stage, params, None, params=params, energy=ev.energy,
                         relative_residual=ev.relative_residual, eigenvalues=ev.eigenvalues), ev


def test_basin_hop_is_accepted_and_leaves_a_wrongly_turned_block(small):
    """A state whose degree-3 block is half-turned has the right power but the wrong spectrum; one hop returns it
    to the truth (the move back is the one of lowest energy, and its refit reaches rounding)."""
    from shspec.inverse.hops import basin_hop
    from shspec.inverse.problem import FitProblem

    target, model = small
    truth = blob_factor().coefficients
    wrong = model.escape_moves(truth)[3]  # the half-turn about z of the degree-3 block
    problem = FitProblem(model, target, FitOptions(starts=1, max_iter=20, schedule=(Stage(),), basin_hops=1,
                                                   hop_iter=3))
    progress, ev = _state_at(problem, wrong)
    assert ev.relative_residual > 1e-4
    basin_hop(problem, progress, "energy_tol", 0)
    assert progress.relative_residual < 1e-10
    assert align(ConformalFactor(progress.params), truth).relative_error < 1e-8


@pytest.mark.parametrize("hops", [True, False])
def test_a_stage_with_hops_leaves_its_minimum_before_the_next_stage(small, hops):
    """Stage.hops runs the basin hops at the end of an intermediate stage: from a half-turned degree-3 block the
    first stage (20 eigenvalues) ends at the truth with them and stays wrong without them."""
    _, model = small
    target = harmonic_target(blob_factor(), 8, 25)
    truth = blob_factor().coefficients
    wrong = model.escape_moves(truth)[3]
    opts = FitOptions(starts=1, max_iter=20, basin_hops=1, hop_iter=3,
                      schedule=(Stage(6, 20, hops=hops), Stage(6, 25, max_iter=2)))
    history = fit(target, model, opts, init=wrong).best.history
    first = history[history[:, 0] == 0]
    assert first.shape[0] > 1
    if hops:
        assert first[-1, 2] < 1e-10
    else:
        assert first[-1, 2] > 1e-5


@pytest.mark.parametrize("optimizer", ["lm", "lbfgs", "gd"])
def test_resume_from_checkpoint_equals_uninterrupted_run(small, tmp_path, monkeypatch, optimizer):
    target, model = small
    opts = FitOptions(starts=2, seed=3, max_iter=5, optimizer=optimizer, schedule=(Stage(4), Stage(6)),
                      basin_hops=1, hop_iter=2, checkpoint_every=2, checkpoint_path=str(tmp_path / "ck.h5"),
                      stop_at_success=False)
    reference = fit(target, model, FitOptions(**{**opts.__dict__, "checkpoint_every": 0, "checkpoint_path": None}))

    cls = optimize_module._CLASSES[optimizer]
    original = cls.step
    calls = {"n": 0}

    def interrupted_step(self):
        calls["n"] += 1
        if calls["n"] == 13:  # in the second start: Ctrl-C
            raise KeyboardInterrupt
        original(self)

    monkeypatch.setattr(cls, "step", interrupted_step)
    partial = fit(target, model, opts)
    assert partial.interrupted and partial.starts[-1].status == "interrupted"
    monkeypatch.setattr(cls, "step", original)
    resumed = fit(target, model, opts, resume=True)
    assert not resumed.interrupted
    for a, b in zip(reference.starts, resumed.starts):
        np.testing.assert_allclose(b.params, a.params, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(b.history[:, 1:], a.history[:, 1:], rtol=1e-10, atol=1e-300)


def test_resume_after_ctrl_c_in_the_hops_of_a_stage_equals_uninterrupted_run(small, tmp_path, monkeypatch):
    """Ctrl-C in the hops after an intermediate stage (Stage.hops), after one of them may have moved the state: the
    resumed fit runs that stage again from its start and ends exactly where an uninterrupted one does."""
    from shspec.inverse import hops

    target, model = small
    opts = FitOptions(starts=2, seed=3, max_iter=5, schedule=(Stage(4, hops=True), Stage(6)), basin_hops=2,
                      hop_iter=2, hop_tries=3, checkpoint_every=2, checkpoint_path=str(tmp_path / "ck.h5"),
                      stop_at_success=False)
    reference = fit(target, model, FitOptions(**{**opts.__dict__, "checkpoint_every": 0, "checkpoint_path": None}))
    assert any(row[0] == 0 for row in reference.starts[1].history[6:])  # stage 0 of start 1 did hop

    original = hops.hop_once
    calls = {"n": 0}

    def interrupted_hop(problem, progress, s, moves, status):
        if progress.index == 1 and s == 0:
            calls["n"] += 1
            if calls["n"] == 2:  # the second round of moves of stage 0, in the second start: Ctrl-C
                raise KeyboardInterrupt
        return original(problem, progress, s, moves, status)

    monkeypatch.setattr(hops, "hop_once", interrupted_hop)
    partial = fit(target, model, opts)
    assert partial.interrupted and calls["n"] == 2
    monkeypatch.setattr(hops, "hop_once", original)
    resumed = fit(target, model, opts, resume=True)
    assert not resumed.interrupted
    for a, b in zip(reference.starts, resumed.starts):
        np.testing.assert_allclose(b.params, a.params, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(b.history, a.history, rtol=1e-10, atol=1e-300)


def test_a_start_interrupted_in_its_hops_counts_their_time(small, monkeypatch):
    """The hops record no iterations; the time of a start stopped inside them still runs to the interrupt."""
    from shspec.inverse import hops

    target, model = small
    opts = FitOptions(starts=1, seed=3, max_iter=2, schedule=(Stage(4), Stage(6)), basin_hops=1, hop_iter=2)
    seen = {}

    def slow_interrupted_hop(problem, progress, s, moves, status):
        seen["seconds"] = progress.seconds
        time.sleep(0.3)
        raise KeyboardInterrupt

    monkeypatch.setattr(hops, "hop_once", slow_interrupted_hop)
    result = fit(target, model, opts)
    assert result.interrupted and result.starts[0].status == "interrupted"
    assert result.starts[0].seconds >= seen["seconds"] + 0.3


def test_positivity_safeguard_never_crashes():
    model = HarmonicModel(8, 4)
    target = harmonic_target(random_centred_coefficients(2, 4, 0.4), 8, 20).eigenvalues
    start = np.zeros(25)
    start[0] = np.sqrt(4 * np.pi)
    start[6] = 1.1  # a_20 close to making ρ negative at the poles
    obj = Objective(model, target, eigenvalue_weights(target, "absolute"), Parametrization(start, model.free_parameters(False)))
    for name in ("lm", "gd", "bfgs"):
        opt = make_optimizer(name, obj, obj.initial(), FitOptions(optimizer=name))
        energies = [opt.ev.energy]
        for _ in range(6):
            opt.step()
            energies.append(opt.ev.energy)
        assert np.all(np.diff(energies) <= 0)
        assert ConformalFactor(obj.params(opt.x)).minimum().value > 0


def test_pl_recovery_error_grows_with_amplitude():
    """The study's Section 3.2.1: star surfaces r = 1 + p|Y_3^3| are harder to hear as p grows."""
    from shspec.fitting import mesh_target
    from shspec.mesh.model import MeshModel
    from shspec.mesh.shapes import star_surface

    errors = []
    for p in (0.2, 0.8):
        target = mesh_target(star_surface(3, 3, p, subdivisions=2), lmax=8, numeig=40, lmax_factor=4)
        model = MeshModel(target.sphere)
        r = fit(target, model, FitOptions(optimizer="lm", starts=1, max_iter=25, reg=1e-4, start_amplitude=0.02, schedule=()))
        w = model.vertex_areas
        errors.append(np.sqrt(w @ (r.best.params - target.factors) ** 2 / (w @ target.factors ** 2)))
    assert errors[1] > errors[0]


@pytest.mark.slow
def test_cli_fit_writes_summary_result_and_figures(tmp_path):
    out = tmp_path / "fit"
    code = main(["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "20", "--starts", "2",
                 "--all-starts", "--workers", "1", "--max-iter", "3", "--schedule", "2,6", "--out", str(out),
                 "--quiet"])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in ("energy", "relative_residual", "time_s", "starts", "cilm", "alignment"):
        assert key in summary
    assert len(summary["starts"]) == 2
    cilm = np.array(summary["cilm"])
    assert cilm.shape == (2, 7, 7)
    for name in ("factors.png", "history.png", "residuals.png", "result.h5"):
        assert (out / name).stat().st_size > 0
    assert main(["fit", "--target", "nonsense", "--out", str(out), "--quiet"]) == 1


def test_cli_degree_ramp_with_basin_hops(tmp_path):
    from shspec.inverse import default_schedule, degree_ramp, load_result_summary
    from shspec.inverse.schedule import DEFAULT_STAGE_MAX_ITER

    assert main(["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "20", "--starts", "1",
                 "--max-iter", "5", "--schedule", "degree-ramp", "--basin-hops", "1", "--hop-tries", "7",
                 "--hop-extend", "20", "--out", str(tmp_path), "--quiet"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    stages = [(s["lmax_factor"], s["numeig"]) for s in summary["options"]["schedule"]]
    assert stages == [(s.lmax_factor, s.numeig) for s in degree_ramp(20, 6)]
    assert summary["options"]["basin_hops"] == 1 and summary["options"]["hop_tries"] == 7
    assert summary["options"]["hop_extend"] == 20
    history = load_result_summary(tmp_path / "result.h5")["starts"][0].history
    assert sorted(set(history[:, 0].astype(int))) == list(range(len(stages)))  # every stage ran
    # the command line's default schedule is the library's
    assert default_schedule(HarmonicModel(8, 6), 20) == degree_ramp(20, 6, stage_max_iter=DEFAULT_STAGE_MAX_ITER)
    assert FitOptions().schedule is None and FitOptions().basin_hops == 12 and FitOptions().hop_grid
    assert FitOptions().hop_tries == 144
    assert FitOptions().hop_extend == 45


def test_cli_hop_degree_marks_the_stage_that_hops(tmp_path, capsys):
    from shspec.inverse import default_schedule, degree_ramp
    from shspec.inverse.schedule import DEFAULT_STAGE_MAX_ITER

    assert main(["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "30", "--starts", "1",
                 "--max-iter", "3", "--basin-hops", "1", "--hop-tries", "2", "--hop-degree", "3",
                 "--out", str(tmp_path), "--quiet"]) == 0
    stages = json.loads((tmp_path / "summary.json").read_text())["options"]["schedule"]
    assert [(s["lmax_factor"], s["numeig"], s["max_iter"], s["hops"]) for s in stages] == [
        (2, 16, DEFAULT_STAGE_MAX_ITER, False), (3, 25, None, True), (6, 30, None, False)]
    # the default hops at degree 6 in fits of degree 10 and more only, and the command line's default is the
    # library's
    assert default_schedule(HarmonicModel(16, 10), 300) == degree_ramp(300, 10, DEFAULT_STAGE_MAX_ITER, hop_degree=6)
    for la in (6, 9):
        assert not any(s.hops for s in default_schedule(HarmonicModel(16, la), 200))
    # --hop-degree shapes only the degree ramp of a harmonic fit
    for extra in (["--schedule", "none"], ["--schedule", "2,6"], ["--model", "mesh", "--target", "star:3,3,0.4"]):
        args = ["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "20", "--starts", "1",
                "--max-iter", "1", "--hop-degree", "3", "--out", str(tmp_path / "bad"), "--quiet", *extra]
        assert main(args) == 1
        assert "--hop-degree" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_mesh_fit_with_default_schedule(tmp_path):
    """The command line's defaults work for a mesh model too (the numeig ramp, no levels), and the summary holds
    the per-vertex comparison with the cMCF factors."""
    out = tmp_path / "mesh"
    assert main(["fit", "--target", "star:3,3,0.2", "--subdivisions", "2", "--model", "mesh", "--lmax", "8",
                 "--lmax-factor", "4", "--numeig", "20", "--starts", "1", "--max-iter", "3", "--out", str(out),
                 "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["model"].startswith("mesh n=162")
    assert summary["options"]["schedule"] is None
    for key in ("factor_error", "log_rms", "log_correlation", "fitted_range", "truth_range"):
        assert key in summary
    for name in ("vertex_factors.png", "validation.png", "history.png"):
        assert (out / name).stat().st_size > 0


def test_fit_from_a_given_start_begins_there(small, tmp_path):
    target, model = small
    truth = target.truth.coefficients
    result = fit(target, model, FitOptions(starts=2, max_iter=5, stop_at_success=False), init=truth)
    first = result.starts[0]
    assert first.history[0, 2] < 1e-12 and first.iterations == 0  # the truth is already the solution
    np.testing.assert_array_equal(first.params, truth)
    assert not np.array_equal(result.starts[1].params, truth)  # the other starts stay random
    with pytest.raises(InvalidArgumentError, match="starting point"):
        fit(target, model, FitOptions(starts=1), init=np.ones(3))


@pytest.mark.slow
def test_cli_init_continues_from_a_previous_fit(tmp_path):
    first, second = tmp_path / "a", tmp_path / "b"
    args = ["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "20", "--starts", "1",
            "--max-iter", "3", "--schedule", "2,6", "--basin-hops", "0", "--quiet"]
    assert main([*args, "--out", str(first)]) == 0
    again = [*args[:-5], "--schedule", "auto", "--basin-hops", "0", "--quiet"]
    assert main([*again, "--out", str(second), "--init", str(first / "summary.json")]) == 0
    from shspec.inverse import load_result_summary

    a = load_result_summary(first / "result.h5")
    b = load_result_summary(second / "result.h5")
    # with a given start the default schedule is one stage at full degree: it begins exactly where the first ended
    np.testing.assert_allclose(b["starts"][0].history[0, 1], a["starts"][0].history[-1, 1], rtol=1e-9)
    assert b["starts"][0].energy <= a["starts"][0].energy
    assert main([*args, "--out", str(tmp_path / "c"), "--init", str(tmp_path / "missing.npy")]) == 1


@pytest.mark.slow
def test_starts_on_an_executor_equal_the_serial_run(small):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from distributed import Client, LocalCluster

    target, model = small
    opts = FitOptions(starts=3, seed=4, max_iter=3, schedule=(Stage(4), Stage(6)), basin_hops=0)
    serial = fit(target, model, opts)
    # spawn, not fork: numba's OpenMP threads make fork unsafe (shspec.core.parallel.make_executor does the same)
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        pooled = fit(target, model, opts, executor=pool)
    # one thread per worker: pyshtools' Fortran grid routines are not thread-safe (two starts in threads of one
    # process returned garbage under load)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        dasked = fit(target, model, opts, executor=client.get_executor())
    for other in (pooled, dasked):
        assert [r.index for r in other.starts] == [0, 1, 2]
        assert other.solutions == serial.solutions
        for a, b in zip(serial.starts, other.starts):  # bit for bit: every start runs on one BLAS thread
            np.testing.assert_array_equal(b.params, a.params)
            np.testing.assert_array_equal(b.history, a.history)


@pytest.mark.slow
def test_cli_mesh_fit_of_a_real_mesh_writes_its_summary(shared_meshes, tmp_path):
    """The first-hour report: a mesh fit of spot_600 whose degree-4 truth is not positive still writes summary.json
    (the alignment is reported as skipped, the per-vertex comparison is there)."""
    out = tmp_path / "spot"
    assert main(["fit", "--target", f"mesh:{shared_meshes / 'spot_600.obj'}", "--model", "mesh", "--lmax", "10",
                 "--lmax-factor", "4", "--numeig", "25", "--starts", "1", "--max-iter", "3", "--out", str(out),
                 "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert "alignment" in summary and "log_correlation" in summary
    assert (out / "vertex_factors.png").is_file()


@pytest.mark.slow
def test_cli_fit_on_workers_equals_the_serial_fit(tmp_path):
    args = ["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "20", "--starts", "2",
            "--max-iter", "2", "--schedule", "2,6", "--basin-hops", "0", "--quiet"]
    assert main([*args, "--workers", "1", "--out", str(tmp_path / "serial")]) == 0
    assert main([*args, "--workers", "2", "--out", str(tmp_path / "pool")]) == 0
    a = json.loads((tmp_path / "serial" / "summary.json").read_text())
    b = json.loads((tmp_path / "pool" / "summary.json").read_text())
    assert [s["energy"] for s in b["starts"]] == [s["energy"] for s in a["starts"]]
    assert main([*args, "--workers", "2", "--scheduler", "tcp://127.0.0.1:1", "--out", str(tmp_path / "x")]) == 1


def test_orienting_a_new_block_finds_its_place_relative_to_the_lower_ones():
    """The blob truncated to degree 3 with its degree-3 block turned by a 90-degree rotation: same power, wrong
    spectrum; the orientation search after the stage that fits degree 3 turns it back."""
    from shspec.inverse.hops import orient_new_block
    from shspec.inverse.problem import FitProblem

    model = HarmonicModel(10, 3)
    truth = blob_factor().truncated(3).coefficients
    target = harmonic_target(truth, 10, 30)
    moves = model.escape_moves(truth, 3, newest=True)
    assert len(moves) == 23 + 24  # proper rotations but the identity; improper ones for the odd block
    for q in moves:
        np.testing.assert_allclose(power_spectrum(q), power_spectrum(truth), rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(q[:9], truth[:9])  # the lower blocks stay where they are
    wrong = moves[5]
    problem = FitProblem(model, target, FitOptions(starts=1, schedule=(Stage(2, 16), Stage(3, 30)), max_iter=30,
                                                   hop_iter=3, orient_blocks=True))
    progress, ev = _state_at(problem, wrong, stage=1)
    assert ev.relative_residual > 1e-4
    orient_new_block(problem, progress, 1)
    assert progress.relative_residual < 1e-10
    assert align(ConformalFactor(progress.params), truth).relative_error < 1e-8


def test_the_optimizer_default_is_the_models_in_api_and_cli(tmp_path):
    from shspec.inverse.problem import FitProblem
    from shspec.mesh.model import MeshModel
    from shspec.mesh.shapes import icosphere

    target = harmonic_target(blob_factor(), 8, 20)
    assert FitProblem(HarmonicModel(8, 6), target, FitOptions()).optimizer == "lm"
    assert FitProblem(MeshModel(icosphere(1)), target, FitOptions()).optimizer == "lbfgs"
    assert FitProblem(MeshModel(icosphere(1)), target, FitOptions(optimizer="lm")).optimizer == "lm"
    assert main(["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "20", "--starts", "1",
                 "--max-iter", "2", "--schedule", "none", "--basin-hops", "0", "--out", str(tmp_path), "--quiet"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["optimizer"] == "lm" and summary["options"]["optimizer"] is None


def _lm_trace(truth, lb, la, k, **options):
    """Relative residuals of LM after each iteration from 1e-3 (RMS, relative) off a zero-residual truth."""
    model = HarmonicModel(lb, la)
    target = harmonic_target(truth, lb, k)
    free = model.free_parameters(False)
    start = np.array(truth, dtype=float)
    start[free] += 1e-3 * start[0] * np.random.default_rng(0).standard_normal(free.size) \
        / np.sqrt(np.arange(1, free.size + 1))
    par = Parametrization.at(start, free)
    obj = Objective(model, target.eigenvalues, eigenvalue_weights(target.eigenvalues), par)
    opt = make_optimizer("lm", obj, par.initial(), FitOptions(**options))
    trace = []
    while opt.status is None and opt.iteration < 100:
        opt.step()
        trace.append(opt.ev.relative_residual)
    return np.array(trace), opt.status


def test_lm_final_convergence_is_superlinear():
    """On a zero-residual problem the residual ratio between successive late iterations falls (0.09, 0.03, 0.01
    measured): Gauss–Newton's fast final convergence, not a constant linear rate."""
    trace, status = _lm_trace(random_centred_coefficients(1, 6, 0.2), 12, 6, 49)
    assert status == "residual_tol" and trace[-1] <= 1e-13
    end = int(np.argmax(trace <= 1e-12))
    ratios = trace[end - 2:end + 1] / trace[end - 3:end]
    assert np.all(ratios < 0.2) and np.all(np.diff(ratios) < 0)


def test_geodesic_acceleration_shortens_the_crawl_of_lm():
    """The blob at La = 10 (121 eigenvalues, Lb 14): plain LM crawls at a few per cent per iteration through a
    curved valley (41 iterations measured), the accelerated one does not (17)."""
    truth = blob_factor(10).coefficients
    plain, s_plain = _lm_trace(truth, 14, 10, 121, lm_acceleration=False)
    fast, s_fast = _lm_trace(truth, 14, 10, 121)
    assert s_plain == s_fast == "residual_tol"
    assert fast.size <= 0.6 * plain.size
    with pytest.raises(InvalidArgumentError):
        FitOptions(lm_acceleration="yes")


def test_cli_fit_without_numeig_plans_k_and_lmax(tmp_path, capsys):
    """No --numeig: the fit takes the planned K and Lb, says so and writes the plan to summary.json.  The plan
    takes 2.5 eigenvalues per coefficient where identifiability would take fewer."""
    from shspec.fitting.numeig_plan import SEARCH_NUMEIG_FACTOR, plan_fit, plan_numeig

    truth = random_centred_coefficients(4, 3, 0.2)
    spectrum_file = tmp_path / "spectrum.txt"
    np.savetxt(spectrum_file, HarmonicModel(10, 3).spectrum(truth, 60).eigenvalues)
    out = tmp_path / "fit"
    assert main(["fit", "--target", f"spectrum:{spectrum_file}", "--lmax-factor", "3", "--starts", "1",
                 "--max-iter", "3", "--basin-hops", "0", "--schedule", "none", "--out", str(out)]) == 0
    assert "numeig = 40: K = " in capsys.readouterr().err  # the plan, with its reason
    summary = json.loads((out / "summary.json").read_text())
    identified = plan_numeig(3, random_centred_coefficients(0, 3, 0.2), noise=1e-13, accuracy=1e-8,
                             basis_tol=1e-10).numeig
    plan = plan_fit(3, random_centred_coefficients(0, 3, 0.2))
    assert identified < plan.numeig == round(SEARCH_NUMEIG_FACTOR * 16) == 40
    assert summary["numeig_plan"]["numeig"] == plan.numeig == summary["numeig"]
    assert summary["numeig_plan"]["identified"] == plan.identified == identified
    assert summary["numeig_plan"]["lmax"] == plan.lmax
    # the basis is planned for the success tolerance: the truth itself meets it there, the accurate spectrum taken
    # 8 degrees higher (on a basis converged to 1e-6 only, it would not)
    accurate = HarmonicModel(plan.lmax + 8, 3).eigenvalues(truth, plan.numeig)[1:]
    assert np.max(np.abs(HarmonicModel(plan.lmax, 3).eigenvalues(truth, plan.numeig)[1:] / accurate - 1)) <= 1e-10
    loose = plan_numeig(3, random_centred_coefficients(0, 3, 0.2), noise=1e-13, accuracy=1e-8)
    assert np.max(np.abs(HarmonicModel(loose.lmax, 3).eigenvalues(truth, plan.numeig)[1:] / accurate - 1)) > 1e-10


@pytest.mark.slow
def test_grid_hop_undoes_a_quarter_turn_when_the_cheap_moves_find_nothing(monkeypatch):
    """A quarter-turn about z of the degree-3 block is no product of the cheap moves (the half-turns about the axes
    and signs).  With the cheap moves exhausted (here: none), a hop without ``hop_grid`` accepts nothing; with it the
    grid's inverse quarter-turn (energy 0 before any refit, so tried first) returns to the truth."""
    from shspec.inverse.hops import basin_hop
    from shspec.inverse.problem import FitProblem
    from shspec.sphere.harmonics import degrees
    from shspec.sphere.rotate import rotate_coefficients

    target, model = harmonic_target(blob_factor(), 12, 49), HarmonicModel(12, 6)
    truth = blob_factor().coefficients
    sel = degrees(6) == 3
    wrong = truth.copy()
    wrong[sel] = rotate_coefficients(np.where(sel, truth, 0.0), np.array([np.pi / 2, 0.0, 0.0]))[sel]
    cheap = type(model).escape_moves
    monkeypatch.setattr(type(model), "escape_moves",
                        lambda self, params, level=None, *, newest=False:
                        cheap(self, params, level, newest=True) if newest else [])
    ends = {}
    for grid in (False, True):
        problem = FitProblem(model, target, FitOptions(starts=1, max_iter=30, schedule=(Stage(),), basin_hops=2,
                                                       hop_iter=3, hop_grid=grid))
        progress, ev = _state_at(problem, wrong)
        assert ev.relative_residual > 1e-3
        basin_hop(problem, progress, "energy_tol", 0)
        ends[grid] = (progress.relative_residual, align(ConformalFactor(progress.params), truth).relative_error)
    assert ends[False][0] == ev.relative_residual
    assert ends[True][0] < 1e-10 and ends[True][1] < 1e-8


def test_hop_options_are_checked():
    with pytest.raises(InvalidArgumentError, match="hop_tries"):
        FitOptions(hop_tries=0)
    with pytest.raises(InvalidArgumentError, match="hop_extend"):
        FitOptions(hop_iter=15, hop_extend=10)
    with pytest.raises(InvalidArgumentError, match="hop_grid must be a bool"):
        FitOptions(hop_grid="yes")


def test_hop_screens_with_plain_lm_and_refits_the_accepted_move_with_acceleration(small, monkeypatch):
    """The short refits of the moves run without the geodesic acceleration (FitOptions.hop_iter); the accepted
    move's refit to convergence runs with the options as given."""
    from shspec.inverse import hops as hops_module
    from shspec.inverse.hops import hop_once
    from shspec.inverse.problem import FitProblem

    target, model = small
    truth = blob_factor().coefficients
    wrong = model.escape_moves(truth)[3]  # the half-turn about z of the degree-3 block
    seen = []
    original = hops_module.make_optimizer

    def recording(name, objective, x0, options, state=None):
        seen.append(options.lm_acceleration)
        return original(name, objective, x0, options, state)

    monkeypatch.setattr(hops_module, "make_optimizer", recording)
    problem = FitProblem(model, target, FitOptions(starts=1, max_iter=20, schedule=(Stage(),), hop_iter=3))
    progress, _ = _state_at(problem, wrong)
    accepted, _ = hop_once(problem, progress, 0, model.escape_moves(wrong), "energy_tol")
    assert accepted and progress.relative_residual < 1e-10
    assert seen[-1] is True and seen[:-1] and not any(seen[:-1])


def test_a_hop_refits_at_most_hop_tries_moves(small, monkeypatch):
    """At the truth (energy 0) no move can be accepted, so a hop refits exactly min(moves, hop_tries) of them."""
    from shspec.inverse import hops as hops_module
    from shspec.inverse.hops import hop_once
    from shspec.inverse.problem import FitProblem

    target, model = small
    truth = blob_factor().coefficients
    calls = {"n": 0}
    original = hops_module.make_optimizer

    def counting(*args, **kwargs):
        calls["n"] += 1
        return original(*args, **kwargs)

    monkeypatch.setattr(hops_module, "make_optimizer", counting)
    moves = model.escape_moves(truth)
    for tries in (1, 5, len(moves) + 3):
        problem = FitProblem(model, target, FitOptions(starts=1, schedule=(Stage(),), hop_iter=1, hop_tries=tries))
        progress, _ = _state_at(problem, truth)
        calls["n"] = 0
        accepted, _ = hop_once(problem, progress, 0, moves, "residual_tol")
        assert not accepted and calls["n"] == min(tries, len(moves))


def test_a_hop_extends_only_the_refits_still_falling_above_the_energy(small, monkeypatch):
    """A screening refit goes past hop_iter only while its energy is at or above the state's and fell by
    _FALLING over the last _FALLING_SPAN iterations, and never past hop_extend."""
    from shspec.inverse import hops as hops_module
    from shspec.inverse.hops import _FALLING, _FALLING_SPAN, hop_once
    from shspec.inverse.problem import FitProblem

    target, model = small
    truth = blob_factor().coefficients  # energy 0: no move is accepted, and every refit is screened to its end
    traces = []
    original = hops_module.make_optimizer

    def tracing(name, objective, x0, options, state=None):
        optimizer = original(name, objective, x0, options, state)
        trace = [optimizer.ev.energy]
        step = optimizer.step

        def traced_step():
            step()
            trace.append(optimizer.ev.energy)

        optimizer.step = traced_step
        if not options.lm_acceleration:  # a screening refit, not the accepted move's refit to convergence
            traces.append((optimizer, trace))
        return optimizer

    monkeypatch.setattr(hops_module, "make_optimizer", tracing)
    longest = {}
    for extend in (2, 12):
        traces.clear()
        problem = FitProblem(model, target, FitOptions(starts=1, max_iter=20, schedule=(Stage(),), hop_iter=2,
                                                       hop_extend=extend))
        progress, _ = _state_at(problem, truth)
        energy = progress.energy
        assert not hop_once(problem, progress, 0, model.escape_moves(truth), "residual_tol")[0]

        def falling(t, i):
            return energy <= t[i] <= (1.0 - _FALLING) * t[max(i - _FALLING_SPAN, 0)]

        for optimizer, t in traces:
            iterations = len(t) - 1
            assert iterations <= extend
            assert all(falling(t, i) for i in range(2, iterations))  # every step taken past hop_iter
            if 2 <= iterations < extend and optimizer.status is None:
                assert not falling(t, iterations)
        longest[extend] = max(len(t) - 1 for _, t in traces)
    assert longest[2] == 2 and longest[12] > 2


def _max_relative_difference(model, a, k):
    return lambda basis: np.max(np.abs(model.restrict(None, basis).eigenvalues(a, k)[1:]
                                       / model.eigenvalues(a, k)[1:] - 1.0))


def test_stage_basis_is_the_smallest_that_agrees_at_the_reference():
    model = HarmonicModel(16, 6)
    sub = model.restrict(4)
    before = set(model.table._restricted)
    lb = model.stage_basis(4, 36, 1e-5)
    assert lb is not None and lb < 16
    # the bisection's probes are not kept in the shared table
    assert set(model.table._restricted) <= before | {(16, 4)}
    differ = _max_relative_difference(sub, random_centred_coefficients(0, 4, 0.2), 36)
    assert differ(lb) <= 1e-5 < differ(lb - 1)
    # another ρ of the starts' law is resolved to the same order on that basis
    assert _max_relative_difference(sub, random_centred_coefficients(5, 4, 0.2), 36)(lb) <= 1e-3
    assert model.stage_basis(4, 36, 1e-15) is None  # only the model's own basis agrees to rounding
    assert model.stage_basis(4, 36, 1.0) == 7  # the floor, (Lb' + 1)² ≥ 1.5 K


def test_the_stage_bases_chosen_on_an_executor_equal_those_chosen_here(monkeypatch):
    from concurrent.futures import ThreadPoolExecutor

    from shspec.inverse import problem as problem_module
    from shspec.inverse.problem import FitProblem

    monkeypatch.setattr(problem_module, "usable_cores", lambda: 2)

    class Counting(ThreadPoolExecutor):
        jobs = 0

        def submit(self, fn, /, *args, **kwargs):
            Counting.jobs += 1
            return super().submit(fn, *args, **kwargs)

    model = HarmonicModel(20, 6)
    target = harmonic_target(blob_factor(), 20, 120)
    here = FitProblem(model, target, FitOptions())
    with Counting(2) as pool:
        there = FitProblem(model, target, FitOptions(), executor=pool)
    assert Counting.jobs == 2  # split over the cores
    assert there.bases == here.bases and there.stages == here.stages and there.search == here.search is not None


def test_early_stages_run_on_their_own_basis_and_the_last_on_the_model():
    from shspec.inverse.problem import FitProblem

    model = HarmonicModel(20, 6)
    target = harmonic_target(blob_factor(), 20, 120)
    plain = FitProblem(model, target, FitOptions(search_basis_tol=None))
    x = plain.initial(np.random.default_rng(0))
    assert plain.search is None and plain.stages == default_schedule(model, 120)
    assert plain.bases[-1] is None and plain.objective(len(plain.stages) - 1, x).model is model
    assert 6 <= plain.bases[0] < 20 and plain.objective(0, x).model.lmax == plain.bases[0]
    assert all(b is None or b < 20 for b in plain.bases)
    assert FitProblem(model, target, FitOptions(stage_basis_tol=None, search_basis_tol=None)).bases == [
        None] * len(plain.stages)
    # by default the last stage searches (and hops) on a smaller basis good to 1e-6, and a copy of it on the
    # model's own basis polishes; only the polish must meet success_tol
    problem = FitProblem(model, target, FitOptions())
    s = problem.search
    assert s == len(plain.stages) - 1 and problem.stages == (*plain.stages[:-1], replace(plain.stages[-1], hops=True),
                                                             plain.stages[-1])
    assert problem.bases[:-2] == plain.bases[:-1] and problem.bases[-1] is None
    assert model.stage_basis(6, 120, 1e-6) == problem.bases[s] < 20
    ev = target.eigenvalues
    assert problem.succeeded(ev, 9e-6, s) and not problem.succeeded(ev, 2e-5, s)
    assert not problem.succeeded(ev, 9e-6, s + 1) and not problem.succeeded(ev, 9e-6)


def test_models_without_coarser_bases_say_so():
    from shspec.mesh.model import MeshModel
    from shspec.mesh.shapes import icosphere

    model = MeshModel(icosphere(1))
    assert model.stage_basis(None, 10, 1e-5) is None
    with pytest.raises(InvalidArgumentError, match="no coarser discretization"):
        model.restrict(None, 3)
    with pytest.raises(InvalidArgumentError, match="stage_basis_tol"):
        FitOptions(stage_basis_tol=0.0)


def test_cli_stage_basis_tolerance_takes_a_positive_number_or_none():
    import argparse

    from shspec.cli.fit import _optional_tol

    assert _optional_tol("1e-6") == 1e-6 and _optional_tol("none") is None
    for bad in ("0", "-1e-5", "tiny"):
        with pytest.raises(argparse.ArgumentTypeError, match="positive tolerance or 'none'"):
            _optional_tol(bad)


def test_a_fit_stopped_in_a_wrong_basin_reports_its_error_as_unknown():
    """From the blob with one degree block turned (an escape move), LM without hops ends in a local minimum (64
    eigenvalues, degree 6): the linearized estimate there is several times too small while rho is off by percent,
    so the result must call its error unknown instead of printing that number."""
    from shspec.inverse.output import summary

    target, model = harmonic_target(blob_factor(), 12, 64), HarmonicModel(12, 6)
    wrong = model.escape_moves(blob_factor().coefficients)[7]
    options = FitOptions(starts=1, basin_hops=0, schedule=(Stage(),), max_iter=100)
    result = fit(target, model, options, init=wrong)
    assert not result.best.success and result.best.relative_residual > 1e-6
    measured = align(result.factor(), target.truth).relative_error
    ident = result.identifiability()
    # the linearized estimate is far too small there (0.006 against 0.026): a local minimum is no noisy solution
    assert measured > 0.01 and ident.estimated_error < 0.5 * measured
    assert ident.converged is False and ident.error_estimate is None
    assert "unknown" in ident.statement() and "estimated relative error" not in ident.statement()
    record = summary(result)["identifiability"]
    assert record["estimated_error"] is None and record["error"].startswith("unknown") and not record["converged"]
    converged = fit(target, model, options, init=model.escape_moves(blob_factor().coefficients)[2])
    assert converged.best.success and converged.identifiability().error_estimate is not None


@pytest.mark.slow
def test_cli_fit_takes_the_truth_from_a_file_and_reports_the_aligned_error(tmp_path, capsys):
    truth = ConformalFactor(random_centred_coefficients(2, 4, 0.15))
    spectrum = tmp_path / "spectrum.txt"
    np.savetxt(spectrum, HarmonicModel(10, 4).eigenvalues(truth.coefficients, 25))
    np.save(tmp_path / "truth.npy", truth.to_cilm())  # a cilm array: any coefficient format is taken
    args = ["fit", "--target", f"spectrum:{spectrum}", "--lmax", "10", "--lmax-factor", "4", "--numeig", "25",
            "--starts", "2", "--workers", "1", "--quiet"]
    assert main(args + ["--truth", str(tmp_path / "truth.npy"), "--out", str(tmp_path / "fit")]) == 0
    summary = json.loads((tmp_path / "fit" / "summary.json").read_text())
    err = capsys.readouterr().out
    assert summary["alignment"]["relative_error"] < 1e-8 and "relative L2 error of rho" in err
    assert main(args + ["--out", str(tmp_path / "blind")]) == 0  # without it: no truth, no alignment
    assert "alignment" not in json.loads((tmp_path / "blind" / "summary.json").read_text())
    (tmp_path / "bad.txt").write_text("not a number\n")
    assert main(args + ["--truth", str(tmp_path / "bad.txt"), "--out", str(tmp_path / "bad")]) == 1
    assert "cannot read the true rho" in capsys.readouterr().err


def test_a_stage_whose_start_is_not_a_metric_ends_the_start_not_the_fit(small, monkeypatch, tmp_path):
    """Positivity never ends a fit: when a stage cannot start (here its perturbed start is made negative), the start
    ends at the best state of the stage before, says why, and the fit goes on and writes its result."""
    from shspec.inverse.output import write_result
    from shspec.inverse.problem import FitProblem

    target, model = small
    original = FitProblem.enter_stage

    def broken(self, s, params, rng):
        out = original(self, s, params, rng)
        return -out if s == 1 else out  # rho < 0 everywhere: no metric

    monkeypatch.setattr(FitProblem, "enter_stage", broken)
    result = fit(target, model, FitOptions(starts=2, max_iter=5, basin_hops=0, schedule=(Stage(4), Stage(6))))
    assert [s.status for s in result.starts] == ["stopped: the start of the next stage is not a metric"] * 2
    assert all(np.all(s.history[:, 0] == 0) and s.params[0] > 0 for s in result.starts)  # stage 0's own states
    write_result(result, tmp_path / "out")
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["starts"][0]["status"].startswith("stopped") and summary["identifiability"]["converged"] is False


def test_an_underdetermined_fit_gives_no_error_estimate(small):
    """20 eigenvalues cannot determine the blob's degree 6 (42 directions): a zero residual is reached anywhere on a
    set of solutions, so no linearized error may be printed, even at a converged start (the README's example)."""
    target, model = small
    result = fit(target, model, FitOptions(starts=1, max_iter=8, seed=0))
    ident = result.identifiability()
    assert ident.underdetermined and ident.estimated_error is not None and ident.error_estimate is None
    assert result.identifiability().to_dict()["estimated_error"] is None


def test_the_search_basis_is_checked_at_the_fit_and_where_it_fails_the_hops_follow_the_polish(monkeypatch, capsys):
    """The search stage's basis is chosen at a reference ρ; at a ρ far from it (a strong Möbius boost) it does not
    hold, and then the search does not hop on it: the hops run after the polish, on the model's own basis."""
    from shspec.inverse.problem import FitProblem

    problem = FitProblem(HarmonicModel(20, 6), harmonic_target(blob_factor(), 20, 120), FitOptions())
    assert problem.search_basis_holds(blob_factor().coefficients)
    assert not problem.search_basis_holds(ConformalFactor.mobius_boost(1.5, 6).coefficients)

    target = harmonic_target(blob_factor(), 16, 30)
    opts = FitOptions(starts=1, schedule=(Stage(6),), max_iter=2, basin_hops=1, hop_tries=2, hop_iter=2,
                      progress=True)
    for holds in (True, False):
        monkeypatch.setattr(FitProblem, "search_basis_holds", lambda self, params: holds)
        result = fit(target, HarmonicModel(16, 6), opts)
        err = capsys.readouterr().err
        assert set(result.starts[0].history[:, 0]) == {0, 1}  # the search, then the polish
        assert ("start 0 stage 0 basin hop 1" in err) == holds
        assert ("start 0 basin hop 1" in err) == (not holds)
        assert ("its basis does not hold at this rho" in err) == (not holds)
