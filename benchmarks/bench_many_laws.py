"""``shspec fit`` with its defaults on random ρ of laws other than the planner's → benchmarks/results/bench_many_laws.json.

The planner assumes a centred ρ whose degree-l RMS amplitude falls as 0.2/l.  A user's ρ follows no such law, so
the truths here come from five others, chosen before any was run and never tuned on:

* ``l^-1``, ``l^-1.5``, ``l^-2``: per-degree RMS amplitude ∝ l⁻¹, l⁻¹·⁵, l⁻² over degrees 2 … La;
* ``dominant``: one degree (drawn in 2 … La) carries 90 % of the variance, the rest falls as l⁻¹;
* ``axisymmetric``: orders m = 0 only, amplitude ∝ l⁻¹·⁵;

each scaled to a total RMS of ρ − 1 drawn uniformly in [0.05, 0.3], mean 1, a_1m = 0 (Möbius-centred), and redrawn
(the next draw of the same generator) until ρ ≥ 0.2 everywhere.  Truth i of degree La uses the generator seeded
``[7000, La, i]`` and law ``LAWS[i % 5]``: 24 truths per degree cover every law four or five times.

The spectrum is computed independently of the fit's Galerkin assembly: the mass matrix by Gauss–Legendre quadrature
of ρ Y_i Y_j on a grid of degree 2·Lb + La (:func:`bench_forward.quadrature_mass`), the stiffness diag(l(l+1)),
scipy's generalized eigensolver, on a basis Lb = 4 La + 12; its convergence is recorded as the largest relative
change of the K eigenvalues from Lb − 4.  K is what the plan asks (2.5 per coefficient of ρ) or, with
``--per-coefficient F``, F per coefficient.  A spectrum shorter than the plan's is refused by the defaults
(``ShortSpectrumError``, naming the degree it supports): each truth records that answer (``default``), then the fit
a user who insists gets (``--allow-short-spectrum``).

Each fit is ``shspec fit --target spectrum:FILE --lmax-factor La --truth FILE --out DIR --quiet`` with every other
option at its default, in a fresh process on the machine's cores, stopped at the degree's goal (degree 6: 2 min,
8: 5 min, 10: 12 min).  Recorded per truth: its law, seed, RMS and minimum, the wall time, the load, the starts run,
each start's residual, iterations and time, the error of ρ after Möbius + O(3) alignment, of its per-degree power,
and the error the fit reported (``rho_error``); recovered means the per-degree power to 1e-8 relative.

With ``--busy`` one core is kept busy during every fit by a process that spins (a pure-Python loop, started before
the benchmark's first fit, stopped after its last); the run is recorded apart (``..._busy``) with the ratio of its
median wall time to that of the idle run of the same truths.

Run:  python -m benchmarks run bench_many_laws --degrees 6 [--truths 24] [--per-coefficient 1.5] [--first N] [--busy]
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import scipy.linalg

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_forward import basis_on_grid, quadrature_mass  # noqa: E402
from common import run_fit_command, updated_record, write_json  # noqa: E402

from shspec.fitting.numeig_plan import search_numeig  # noqa: E402
from shspec.sphere.factor import ConformalFactor  # noqa: E402
from shspec.sphere.grid import glq_grid  # noqa: E402
from shspec.sphere.harmonics import degree_order, degrees  # noqa: E402

NAME = "bench_many_laws.json"

#: The laws of the truths, in the order truth i takes them (i % 5).
LAWS = ("l^-1", "l^-1.5", "l^-2", "dominant", "axisymmetric")

#: Wall-time goal of a fit, per degree (issue 49).
GOALS = {6: 120.0, 8: 300.0, 10: 720.0}

#: Recovered: the per-degree power of ρ to this relative error after alignment.
RECOVERED = 1e-8

#: The smallest ρ a truth may have (a redraw otherwise).
MIN_RHO = 0.2


def truth(degree: int, index: int) -> tuple[np.ndarray, dict]:
    """The flat coefficients of truth ``index`` of ``degree`` (module notes) and what it is."""
    law = LAWS[index % len(LAWS)]
    rng = np.random.default_rng([7000, degree, index])
    ls, ms = degree_order(degree)
    while True:
        a = rng.standard_normal(ls.size)
        scale = np.where(ls >= 2, np.maximum(ls, 1).astype(float), np.inf)
        if law == "dominant":
            a /= scale
            top = rng.integers(2, degree + 1)
            own = ls == top
            # 90 % of the variance in the dominant degree, whatever the others hold
            a[own] *= np.sqrt(9 * np.sum(a[~own & (ls >= 2)] ** 2) / np.sum(a[own] ** 2))
        else:
            a /= scale ** {"l^-1": 1.0, "l^-1.5": 1.5, "l^-2": 2.0, "axisymmetric": 1.5}[law]
            if law == "axisymmetric":
                a[ms != 0] = 0.0
        rms = rng.uniform(0.05, 0.3)
        a *= rms * np.sqrt(4 * np.pi) / np.linalg.norm(a)  # RMS of rho - 1 over the sphere: |a| / sqrt(4 pi)
        a[0] = np.sqrt(4 * np.pi)
        minimum = ConformalFactor(a).minimum().value
        if minimum >= MIN_RHO:
            return a, {"law": law, "seed": [7000, degree, index], "rms": float(rms), "minimum": float(minimum)}


def quadrature_spectrum(a: np.ndarray, degree: int, numeig: int) -> tuple[np.ndarray, float]:
    """The first K eigenvalues of ρ by quadrature (module notes), and their largest change from Lb − 4."""
    def solve(lb):
        grid = glq_grid(2 * lb + degree)
        y = basis_on_grid(lb, grid)
        ls = degrees(lb).astype(float)
        return scipy.linalg.eigh(np.diag(ls * (ls + 1.0)), quadrature_mass(a, y, grid),
                                 subset_by_index=[0, numeig - 1], eigvals_only=True)

    lb = 4 * degree + 12
    lam, coarse = solve(lb), solve(lb - 4)
    lam[0] = 0.0
    return lam, float(np.max(np.abs(coarse[1:] / lam[1:] - 1)))


def run_truth(degree: int, index: int, per_coefficient: float, work: Path) -> dict:
    a, record = truth(degree, index)
    numeig = int(round(per_coefficient * (degree + 1) ** 2))
    lam, change = quadrature_spectrum(a, degree, numeig)
    name = f"d{degree}_{index}"
    rho, spectrum, out = work / f"rho_{name}.txt", work / f"spectrum_{name}.txt", work / f"fit_{name}"
    np.savetxt(rho, a)
    np.savetxt(spectrum, lam)
    command = ["fit", "--target", f"spectrum:{spectrum}", "--lmax-factor", str(degree), "--truth", str(rho),
               "--quiet", "--out"]
    record.update(numeig_given=numeig, spectrum_convergence=change)
    if numeig < search_numeig(degree):
        record["default"] = short_spectrum_default(command, work / f"default_{name}")
        command.insert(1, "--allow-short-spectrum")  # what a user who insists gets
    record.update(run_fit_command([*command, str(out)], out, GOALS[degree]))
    power = record.get("power_error")
    record["recovered"] = bool(power is not None and power <= RECOVERED)
    record["goal_met"] = bool(record["recovered"] and record["wall_s"] <= GOALS[degree])
    # a small reported error for a truth not recovered is what a user must never be shown
    reported = record.get("reported_rho_error")
    record["overconfident"] = bool(not record["recovered"] and reported is not None
                                   and reported < 0.5 * (record.get("rho_error") or np.inf))
    return record


def short_spectrum_default(command: list, out: Path) -> dict:
    """The defaults' answer to a spectrum shorter than the plan's: refused before any fit, naming the degree it
    supports (``ShortSpectrumError``), or not."""
    answer = run_fit_command([*command, str(out)], out, 60.0)
    named = re.search(r"support degree (\d+)", answer.get("stderr", ""))
    return {"refused": answer["exit_code"] == 1 and named is not None and not (out / "summary.json").exists(),
            "supported_degree": None if named is None else int(named.group(1)), "wall_s": answer["wall_s"]}


def degree_summary(rows: list, degree: int) -> dict:
    walls = sorted(r["wall_s"] for r in rows)
    return {"truths": len(rows), "recovered": sum(r["recovered"] for r in rows),
            "recovered_share": sum(r["recovered"] for r in rows) / len(rows),
            "within_goal": sum(r["goal_met"] for r in rows), "goal_wall_s": GOALS[degree],
            "wall_median_s": statistics.median(walls), "wall_p90_s": walls[int(0.9 * (len(walls) - 1))],
            "overconfident": sum(r["overconfident"] for r in rows),
            **({"refused_by_default": sum(r["default"]["refused"] for r in rows),
                "supported_degrees_named": sorted({r["default"]["supported_degree"] for r in rows})}
               if all("default" in r for r in rows) else {}),
            "by_law": {law: f"{sum(r['recovered'] for r in rows if r['law'] == law)} of "
                            f"{sum(r['law'] == law for r in rows)}" for law in LAWS}}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--degrees", default="6", help="comma-separated degrees among 6, 8, 10")
    p.add_argument("--truths", type=int, default=24, help="truths per degree (the first N of the fixed list)")
    p.add_argument("--per-coefficient", type=float, default=2.5, help="eigenvalues per coefficient of rho")
    p.add_argument("--first", type=int, default=0,
                   help="go on from truth N, keeping the record's truths 0 … N-1 of the same run (made by the "
                        "same shspec)")
    p.add_argument("--busy", action="store_true", help="keep one core busy with a spinning process during the fits")
    args = p.parse_args()
    report = updated_record(NAME)
    runs = report.setdefault("runs", {})
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if args.busy else None
    try:
        run_degrees(args, report, runs)
    finally:
        if spinner is not None:
            spinner.kill()
    print(write_json(NAME, report))


def busy_ratio(runs: dict, key: str, rows: list) -> dict:
    """The median wall time of a busy run's truths against that of the same truths in the idle run ``key``."""
    idle = {tuple(r["seed"]): r["wall_s"] for r in runs.get(key, {}).get("truths", [])}
    pairs = [(r["wall_s"], idle[tuple(r["seed"])]) for r in rows if tuple(r["seed"]) in idle]
    if not pairs:
        return {"idle_run": key, "ratio_of_medians": None}
    busy, calm = zip(*pairs)
    return {"idle_run": key, "truths_compared": len(pairs), "idle_median_s": statistics.median(calm),
            "busy_median_s": statistics.median(busy),
            "ratio_of_medians": statistics.median(busy) / statistics.median(calm)}


def run_degrees(args, report: dict, runs: dict) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for degree in (int(d) for d in args.degrees.split(",")):
            idle_key = f"degree{degree}_K{args.per_coefficient:g}"
            key = idle_key + ("_busy" if args.busy else "")
            rows = runs.get(key, {}).get("truths", [])[:args.first]
            if [r["seed"] for r in rows] != [[7000, degree, i] for i in range(args.first)]:
                raise SystemExit(f"--first {args.first}: the record of {key} does not hold truths 0 … {args.first - 1}")
            for index in range(args.first, args.truths):
                rows.append(run_truth(degree, index, args.per_coefficient, Path(tmp)))
                print(key, index, json.dumps({k: v for k, v in rows[-1].items() if k != "per_start"}), flush=True)
                runs[key] = {"truths": rows, "summary": degree_summary(rows, degree), "commit": report["commit"]}
                if args.busy:
                    runs[key]["busy"] = busy_ratio(runs, idle_key, rows)
                write_json(NAME, report)
            print(key, json.dumps(runs[key]["summary"]), json.dumps(runs[key].get("busy")), flush=True)


if __name__ == "__main__":
    main()
