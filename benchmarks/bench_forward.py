"""Cost of the forward problem (assembly, eigensolve, energy + gradient) and accuracy per second against FEM.

Part 1, for (Lb, La, k) = (20,10,120), (30,15,256), (60,30,500), on 1 and 2 threads, timed side by side
(interleaved repeats, median):

* ``assembly``        — ``table.mass_matrix(a)`` (full symmetric M) and ``symmetrize=False`` (the upper triangle, what
  the solver uses);
* ``forward``         — ``model.spectrum(a, k)`` (positivity check + assembly + Schur-reduced standard eigh, 'evr');
* ``forward_grad``    — ``model.energy(a, target)`` (forward + adjoint gradient, one table contraction);
* ``bare_eigh``       — ``scipy.linalg.eigh(S, M, subset_by_index=[0, k-1])`` of the generalized problem with
  S = diag(l(l+1)) and M from the table: the floor a forward solve is compared with (M given, not assembled).

plus the breakdown of ``forward`` into its pieces, a comparison of LAPACK drivers ('evr', 'evx', 'evd', 'ev' on the
reduced standard problem; 'gvx', 'gvd', 'gv' on the generalized one), and (a) a straightforward quadrature
assembly M = Y diag(w ρ) Yᵀ on a pyshtools Gauss–Legendre grid exact for the integrand (degree 2Lb + La): ratio of
times and max |M_quad − M_table| / max |M|.

Part 2 (b), accuracy per second on the Möbius-boosted sphere (k = 2, eigenvalues exactly l(l+1)): lapy's linear
FEM (``lapy.TriaMesh``, ``lapy.Solver``, consistent mass) on icospheres of 642 … 40962 vertices whose vertices are
moved by the boost tan(θ'/2) = 2 tan(θ/2) — a non-uniform mesh of the round unit sphere, the discrete counterpart
of the uniform parameter domain carrying ρ_k — against shspec at Lb = 10 … 40 (La = min(2Lb, 30)); max relative
error over the first 36 eigenvalues (λ₀ = 0 excluded from the relative error), one thread for both.

Writes benchmarks/results/bench_forward.json and docs/figures/accuracy_vs_time.png.
Run:  python benchmarks/bench_forward.py   (~10–20 minutes on a loaded 2-core machine)
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pyshtools
import scipy.linalg

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, command_line, load_average, machine_info, side_by_side, summarize, threads, timed, write_json  # noqa: E402

from shspec.sphere.factor import ConformalFactor  # noqa: E402
from shspec.galerkin.model import HarmonicModel, _schur_scaled_upper  # noqa: E402
from shspec.sphere.grid import evaluate_on_grid, glq_grid  # noqa: E402
from shspec.sphere.harmonics import degree_order, degrees  # noqa: E402
from shspec.gaunt.build import build_table  # noqa: E402

CASES = [(20, 10, 120, 7), (30, 15, 256, 5), (60, 30, 500, 3)]  # (Lb, La, k, repeats)
THREADS = (1, 2)
GOALS = {"forward_over_bare_eigh": 1.3, "forward_grad_over_forward": 1.5}
BOOST = 2.0
AXIS = (0.3, -0.5, 0.81)  # a tilted axis, so that every order m of rho is present
FIGURE = REPO / "docs" / "figures" / "accuracy_vs_time.png"


# --------------------------------------------------------------------------------------------------------------
# (a) quadrature assembly


def basis_on_grid(lmax: int, grid) -> np.ndarray:
    """Y (N, nlat*nlon): the real orthonormal harmonics (pyshtools 'ortho', csphase=1) at the grid points."""
    ls, ms = degree_order(lmax)
    plm_index = ls * (ls + 1) // 2 + np.abs(ms)
    p = np.stack([pyshtools.legendre.PlmON(lmax, z, csphase=1) for z in grid.zero])  # (nlat, nplm)
    trig = np.where(ms[:, None] >= 0, np.cos(np.abs(ms)[:, None] * grid.lon[None, :]),
                    np.sin(np.abs(ms)[:, None] * grid.lon[None, :]))  # (N, nlon)
    y = p[:, plm_index][:, :, None] * trig[None, :, :]  # (nlat, N, nlon)
    return np.ascontiguousarray(y.transpose(1, 0, 2).reshape(ls.size, -1))


def quadrature_mass(a, y, grid) -> np.ndarray:
    rho = evaluate_on_grid(a, grid)
    return (y * (grid.weights * rho).ravel()[None, :]) @ y.T


# --------------------------------------------------------------------------------------------------------------
# part 1


def forward_case(lb, la, k, repeats):
    case = {"lmax": lb, "lmax_factor": la, "k": k, "nbasis": (lb + 1) ** 2, "rho": f"boost k={BOOST} axis={AXIS}"}
    t_build, table = timed(build_table, lb, la)
    case["table_build_s"] = t_build
    model = HarmonicModel(lb, la, table=table)
    a = ConformalFactor.mobius_boost(BOOST, la, axis=AXIS).coefficients
    _ = table.plan
    ls = degrees(lb).astype(float)
    s_mat = np.diag(ls * (ls + 1.0))
    m_full = table.mass_matrix(a)
    spec = model.spectrum(a, k)
    target = spec.eigenvalues * 1.01
    n = model.nbasis

    # correctness of the floor against the forward solve
    lam_bare = scipy.linalg.eigh(s_mat, m_full, subset_by_index=[0, k - 1], eigvals_only=True)
    case["max_abs_eig_diff_forward_vs_bare"] = float(np.abs(lam_bare - spec.eigenvalues).max())
    case["lambda_max"] = float(spec.eigenvalues[-1])

    h_upper = np.empty((n - 1, n - 1))
    _schur_scaled_upper(table.mass_matrix(a, symmetrize=False), model._dinv, h_upper)
    h_full = np.triu(h_upper) + np.triu(h_upper, 1).T
    coef = np.ones(k)
    lo = n - k

    big = lb >= 60
    case["timings"] = {}
    for nt in THREADS:
        # on a loaded 2-core machine 2 BLAS/numba threads can be many times slower than 1 (threads spin-wait for
        # a descheduled partner), so the 2-thread runs of the largest case are cut to one round
        reps = 1 if (big and nt == 2) else repeats
        with threads(nt):
            load_before = load_average()
            main = side_by_side({
                "assembly_full": lambda: table.mass_matrix(a),
                "assembly_upper": lambda: table.mass_matrix(a, symmetrize=False),
                "forward": lambda: model.spectrum(a, k),
                "forward_grad": lambda: model.energy(a, target),
                "bare_eigh": lambda: scipy.linalg.eigh(s_mat, m_full, subset_by_index=[0, k - 1]),
            }, reps, warmup=0 if big else 1)
            main["load_average_before_after"] = [load_before, load_average()]
            main["forward_over_bare_eigh"] = main["forward"]["median_s"] / main["bare_eigh"]["median_s"]
            main["forward_grad_over_forward"] = main["forward_grad"]["median_s"] / main["forward"]["median_s"]
            # where the forward time goes
            parts = side_by_side({
                "check_positive": lambda: ConformalFactor(a).check_positive(),
                "assembly_upper": lambda: table.mass_matrix(a, symmetrize=False),
                "schur_scale": lambda: _schur_scaled_upper(m_full, model._dinv, np.empty((n - 1, n - 1))),
                "eigh_evr_reduced": lambda: scipy.linalg.eigh(h_upper, lower=False, subset_by_index=[lo, n - 2],
                                                              driver="evr", check_finite=False),
                "gradient_contract": lambda: model.contract(spec, coef),
                "table_contract_only": lambda: table.contract(m_full),
                "jacobian_quadratic_forms": lambda: model.jacobian(spec),
            }, 1 if big else max(2, repeats - 2), warmup=0 if big else 1)
            # eigensolver drivers on the same matrices (evd/ev/gvd/gv compute all N eigenpairs); the QR drivers
            # 'ev'/'gv' only below Lb = 60 and, on 2 threads, only the three standard-problem drivers
            drivers = {
                "evr_subset": lambda: scipy.linalg.eigh(h_upper, lower=False, subset_by_index=[lo, n - 2],
                                                        driver="evr", check_finite=False),
                "evx_subset": lambda: scipy.linalg.eigh(h_upper, lower=False, subset_by_index=[lo, n - 2],
                                                        driver="evx", check_finite=False),
                "evd_all": lambda: scipy.linalg.eigh(h_upper, lower=False, driver="evd", check_finite=False),
                "ev_all": lambda: scipy.linalg.eigh(h_upper, lower=False, driver="ev", check_finite=False),
                "evr_values_only_subset": lambda: scipy.linalg.eigh(h_upper, lower=False, eigvals_only=True,
                                                                    subset_by_index=[lo, n - 2], driver="evr",
                                                                    check_finite=False),
                "gvx_subset_generalized": lambda: scipy.linalg.eigh(s_mat, m_full, subset_by_index=[0, k - 1],
                                                                    driver="gvx", check_finite=False),
                "gvd_all_generalized": lambda: scipy.linalg.eigh(s_mat, m_full, driver="gvd", check_finite=False),
                "gv_all_generalized": lambda: scipy.linalg.eigh(s_mat, m_full, driver="gv", check_finite=False),
            }
            if big:
                drivers = {name: fn for name, fn in drivers.items() if name not in ("ev_all", "gv_all_generalized")}
            if nt == 2:
                drivers = {name: fn for name, fn in drivers.items() if name in ("evr_subset", "evx_subset", "evd_all")}
            drivers = side_by_side(drivers, 1 if big else max(2, repeats - 2), warmup=0 if big else 1)
            case["timings"][f"{nt}_threads"] = {"main": main, "forward_parts": parts, "drivers": drivers}
        print(lb, la, k, nt, {kk: round(v["median_s"], 4) for kk, v in main.items() if isinstance(v, dict)},
              "fwd/bare", round(main["forward_over_bare_eigh"], 3), "grad/fwd", round(main["forward_grad_over_forward"], 3),
              flush=True)
        print("   parts", {kk: round(v["median_s"], 4) for kk, v in parts.items()}, flush=True)
        print("   drivers", {kk: round(v["median_s"], 4) for kk, v in drivers.items()}, flush=True)

    # the driver choices give the same eigenvalues?
    mu_evr = scipy.linalg.eigh(h_full, subset_by_index=[lo, n - 2], eigvals_only=True, driver="evr")
    mu_evd = scipy.linalg.eigh(h_full, eigvals_only=True, driver="evd")[lo:]
    case["evr_vs_evd_max_rel_diff"] = float(np.abs(mu_evr - mu_evd).max() / np.abs(mu_evd).max())

    # (a) quadrature assembly side by side with the table
    lq = math.ceil((2 * lb + la) / 2)
    grid = glq_grid(lq)
    t_y, y = timed(basis_on_grid, lb, grid)
    c = np.random.default_rng(0).standard_normal(n)
    y_check = float(np.abs(y.T @ c - evaluate_on_grid(c, grid).ravel()).max())
    m_quad = quadrature_mass(a, y, grid)
    quad = {"grid_degree": lq, "grid_points": int(y.shape[1]), "basis_matrix_bytes": int(y.nbytes),
            "basis_matrix_build_s": t_y, "basis_matrix_check_max_abs": y_check,
            "max_abs_diff_over_max_abs": float(np.abs(m_quad - m_full).max() / np.abs(m_full).max()),
            "timings": {}}
    del m_quad
    for nt in (1,) if big else THREADS:
        with threads(nt):
            r = side_by_side({"table_assembly_full": lambda: table.mass_matrix(a),
                              "quadrature_assembly": lambda: quadrature_mass(a, y, grid)},
                             max(2, repeats - 2))
            r["quadrature_over_table"] = r["quadrature_assembly"]["median_s"] / r["table_assembly_full"]["median_s"]
            quad["timings"][f"{nt}_threads"] = r
        print("   quadrature", nt, round(r["quadrature_over_table"], 2), flush=True)
    case["quadrature_assembly"] = quad
    del y
    return case


# --------------------------------------------------------------------------------------------------------------
# part 2: accuracy per second


def exact_eigenvalues(count: int) -> np.ndarray:
    ls = np.concatenate([np.full(2 * l + 1, l) for l in range(int(math.isqrt(count)) + 2)])[:count]
    return (ls * (ls + 1)).astype(float)


def boosted_icosphere(subdivisions: int, k: float):
    """Icosphere vertices moved by tan(θ'/2) = k tan(θ/2) about z: a non-uniform mesh of the round unit sphere."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    v = np.asarray(m.vertices, dtype=float)
    v /= np.linalg.norm(v, axis=1)[:, None]
    theta = np.arccos(np.clip(v[:, 2], -1.0, 1.0))
    phi = np.arctan2(v[:, 1], v[:, 0])
    t2 = 2.0 * np.arctan(k * np.tan(theta / 2.0))
    w = np.column_stack([np.sin(t2) * np.cos(phi), np.sin(t2) * np.sin(phi), np.cos(t2)])
    return w, np.asarray(m.faces, dtype=np.int64)


def lapy_solve(v, f, nev):
    import lapy

    solver = lapy.Solver(lapy.TriaMesh(v, f), lump=False)
    evals, _ = solver.eigs(k=nev)
    return np.sort(evals)


def accuracy_vs_time(nev=36):
    exact = exact_eigenvalues(nev)
    res = {"nev": nev, "boost_k": BOOST, "error": "max_i>=1 |λ_i − l_i(l_i+1)| / (l_i(l_i+1)), i < nev",
           "threads": 1, "lapy": [], "shspec": []}
    with threads(1):
        for s in (3, 4, 5, 6):
            v, f = boosted_icosphere(s, BOOST)
            reps = 3 if s <= 5 else 2
            times = []
            for _ in range(reps):
                t, lam = timed(lapy_solve, v, f, nev)
                times.append(t)
            err = float(np.max(np.abs(lam[1:] - exact[1:]) / exact[1:]))
            edge = np.linalg.norm(v[f[:, 0]] - v[f[:, 1]], axis=1)
            res["lapy"].append({"subdivisions": s, "vertices": int(v.shape[0]), "time": summarize(times),
                                "max_rel_error": err, "edge_length_max_over_min": float(edge.max() / edge.min())})
            print("lapy", v.shape[0], round(summarize(times)["median_s"], 3), f"{err:.2e}", flush=True)
        for lb in (10, 15, 20, 25, 30, 35, 40):
            la = min(2 * lb, 30)
            t_table, table = timed(build_table, lb, la)
            model = HarmonicModel(lb, la, table=table)
            t_factor, rho = timed(ConformalFactor.mobius_boost, BOOST, la)
            a = rho.coefficients
            model.spectrum(a, nev)  # builds the plan
            times = [timed(model.spectrum, a, nev)[0] for _ in range(5)]
            lam = model.spectrum(a, nev).eigenvalues
            err = float(np.max(np.abs(lam[1:] - exact[1:]) / exact[1:]))
            res["shspec"].append({"lmax": lb, "lmax_factor": la, "nbasis": (lb + 1) ** 2, "time": summarize(times),
                                  "table_build_s": t_table, "factor_expansion_s": t_factor,
                                  "max_rel_error": err})
            print("shspec", lb, la, round(summarize(times)["median_s"], 4), f"{err:.2e}", flush=True)
    return res


def plot(acc):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    floor = 1e-16
    lt = [r["time"]["median_s"] for r in acc["lapy"]]
    le = [max(r["max_rel_error"], floor) for r in acc["lapy"]]
    ax.loglog(lt, le, "o-", color="tab:red", label="lapy linear FEM (boosted icosphere)")
    for r, t, e in zip(acc["lapy"], lt, le):
        ax.annotate(f"{r['vertices']} v", (t, e), textcoords="offset points", xytext=(5, 4), fontsize=8)
    st = [r["time"]["median_s"] for r in acc["shspec"]]
    se = [max(r["max_rel_error"], floor) for r in acc["shspec"]]
    sc = [r["time"]["median_s"] + r["table_build_s"] for r in acc["shspec"]]
    ax.loglog(st, se, "s-", color="tab:blue", label="shspec Galerkin, table cached")
    ax.loglog(sc, se, "s:", color="tab:blue", mfc="none", alpha=0.6, label="shspec incl. table build")
    for r, t, e in zip(acc["shspec"], st, se):
        ax.annotate(f"Lb={r['lmax']}", (t, e), textcoords="offset points", xytext=(5, -10), fontsize=8)
    ax.set_xlabel("seconds (one thread, median)")
    ax.set_ylabel("max relative error, first 36 eigenvalues")
    ax.set_title(f"Möbius-boosted sphere (k = {acc['boost_k']:g}): accuracy vs time")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURE, dpi=120)
    plt.close(fig)


