"""``shspec fit`` stopped by SIGTERM, Ctrl-C or kill -9 and continued with ``--resume`` ends as the uninterrupted fit:
parameters, history, iteration counts and summary.json but its timings (issue 50 item 4)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from shspec.inverse import load_result_summary

#: A fit of degree 4 to the degree-6 blob: no zero residual, so that its start ends in a few seconds of basin hops
#: (seven accepted, then a round of grid moves), inside which the signal lands.
FIT = ["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "4", "--numeig", "20", "--starts", "1",
       "--max-iter", "30", "--schedule", "2,4", "--basin-hops", "12", "--hop-tries", "40", "--checkpoint-every", "2",
       "--workers", "1", "--stage-basis-tol", "none", "--search-basis-tol", "none"]
_ENV = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2]), "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}


def _shspec(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "shspec", *args], env=_ENV, capture_output=True, text=True,
                          timeout=300)


def _without_timings(summary: dict) -> dict:
    summary.pop("time_s")
    summary["options"].pop("checkpoint_path")  # in each fit's own folder
    for start in summary["starts"]:
        start.pop("time_s")
    return summary


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("whole") / "fit"
    done = _shspec(*FIT, "--quiet", "--out", str(out))
    assert done.returncode == 0, done.stderr
    return out


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT, signal.SIGKILL])
def test_a_fit_stopped_in_its_hops_and_resumed_ends_as_the_uninterrupted_one(uninterrupted, tmp_path, signum):
    out = tmp_path / "fit"
    proc = subprocess.Popen([sys.executable, "-m", "shspec", *FIT, "--out", str(out)], env=_ENV,
                            stderr=subprocess.PIPE, text=True)
    line = "fitting"
    while line and "basin hop 1:" not in line:  # EOF if the fit died
        line = proc.stderr.readline()
    assert line, proc.communicate(timeout=60)[1]
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=120)
    # kill -9 leaves the last checkpoint (and the folder's lock, of a process that no longer runs)
    assert proc.returncode == (-signal.SIGKILL if signum == signal.SIGKILL else 130), err
    resumed = _shspec(*FIT, "--quiet", "--resume", "--out", str(out))
    assert resumed.returncode == 0, resumed.stderr
    a, b = load_result_summary(out / "result.h5"), load_result_summary(uninterrupted / "result.h5")
    for x, y in zip(a["starts"], b["starts"], strict=True):
        assert (x.iterations, x.status, x.work) == (y.iterations, y.status, y.work)
        np.testing.assert_array_equal(x.history, y.history)
        np.testing.assert_array_equal(x.params, y.params)
    assert (_without_timings(json.loads((out / "summary.json").read_text()))
            == _without_timings(json.loads((uninterrupted / "summary.json").read_text())))
