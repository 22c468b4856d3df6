"""The one progress display of a fit: lines for stages, hops and starts; a bar with the count of starts, successes
and the time left on a terminal only; nothing with progress off."""

import io

import numpy as np

from shspec.galerkin import HarmonicModel
from shspec.inverse import FitOptions, Stage, fit
from shspec.fitting import blob_factor, harmonic_target
from shspec.inverse.progress import FitDisplay
from shspec.inverse.results import StartResult


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def _result(index, success):
    return StartResult(index=index, params=np.zeros(1), energy=0.0, relative_residual=1e-12 if success else 1e-3,
                       iterations=3, seconds=1.5, status="residual_tol", history=np.zeros((1, 3)),
                       eigenvalues=np.zeros(2), success=success)


def test_on_a_terminal_the_bar_counts_starts_successes_and_time_left():
    out = _Terminal()
    display = FitDisplay(3, 2, True, file=out)
    display.iteration(0, 1, 7, 2.5e-4)
    display.stage_done()
    display.start_done(_result(0, True))
    display.start_done(_result(1, False))
    display.close()
    text = out.getvalue()
    assert "fit: 2/3 starts done, 1 succeeded" in text
    assert "left" in text and "elapsed" in text
    assert "start 1 done: residual_tol" in text and "(2/3, 1 succeeded)" in text


def test_elsewhere_only_lines_and_with_progress_off_nothing():
    log = io.StringIO()
    display = FitDisplay(2, 2, True, file=log)
    display.iteration(0, 0, 1, 1e-2)
    display.start_done(_result(0, True))
    display.close()
    assert log.getvalue().splitlines() == ["  start 0 done: residual_tol, max rel. residual 1.000e-12, 2 s "
                                           "(1/2, 1 succeeded)"]
    quiet = _Terminal()
    display = FitDisplay(2, 2, False, file=quiet)
    display.message("x")
    display.start_done(_result(0, True))
    display.close()
    assert quiet.getvalue() == ""


def test_a_fit_reports_its_stages_and_starts_through_the_display(capsys):
    target = harmonic_target(blob_factor(), lmax=8, numeig=20)
    fit(target, HarmonicModel(8, 6), FitOptions(starts=2, max_iter=3, basin_hops=0, progress=True,
                                                schedule=(Stage(2), Stage(6))))
    err = capsys.readouterr().err
    assert "\r" not in err  # no hand-made carriage returns off a terminal
    assert err.count("stage 0 (degree 2, 20 eigenvalues") == 2 and err.count("stage 1 (degree 6") == 2
    assert "start 0 done" in err and "(2/2, " in err
    fit(target, HarmonicModel(8, 6), FitOptions(starts=1, max_iter=3, basin_hops=0, schedule=(Stage(6),)))
    assert "start 0 done" in capsys.readouterr().err  # shown by default, in Python too
    fit(target, HarmonicModel(8, 6), FitOptions(starts=1, max_iter=3, basin_hops=0, schedule=(Stage(6),),
                                                progress=False))
    assert capsys.readouterr().err == ""