def main():
    command_line(__doc__)
    out = {"benchmark": "bench_forward", "machine": machine_info(), "goals": GOALS, "cases": []}
    print(out["machine"]["cpu"], "load", out["machine"]["load_average_1_5_15"], flush=True)
    build_table(6, 4)
    for lb, la, k, repeats in CASES:
        out["cases"].append(forward_case(lb, la, k, repeats))
    acc = accuracy_vs_time()
    out["accuracy_vs_time"] = acc
    plot(acc)
    out["figure"] = str(FIGURE.relative_to(REPO))
    out["goal_check"] = {}
    for c in out["cases"]:
        for nt in THREADS:
            m = c["timings"][f"{nt}_threads"]["main"]
            out["goal_check"][f"({c['lmax']},{c['lmax_factor']},{c['k']})_{nt}t"] = {
                "forward_over_bare_eigh": m["forward_over_bare_eigh"],
                "met_forward": m["forward_over_bare_eigh"] <= GOALS["forward_over_bare_eigh"],
                "forward_grad_over_forward": m["forward_grad_over_forward"],
                "met_grad": m["forward_grad_over_forward"] <= GOALS["forward_grad_over_forward"]}
    out["machine"]["load_average_end"] = load_average()
    path = write_json("bench_forward.json", out)
    print("wrote", path, flush=True)


if __name__ == "__main__":
    main()
