"""Cost of building Gaunt tables: shspec against the strongest peer path, exact arithmetic, and the bare recursion.

For (Lb, La) = (20,10), (30,15), (30,30), (60,30), timed side by side (interleaved repeats) on 1 and 2 threads:

* ``shspec``       — :func:`shspec.gaunt.build.build_table`.
* ``peer_fused``   — the same table, with every 3j family computed by SHTOOLS' Fortran ``Wigner3j`` (the routine
  behind ``pyshtools.utils.Wigner3j``), called from a numba loop through ctypes (the f2py wrapper ``pywigner3j_``
  of the pyshtools extension module: explicit-shape arguments passed by reference), and the product
  √((2l1+1)(2l2+1)(2l3+1)/4π) · w(l1 l2 l3; 0 0 0) · w(l1 l2 l3; μ) formed in the same numba loop.  This is the
  strongest peer: the loop, the layout and the parallel schedule are shspec's; only the 3j kernel differs.
* ``peer_glue``    — the same Fortran families from the numba loop, which stores the needed entries of each family
  and an index into the per-(l1, l2) prefactor·(0 0 0) vector; numpy glue multiplies them into the table.
* ``peer_python``  — (20,10) only: ``pyshtools.utils.Wigner3j`` called from a plain Python loop with numpy glue, to
  show what the Python call overhead alone costs.

All peers produce exactly shspec's value array (same layout), checked elementwise, and a sample of real Gaunt
coefficients G_ijk read from the peer's values is checked against :func:`shspec.real_gaunt` (to 1e-12).
Also: sympy's exact ``real_gaunt`` for every G_ijk at Lb = La = 4, the bare Schulten–Gordon recursion
(:func:`shspec.gaunt.wigner.family_into` over every family the (60,30) table needs, one core), bytes on disk, peak memory.

Writes benchmarks/results/bench_tables.json.  Run:  python benchmarks/bench_tables.py   (~3–5 minutes)
"""

from __future__ import annotations

import ctypes
import math
import sys
import tempfile
import time
from pathlib import Path

import numba as nb
import numpy as np
import pyshtools
from pyshtools import _SHTOOLS

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import command_line, load_average, machine_info, peak_memory, side_by_side, summarize, threads, timed, write_json  # noqa: E402

from shspec import real_gaunt  # noqa: E402
from shspec.gaunt.cache import save_table  # noqa: E402
from shspec.sphere.harmonics import degree_order  # noqa: E402
from shspec.gaunt.build import build_table  # noqa: E402
from shspec.gaunt.table import GauntTable, _balanced_rows, _block_offsets, _family_count  # noqa: E402
from shspec.gaunt.wigner import family_into  # noqa: E402

CASES = [(20, 10, 7), (30, 15, 7), (30, 30, 5), (60, 30, 3)]  # (Lb, La, repeats)
THREADS = (1, 2)
GOALS = {"(60,30)_one_core_s": 1.5, "(60,30)_speedup_vs_peer": 5.0, "(30,15)_one_core_s": 0.1}
_INV_4PI = 1.0 / (4.0 * math.pi)

# --------------------------------------------------------------------------------------------------------------
# the peer: SHTOOLS' Fortran Wigner3j through ctypes, callable from numba

_lib = ctypes.CDLL(_SHTOOLS.__file__)
_f_w3j = _lib.pywigner3j_
_f_w3j.restype = None
# subroutine pyWigner3j(exitstatus, w3j, jmin, jmax, j2, j3, m1, m2, m3, w3j_d0), all by reference (int32)
_f_w3j.argtypes = [ctypes.c_void_p] * 10


@nb.njit(nogil=True)
def shtools_family(j2, j3, m1, m2, m3, w, ints):
    """(j j2 j3; m1 m2 m3) for j = jmin..j2+j3 into w[0:], by SHTOOLS' Fortran; returns jmin (ints: int32 scratch)."""
    ints[0] = 0
    ints[3] = j2
    ints[4] = j3
    ints[5] = m1
    ints[6] = m2
    ints[7] = m3
    ints[8] = w.size
    _f_w3j(ints[0:].ctypes, w.ctypes, ints[1:].ctypes, ints[2:].ctypes, ints[3:].ctypes, ints[4:].ctypes,
           ints[5:].ctypes, ints[6:].ctypes, ints[7:].ctypes, ints[8:].ctypes)
    return ints[1]


