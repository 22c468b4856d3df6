"""What a fit says it can expect before it runs: the many-law benchmark's record where it applies, "unknown" and
why where it does not, never a number the benchmark did not measure."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from shspec.fitting import blob_factor, harmonic_target, prepare_fit
from shspec.fitting.expected import MEASURED, Measured, expectation
from shspec.inverse import FitOptions

RECORD = Path(__file__).resolve().parents[2] / "benchmarks" / "results" / "bench_many_laws.json"


def test_the_shipped_record_is_the_benchmarks_record():
    # the expectation is an idle machine's: the runs beside a busy core (--busy) are not shipped
    runs = {key: run for key, run in json.loads(RECORD.read_text())["runs"].items() if not key.endswith("_busy")}
    assert {(m.degree, m.per_coefficient) for m in MEASURED} == {
        (int(key.split("_")[0].removeprefix("degree")), float(key.split("_K")[1])) for key in runs}
    for m in MEASURED:
        s = runs[f"degree{m.degree}_K{m.per_coefficient:g}"]["summary"]
        assert (m.truths, m.recovered, m.goal_s) == (s["truths"], s["within_goal"], s["goal_wall_s"])
        assert (m.wall_median_s, m.wall_p90_s) == pytest.approx((s["wall_median_s"], s["wall_p90_s"]), abs=0.5)


def test_the_run_that_applies_has_as_many_eigenvalues_per_coefficient_or_fewer(monkeypatch):
    runs = (Measured(6, 1.5, 24, 10, 120.0, 90.0, 120.0), Measured(6, 2.5, 24, 22, 120.0, 40.0, 110.0))
    monkeypatch.setattr("shspec.fitting.expected.MEASURED", runs)
    assert expectation(6, 122)[0] is runs[1]            # the benchmark's K at 2.5 per coefficient
    assert expectation(6, 100)[0] is runs[0] and expectation(6, 121)[0] is runs[0]
    assert expectation(6, 300)[0] is runs[1]
    measured, said = expectation(6, 60)
    assert measured is None and said.endswith("(60 eigenvalues; the many-law benchmark measured degree 6 with 74 "
                                              "and more)")
    assert expectation(10, 302) == (None, "expected success and time: unknown (the many-law benchmark has not "
                                          "measured degree 10)")
    assert expectation(6, 122, "a given start") == (None, "expected success and time: unknown (a given start)")
    assert "22 of 24 recovered within 120 s" in expectation(6, 122)[1]


def _spectrum(numeig=40):
    return harmonic_target(blob_factor(), lmax=14, numeig=numeig).eigenvalues


@pytest.mark.parametrize("fields, reason", [
    ({}, None),
    ({"workers": None}, "the starts run one after another; the benchmark ran them on two processes"),
    ({"noise": 1e-6}, "the target has errors; the benchmark's spectra are exact"),
    ({"options": FitOptions(starts=2, max_iter=50)}, "options other than the defaults: starts, max_iter"),
    ({"reg": 1e-6}, "options other than the defaults: reg"),
    ({"options": FitOptions(seed=5)}, None),   # other starts of the same law
    ({"schedule": "none"}, "a schedule other than the default"),
    ({"model": "log"}, "a log fit; the many-law benchmark measures harmonic fits of spectra"),
])
def test_a_plan_says_what_to_expect_or_why_it_is_unknown(monkeypatch, fields, reason):
    run = Measured(3, 2.5, 24, 23, 120.0, 30.0, 60.0)
    monkeypatch.setattr("shspec.fitting.expected.MEASURED", (run,))
    plan = prepare_fit(_spectrum(), **{"lmax_factor": 3, "numeig": 40, "lmax": 12, "workers": 2,
                                       "progress": False, **fields})
    measured, said = plan.expectation
    assert said in plan.statement() and plan.record()["expectation"]["said"] == said
    if reason is None:
        assert measured is run and "23 of 24 recovered within 120 s; wall time median 30 s" in said
    else:
        assert measured is None and said == f"expected success and time: unknown ({reason})"

