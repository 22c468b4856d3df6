"""The inverse solver end to end: recovery to rounding, mirror images, determinism, exact resume, positivity,
schedules, the PL path on the study's star surfaces, and the command line."""

from __future__ import annotations

import json

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest

from shspec import HarmonicModel
from shspec.cli import main
from shspec.inverse import FitOptions, Stage, align, blob_factor, fit, harmonic_target, random_centred_coefficients
from shspec.inverse import optimize as optimize_module
from shspec.inverse.energy import Objective, eigenvalue_weights, harmonic_free_indices
from shspec.inverse.optimize import make_optimizer
from shspec.sphere.rotate import mirror_coefficients, power_spectrum



@pytest.fixture(scope="module")
def recovered():
    """Lb = 20, La = 4, 120 eigenvalues; the best of three symmetry-broken starts."""
    truth = random_centred_coefficients(1, 4, 0.15)
    target = harmonic_target(truth, 20, 120)
    result = fit(target, HarmonicModel(20, 4), FitOptions(starts=3, seed=1))
    return truth, target, result


def test_best_start_recovers_spectrum_and_factor(recovered):
    truth, target, result = recovered
    assert result.best.relative_residual <= 1e-10
    assert result.success_count >= 1
    assert len(result.starts) == 3 and set(result.solutions) <= {0, 1, 2}
    al = align(result.factor(), truth)
    assert al.relative_error <= 1e-6
    assert al.power_error <= 1e-6


def test_mirror_image_is_a_match(recovered):
    truth, _, result = recovered
    direct, mirrored = align(result.factor(), truth), align(result.factor(), mirror_coefficients(truth))
    # The spectrum cannot tell a surface from its mirror image: the fit matches one of them up to a rotation, the
    # other up to a reflection, both to rounding.
    assert direct.mirrored != mirrored.mirrored
    assert max(direct.relative_error, mirrored.relative_error) <= 1e-6


def test_distinct_solutions_are_reported(recovered):
    _, _, result = recovered
    energies = [result.starts[i].energy for i in result.solutions]
    assert energies == sorted(energies)
    failed = [s for s in result.starts if not s.success]
    if failed:  # each local minimum that is not the truth is listed too, not just the best
        assert len(result.solutions) >= 2


@pytest.fixture(scope="module")
def small():
    target = harmonic_target(blob_factor(), 8, 20)
    return target, HarmonicModel(8, 6)


def test_fit_is_deterministic_under_a_seed(small):
    target, model = small
    opts = FitOptions(starts=2, seed=5, max_iter=4, schedule=(Stage(2), Stage(4), Stage(6)))
    r1, r2 = fit(target, model, opts), fit(target, model, opts)
    for a, b in zip(r1.starts, r2.starts):
        np.testing.assert_array_equal(a.params, b.params)
        np.testing.assert_array_equal(a.history, b.history)
    other = fit(target, model, FitOptions(starts=1, seed=6, max_iter=4, schedule=opts.schedule))
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
    FitOptions(schedule=degree_ramp(300, 15))  # degrees never decrease


def test_basin_hops_only_lower_the_energy_and_keep_the_gauge(small):
    from shspec.inverse.schedule import _block_moves

    target, model = small
    sched = (Stage(2, 9), Stage(6))
    plain = fit(target, model, FitOptions(starts=1, max_iter=4, schedule=sched))
    hopped = fit(target, model, FitOptions(starts=1, max_iter=4, schedule=sched, basin_hops=1, hop_iter=2))
    assert hopped.best.energy <= plain.best.energy
    assert hopped.best.iterations >= plain.best.iterations
    assert np.all(hopped.best.params[1:4] == 0)
    # Every move keeps the per-degree power (a rotation invariant) and the gauge.
    for q in _block_moves(plain.best.params, 6):
        assert np.allclose(power_spectrum(q), power_spectrum(plain.best.params))
        assert np.all(q[1:4] == 0) and q[0] == plain.best.params[0]


@pytest.mark.parametrize("optimizer", ["lm", "lbfgs", "gd"])
def test_resume_from_checkpoint_equals_uninterrupted_run(small, tmp_path, monkeypatch, optimizer):
    target, model = small
    opts = FitOptions(starts=2, seed=3, max_iter=5, optimizer=optimizer, schedule=(Stage(4), Stage(6)),
                      checkpoint_every=2, checkpoint_path=str(tmp_path / "ck.h5"))
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


def test_positivity_safeguard_never_crashes():
    model = HarmonicModel(8, 4)
    target = harmonic_target(random_centred_coefficients(2, 4, 0.4), 8, 20).eigenvalues
    start = np.zeros(25)
    start[0] = np.sqrt(4 * np.pi)
    start[6] = 1.1  # a_20 close to making ρ negative at the poles
    obj = Objective(model, target, eigenvalue_weights(target, "absolute"), start, harmonic_free_indices(4, False))
    for name in ("lm", "gd", "bfgs"):
        opt = make_optimizer(name, obj, obj.initial(), FitOptions(optimizer=name))
        energies = [opt.ev.energy]
        for _ in range(6):
            opt.step()
            energies.append(opt.ev.energy)
        assert np.all(np.diff(energies) <= 0)
        from shspec import ConformalFactor

        assert ConformalFactor(obj.params(opt.x)).minimum().value > 0


def test_pl_recovery_error_grows_with_amplitude():
    """The study's Section 3.2.1: star surfaces r = 1 + p|Y_3^3| are harder to hear as p grows."""
    from shspec.inverse import mesh_target
    from shspec.mesh.model import MeshModel
    from shspec.mesh.shapes import star_surface

    errors = []
    for p in (0.2, 0.8):
        target = mesh_target(star_surface(3, 3, p, subdivisions=2), lmax=8, numeig=40, lmax_factor=4)
        model = MeshModel(target.sphere)
        r = fit(target, model, FitOptions(starts=1, max_iter=25, reg=1e-4, start_amplitude=0.02))
        w = model.vertex_areas
        errors.append(np.sqrt(w @ (r.best.params - target.factors) ** 2 / (w @ target.factors ** 2)))
    assert errors[1] > errors[0]


def test_cli_fit_writes_summary_result_and_figures(tmp_path):
    out = tmp_path / "fit"
    code = main(["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "20", "--starts", "2",
                 "--max-iter", "3", "--schedule", "2,6", "--out", str(out), "--quiet"])
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
    import json

    from shspec.cli import main

    assert main(["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "20", "--starts", "1",
                 "--max-iter", "5", "--schedule", "degree-ramp", "--basin-hops", "1", "--out", str(tmp_path),
                 "--quiet"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert len(summary["starts"]) == 1 and summary["relative_residual"] < 1e-2