@nb.njit(nogil=True)
def _peer_row(l1, lmax, lmax_factor, off, values, w0, w, ints):
    # shspec's _fill_row with the 3j kernel swapped: family over l3 of (l3 l1 l2; -(a+mu2) a mu2)
    for l2 in range(l1, min(lmax, l1 + lmax_factor) + 1):
        pos = off[l1, l2]
        jmin0 = shtools_family(l1, l2, 0, 0, 0, w0, ints)
        for a in range(l1 + 1):
            for b in range(a if l1 == l2 else 0, l2 + 1):
                for choice in range(2):
                    if choice == 1 and (a == 0 or b == 0):
                        continue
                    mu2 = b if choice == 0 else -b
                    l3min, cnt = _family_count(l1, l2, abs(a + mu2), lmax_factor)
                    if cnt == 0:
                        continue
                    jmin = shtools_family(l1, l2, -(a + mu2), a, mu2, w, ints)
                    for t in range(cnt):
                        l3 = l3min + 2 * t
                        pref = math.sqrt((2.0 * l1 + 1.0) * (2.0 * l2 + 1.0) * (2.0 * l3 + 1.0) * _INV_4PI)
                        values[pos + t] = pref * w0[l3 - jmin0] * w[l3 - jmin]
                    pos += cnt


@nb.njit(parallel=True)
def _peer_fused(rows, lmax, lmax_factor, off, values):
    for r in nb.prange(rows.size):
        w0 = np.zeros(2 * lmax + 1)
        w = np.zeros(2 * lmax + 1)
        ints = np.zeros(9, dtype=np.int32)
        _peer_row(rows[r], lmax, lmax_factor, off, values, w0, w, ints)


def peer_fused(lmax, lmax_factor):
    off = _block_offsets(lmax, lmax_factor)
    values = np.empty(int(off[lmax, lmax + 1]))
    _peer_fused(_balanced_rows(off, lmax), lmax, lmax_factor, off, values)
    return values


@nb.njit(nogil=True)
def _glue_row(l1, lmax, lmax_factor, off, goff, raw, gidx, g0, w0, w, ints):
    # the numba part of the glue path: raw 3j entries and, per value, the index of its prefactor·(0 0 0) factor
    for l2 in range(l1, min(lmax, l1 + lmax_factor) + 1):
        pos = off[l1, l2]
        gb = goff[l1, l2]
        lo = l2 - l1
        jmin0 = shtools_family(l1, l2, 0, 0, 0, w0, ints)
        for l3 in range(lo, min(l1 + l2, lmax_factor) + 1, 2):
            g0[gb + (l3 - lo) // 2] = w0[l3 - jmin0]
        for a in range(l1 + 1):
            for b in range(a if l1 == l2 else 0, l2 + 1):
                for choice in range(2):
                    if choice == 1 and (a == 0 or b == 0):
                        continue
                    mu2 = b if choice == 0 else -b
                    l3min, cnt = _family_count(l1, l2, abs(a + mu2), lmax_factor)
                    if cnt == 0:
                        continue
                    jmin = shtools_family(l1, l2, -(a + mu2), a, mu2, w, ints)
                    for t in range(cnt):
                        l3 = l3min + 2 * t
                        raw[pos + t] = w[l3 - jmin]
                        gidx[pos + t] = gb + (l3 - lo) // 2
                    pos += cnt


@nb.njit(parallel=True)
def _glue_rows(rows, lmax, lmax_factor, off, goff, raw, gidx, g0):
    for r in nb.prange(rows.size):
        w0 = np.zeros(2 * lmax + 1)
        w = np.zeros(2 * lmax + 1)
        ints = np.zeros(9, dtype=np.int32)
        _glue_row(rows[r], lmax, lmax_factor, off, goff, raw, gidx, g0, w0, w, ints)


def _glue_layout(lmax, lmax_factor):
    """Offsets of the per-(l1, l2) vectors over l3 (pref·(0 0 0)) and their l1, l2, l3 (numpy)."""
    goff = np.zeros((lmax + 1, lmax + 2), dtype=np.int64)
    l1s, l2s, l3s = [], [], []
    pos = 0
    for l1 in range(lmax + 1):
        for l2 in range(l1, min(lmax, l1 + lmax_factor) + 1):
            goff[l1, l2] = pos
            l3 = np.arange(l2 - l1, min(l1 + l2, lmax_factor) + 1, 2)
            l1s.append(np.full(l3.size, l1))
            l2s.append(np.full(l3.size, l2))
            l3s.append(l3)
            pos += l3.size
    return goff, np.concatenate(l1s), np.concatenate(l2s), np.concatenate(l3s)


def peer_glue(lmax, lmax_factor):
    off = _block_offsets(lmax, lmax_factor)
    goff, gl1, gl2, gl3 = _glue_layout(lmax, lmax_factor)
    total = int(off[lmax, lmax + 1])
    raw = np.empty(total)
    gidx = np.empty(total, dtype=np.int32)
    g0 = np.empty(gl1.size)
    _glue_rows(_balanced_rows(off, lmax), lmax, lmax_factor, off, goff, raw, gidx, g0)
    g0 *= np.sqrt((2.0 * gl1 + 1.0) * (2.0 * gl2 + 1.0) * (2.0 * gl3 + 1.0) * _INV_4PI)
    return raw * g0[gidx]


def peer_python(lmax, lmax_factor):
    """pyshtools.utils.Wigner3j from a Python loop over the families, numpy for each family's slice."""
    off = _block_offsets(lmax, lmax_factor)
    values = np.empty(int(off[lmax, lmax + 1]))
    w3j = pyshtools.utils.Wigner3j
    for l1 in range(lmax + 1):
        for l2 in range(l1, min(lmax, l1 + lmax_factor) + 1):
            pos = int(off[l1, l2])
            w0, jmin0, _ = w3j(l1, l2, 0, 0, 0)
            for a in range(l1 + 1):
                for b in range(a if l1 == l2 else 0, l2 + 1):
                    for choice in ((0, 1) if a > 0 and b > 0 else (0,)):
                        mu2 = b if choice == 0 else -b
                        l3min, cnt = _family_count(l1, l2, abs(a + mu2), lmax_factor)
                        if cnt == 0:
                            continue
                        w, jmin, _ = w3j(l1, l2, -(a + mu2), a, mu2)
                        l3 = np.arange(l3min, l3min + 2 * cnt, 2)
                        values[pos:pos + cnt] = (np.sqrt((2.0 * l1 + 1) * (2.0 * l2 + 1) * (2.0 * l3 + 1) * _INV_4PI)
                                                 * w0[l3 - jmin0] * w[l3 - jmin])
                        pos += cnt
    return values


# --------------------------------------------------------------------------------------------------------------
# the bare recursion: every family the table needs, nothing else


@nb.njit
def _bare_recursion(lmax, lmax_factor):
    w0 = np.empty(2 * lmax + 1)
    w = np.empty(2 * lmax + 1)
    nvals = 0
    nfam = 0
    chk = 0.0
    for l1 in range(lmax + 1):
        for l2 in range(l1, min(lmax, l1 + lmax_factor) + 1):
            n = family_into(l1, l2, 0, 0, w0)[1]
            nvals += n
            nfam += 1
            chk += w0[0]
            for a in range(l1 + 1):
                for b in range(a if l1 == l2 else 0, l2 + 1):
                    for choice in range(2):
                        if choice == 1 and (a == 0 or b == 0):
                            continue
                        mu2 = b if choice == 0 else -b
                        if _family_count(l1, l2, abs(a + mu2), lmax_factor)[1] == 0:
                            continue
                        n = family_into(l1, l2, a, mu2, w)[1]
                        nvals += n
                        nfam += 1
                        chk += w[0]
    return nvals, nfam, chk


# --------------------------------------------------------------------------------------------------------------


def structural_nonzeros(table) -> dict:
    """Real G_ijk (ordered i, j <= Lb; k <= La) with a nonzero order factor and the degree rules: what the table holds."""
    p = table.plan
    per_entry = p.count.astype(np.int64) * np.where(p.i == p.j, 1, 2)
    return {"real_nonzeros_ijk": int(per_entry.sum()), "stored_values": int(table.values.size),
            "real_per_stored": float(per_entry.sum() / table.values.size), "plan_entries": int(p.i.size),
            "plan_bytes": int(sum(a.nbytes for a in p.arrays))}


def sample_check(table, values, nsample=3000, seed=1) -> dict:
    """Max |G from ``values`` (read through the table's plan) − shspec.real_gaunt| on random stored (i, j, k)."""
    rng = np.random.default_rng(seed)
    p = table.plan
    ls, ms = degree_order(table.lmax)
    worst = 0.0
    biggest = 0.0
    for e in rng.integers(0, p.i.size, nsample):
        t = int(rng.integers(0, p.count[e]))
        l3 = int(p.l3min[e]) + 2 * t
        ours = float(p.factor[e] * values[p.offset[e] + t])
        ref = real_gaunt(int(ls[p.i[e]]), int(ms[p.i[e]]), int(ls[p.j[e]]), int(ms[p.j[e]]), l3, int(p.m3[e]))
        worst = max(worst, abs(ours - ref))
        biggest = max(biggest, abs(ref))
    return {"samples": nsample, "max_abs_diff_vs_real_gaunt": worst, "max_abs_value": biggest}


def sympy_case(lmax=4) -> dict:
    from sympy.physics.wigner import real_gaunt as sympy_real_gaunt

    ls, ms = degree_order(lmax)
    lm = list(zip(ls.tolist(), ms.tolist()))
    triples = [(a, b, c) for a in lm for b in lm for c in lm]
    t0 = time.perf_counter()
    exact = np.array([float(sympy_real_gaunt(l1, l2, l3, m1, m2, m3)) for (l1, m1), (l2, m2), (l3, m3) in triples])
    t_sympy = time.perf_counter() - t0
    t0 = time.perf_counter()
    ours = np.array([real_gaunt(l1, m1, l2, m2, l3, m3) for (l1, m1), (l2, m2), (l3, m3) in triples])
    t_scalar = time.perf_counter() - t0
    t_table = summarize([timed(build_table, lmax, lmax)[0] for _ in range(20)])
    return {"lmax": lmax, "lmax_factor": lmax, "triples": len(triples), "nonzero": int(np.count_nonzero(exact)),
            "sympy_exact_s": t_sympy, "sympy_per_coefficient_s": t_sympy / len(triples),
            "shspec_real_gaunt_scalar_calls_s": t_scalar, "shspec_build_table_4_4": t_table,
            "ratio_sympy_over_table": t_sympy / t_table["median_s"],
            "ratio_sympy_over_scalar_calls": t_sympy / t_scalar,
            "max_abs_diff_shspec_vs_sympy": float(np.abs(exact - ours).max())}


def main():
    command_line(__doc__)
    out = {"benchmark": "bench_tables", "machine": machine_info(), "goals": GOALS, "cases": []}
    print(out["machine"]["cpu"], "load", out["machine"]["load_average_1_5_15"], flush=True)

    # compile everything once (numba caches to disk only for the library kernels)
    build_table(6, 4)
    peer_fused(6, 4)
    peer_glue(6, 4)
    _bare_recursion(6, 4)

    for lb, la, repeats in CASES:
        case = {"lmax": lb, "lmax_factor": la, "timings": {}}
        ref = build_table(lb, la)
        nvals = ref.values.size
        # correctness of the peers: identical value arrays (same layout) and real coefficients vs real_gaunt
        vf, vg = peer_fused(lb, la), peer_glue(lb, la)
        case["peer_agreement"] = {
            "fused_max_abs_diff_vs_shspec": float(np.abs(vf - ref.values).max()),
            "glue_max_abs_diff_vs_shspec": float(np.abs(vg - ref.values).max()),
            "fused_vs_glue_max_abs_diff": float(np.abs(vf - vg).max()),
            "peer_sample_vs_real_gaunt": sample_check(ref, vf),
            "shspec_sample_vs_real_gaunt": sample_check(ref, ref.values),
        }
        del vf, vg
        for nt in THREADS:
            with threads(nt):
                funcs = {"shspec": lambda: build_table(lb, la), "peer_fused": lambda: peer_fused(lb, la),
                         "peer_glue": lambda: peer_glue(lb, la)}
                load_before = load_average()
                res = side_by_side(funcs, repeats)
                res["load_average_before_after"] = [load_before, load_average()]
                if nt == 2:  # the 2-thread peers must still agree (is the Fortran routine thread safe?)
                    res["peer_fused_2threads_max_abs_diff"] = float(np.abs(peer_fused(lb, la) - ref.values).max())
                for name in funcs:
                    res[name]["values_per_s"] = nvals / res[name]["median_s"]
                best_peer = min(res["peer_fused"]["median_s"], res["peer_glue"]["median_s"])
                res["speedup_vs_best_peer"] = best_peer / res["shspec"]["median_s"]
                res["speedup_vs_peer_fused"] = res["peer_fused"]["median_s"] / res["shspec"]["median_s"]
                res["speedup_vs_peer_glue"] = res["peer_glue"]["median_s"] / res["shspec"]["median_s"]
                case["timings"][f"{nt}_threads"] = res
            print(lb, la, nt, {k: round(v["median_s"], 4) for k, v in res.items() if isinstance(v, dict)},
                  round(res["speedup_vs_best_peer"], 2), flush=True)
        if (lb, la) == (20, 10):
            with threads(1):
                tp = [timed(peer_python, lb, la)[0] for _ in range(3)]
                ts = [timed(build_table, lb, la)[0] for _ in range(3)]
            case["peer_python_1_thread"] = summarize(tp)
            case["peer_python_over_shspec"] = summarize(tp)["median_s"] / summarize(ts)["median_s"]
            case["peer_python_max_abs_diff"] = float(np.abs(peer_python(lb, la) - ref.values).max())
        # sizes
        with tempfile.TemporaryDirectory() as d:
            path = save_table(ref, d)
            case["bytes_on_disk"] = path.stat().st_size
        case["bytes_in_memory"] = int(ref.values.nbytes)
        fresh = GauntTable(lb, la, ref.values)  # ref's plan was built by sample_check: time a fresh one
        case["plan_build_s"] = timed(lambda: fresh.plan)[0]
        del fresh
        case["structure"] = structural_nonzeros(ref)
        with threads(1):
            case["peak_memory_shspec"] = peak_memory(lambda: build_table(lb, la))
            case["peak_memory_peer_glue"] = peak_memory(lambda: peer_glue(lb, la))
        out["cases"].append(case)
        del ref

    # the arithmetic limit: bare numba Schulten–Gordon recursion over every family the (60,30) table needs
    lb, la = 60, 30
    with threads(1):
        r = side_by_side({"bare": lambda: _bare_recursion(lb, la), "full": lambda: build_table(lb, la)}, 3)
        bare, full = r["bare"], r["full"]
        nv, nf, _ = _bare_recursion(lb, la)
    nstored = int(_block_offsets(lb, la)[lb, lb + 1])
    out["bare_recursion_60_30"] = {
        "what": "shspec.gaunt.wigner.family_into over every family build_table(60,30) computes (incl. the (0 0 0) ones), "
                "one core, results discarded; interleaved with the full build",
        "families": int(nf), "threej_values_computed": int(nv), "table_values": nstored,
        "fraction_of_computed_3j_used": nstored / nv,
        "time": bare, "threej_values_per_s_per_core": nv / bare["median_s"],
        "families_per_s_per_core": nf / bare["median_s"],
        "full_build_1_thread": full, "full_build_over_bare": full["median_s"] / bare["median_s"]}
    print("bare", out["bare_recursion_60_30"]["time"]["median_s"], "full", full["median_s"], flush=True)

    with threads(1):
        out["sympy_exact_4_4"] = sympy_case(4)
    print("sympy", out["sympy_exact_4_4"]["sympy_exact_s"], flush=True)

    c = {(x["lmax"], x["lmax_factor"]): x for x in out["cases"]}
    t6030 = c[(60, 30)]["timings"]["1_threads"]
    out["goal_check"] = {
        "(60,30)_one_core_s": t6030["shspec"]["median_s"],
        "(60,30)_one_core_met": t6030["shspec"]["median_s"] <= GOALS["(60,30)_one_core_s"],
        "(60,30)_speedup_vs_best_peer": t6030["speedup_vs_best_peer"],
        "(60,30)_speedup_met": t6030["speedup_vs_best_peer"] >= GOALS["(60,30)_speedup_vs_peer"],
        "(30,15)_one_core_s": c[(30, 15)]["timings"]["1_threads"]["shspec"]["median_s"],
        "(30,15)_one_core_met": c[(30, 15)]["timings"]["1_threads"]["shspec"]["median_s"] <= GOALS["(30,15)_one_core_s"],
    }
    out["machine"]["load_average_end"] = load_average()
    path = write_json("bench_tables.json", out)
    print("wrote", path, out["goal_check"])


if __name__ == "__main__":
    main()
