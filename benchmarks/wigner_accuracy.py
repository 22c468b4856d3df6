"""Accuracy and cost of the Wigner 3j families per degree band, against WIGXJPF.

Measures, for random families (j1 j2 j3; −m2−m3 m2 m3) over j1, three implementations:

* ``public``  — :func:`shspec.gaunt.wigner_dd.wigner3j_family` (double-double recursion :func:`family_into_dd`, rounded);
* ``table``   — :func:`shspec.gaunt.wigner.family_into`, the double recursion used by the Gaunt table builder;
* ``pyshtools`` — ``pyshtools.utils.Wigner3j(j2, j3, m1, m2, m3)`` (SHTOOLS' Fortran routine, same family),

against WIGXJPF (pywigxjpf: exact arithmetic, rounded once to double, so it is itself within 1.1e-16 relative).

A symbol belongs to the band (a, b] when its degree max(j1, j2, j3) lies in it; the families are drawn with
max(j2, j3) in the band and only j1 <= b is scored.  WIGXJPF costs ~ms per symbol at l ~ 1000, so large families are
subsampled: every candidate symbol when a family has few, otherwise both ends of the family (deepest in the
classically forbidden regions), the local minima of |w| (the near-nodes, where a recursion's *relative* error is
worst) and uniformly random ones.  Relative errors are taken over symbols whose exact value is a normal double
(|w| >= 1e-290) and nonzero; exact zeros are counted separately (do they come out as exactly 0?).

Writes benchmarks/results/wigner_accuracy.json.  Run:  python benchmarks/wigner_accuracy.py  (~2–4 minutes).
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import platform
import time
from pathlib import Path

from common import command_line, cpu_model

import numba as nb
import numpy as np
import pywigxjpf as wx

from shspec.gaunt.wigner import family_into, family_range
from shspec.gaunt.wigner_dd import family_into_dd, wigner3j_family

try:
    import pyshtools
except ImportError:  # pragma: no cover - pyshtools is a dependency, but keep the benchmark usable without it
    pyshtools = None

# (a, b], number of families, cap on scored symbols per family
BANDS = [
    (0, 10, 4000, 1000),
    (10, 30, 3000, 1000),
    (30, 60, 3000, 1000),
    (60, 100, 1500, 60),
    (100, 200, 1000, 60),
    (200, 500, 500, 50),
    (500, 1000, 300, 40),
]
TINY_NORMAL = 1e-290
BIG_FRACTION = 1e-3  # the "away from nodes" column: symbols with |w| >= 1e-3 × family max
SEED = 20240601
OUT = Path(__file__).resolve().parent / "results" / "wigner_accuracy.json"


def machine():
    cpu = cpu_model()

    def version(name):
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            return None

    return {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "numpy": np.__version__,
        "numba": nb.__version__,
        "pyshtools": version("pyshtools"),
        "pywigxjpf": version("pywigxjpf"),
    }


def draw_family(rng, a, b):
    while True:
        j2 = int(rng.integers(a + 1, b + 1)) if b > 0 else 0
        j3 = int(rng.integers(0, b + 1))
        if rng.random() < 0.5:
            j2, j3 = j3, j2
        if rng.random() < 0.1:
            m2 = m3 = 0
        else:
            m2 = int(rng.integers(-j2, j2 + 1))
            m3 = int(rng.integers(-j3, j3 + 1))
        jmin, jmax = family_range(j2, j3, m2, m3)
        if jmin <= min(jmax, b):  # max(j2, j3) > a by construction
            return j2, j3, m2, m3


def pick_indices(rng, w, n_scored, cap):
    """Indices (into the family) of the symbols to score: all, or ends + near-nodes + random."""
    if n_scored <= cap:
        return np.arange(n_scored)
    v = np.abs(w[:n_scored])
    chosen = {0, n_scored - 1}
    interior = np.arange(1, n_scored - 1)
    minima = interior[(v[interior] < v[interior - 1]) & (v[interior] < v[interior + 1])]
    minima = minima[np.argsort(v[minima])][: cap // 2]
    chosen.update(int(t) for t in minima)
    rest = np.setdiff1d(np.arange(n_scored), np.fromiter(chosen, int))
    chosen.update(int(t) for t in rng.choice(rest, size=min(rest.size, cap - len(chosen)), replace=False))
    return np.array(sorted(chosen))


class Score:
    """Running maxima of the error measures of one method in one band."""

    def __init__(self):
        self.max_rel = 0.0
        self.max_rel_big = 0.0
        self.max_abs_over_max = 0.0
        self.worst = None
        self.worst_abs = None
        self.zeros_not_exact = 0

    def add(self, got, ref, fam_max, family, js):
        nz = np.abs(ref) >= TINY_NORMAL
        zero = ref == 0.0
        self.zeros_not_exact += int(np.count_nonzero(got[zero] != 0.0))
        if np.any(nz):
            rel = np.abs(got[nz] - ref[nz]) / np.abs(ref[nz])
            k = int(np.argmax(rel))
            if rel[k] > self.max_rel:
                self.max_rel = float(rel[k])
                self.worst = [*family, int(js[nz][k])]
            big = np.abs(ref[nz]) >= BIG_FRACTION * fam_max
            if np.any(big):
                self.max_rel_big = max(self.max_rel_big, float(rel[big].max()))
        err = np.abs(got - ref) / fam_max
        k = int(np.argmax(err))
        if err[k] > self.max_abs_over_max:
            self.max_abs_over_max = float(err[k])
            self.worst_abs = [*family, int(js[k])]

    def as_dict(self):
        return {
            "max_rel": self.max_rel,
            "max_rel_away_from_nodes": self.max_rel_big,
            "max_abs_over_family_max": self.max_abs_over_max,
            "worst_rel_symbol_j2_j3_m2_m3_j1": self.worst,
            "worst_abs_symbol_j2_j3_m2_m3_j1": self.worst_abs,
            "exact_zeros_not_returned_as_zero": self.zeros_not_exact,
        }


@nb.njit(cache=True)
def _time_double(fams, out, reps):
    acc = 0.0
    for _ in range(reps):
        for i in range(fams.shape[0]):
            family_into(fams[i, 0], fams[i, 1], fams[i, 2], fams[i, 3], out)
            acc += out[0]
    return acc


@nb.njit(cache=True)
def _time_dd(fams, hi, lo, reps):
    acc = 0.0
    for _ in range(reps):
        for i in range(fams.shape[0]):
            family_into_dd(fams[i, 0], fams[i, 1], fams[i, 2], fams[i, 3], hi, lo)
            acc += hi[0]
    return acc


def time_per_family(fams):
    """µs per family (best of 3) of the double and the double-double kernel, and of the pyshtools call."""
    fams = np.asarray(fams, dtype=np.int64)
    nmax = int((fams[:, 0] + fams[:, 1]).max()) + 2
    out, hi, lo = np.empty(nmax), np.empty(nmax), np.empty(nmax)
    _time_double(fams[:1], out, 1)
    _time_dd(fams[:1], hi, lo, 1)
    reps = max(1, int(20000 // (len(fams) * max(1.0, nmax / 20))))
    res = {}
    for name, fn in (("table", lambda: _time_double(fams, out, reps)), ("public", lambda: _time_dd(fams, hi, lo, reps))):
        best = np.inf
        for _ in range(3):
            t = time.perf_counter()
            fn()
            best = min(best, time.perf_counter() - t)
        res[name] = 1e6 * best / (reps * len(fams))
    if pyshtools is not None:
        best = np.inf
        for _ in range(3):
            t = time.perf_counter()
            for j2, j3, m2, m3 in fams:
                pyshtools.utils.Wigner3j(int(j2), int(j3), int(-(m2 + m3)), int(m2), int(m3))
            best = min(best, time.perf_counter() - t)
        res["pyshtools"] = 1e6 * best / len(fams)
    res["public_over_table"] = res["public"] / res["table"]
    return res


def run_band(rng, a, b, n_fam, cap):
    methods = ["public", "table"] + (["pyshtools"] if pyshtools is not None else [])
    scores = {m: Score() for m in methods}
    n_sym = n_zero = 0
    fams = []
    t0 = time.perf_counter()
    for _ in range(n_fam):
        j2, j3, m2, m3 = draw_family(rng, a, b)
        fams.append((j2, j3, m2, m3))
        m1 = -(m2 + m3)
        jmin, w_pub = wigner3j_family(j2, j3, m2, m3)
        n = w_pub.size
        w_tab = np.empty(n)
        family_into(j2, j3, m2, m3, w_tab)
        got = {"public": w_pub, "table": w_tab}
        if pyshtools is not None:
            w_sh, jmin_sh, _ = pyshtools.utils.Wigner3j(j2, j3, m1, m2, m3)
            assert jmin_sh == jmin, (j2, j3, m2, m3, jmin_sh, jmin)
            got["pyshtools"] = np.asarray(w_sh[:n], dtype=float)
        fam_max = float(np.max(np.abs(w_pub)))  # accurate to ~1e-16: the public path, checked below
        n_scored = min(n, b - jmin + 1)
        idx = pick_indices(rng, w_pub, n_scored, cap)
        js = jmin + idx
        ref = np.array([wx.wig3jj(2 * int(j), 2 * j2, 2 * j3, 2 * m1, 2 * m2, 2 * m3) for j in js])
        n_sym += idx.size
        n_zero += int(np.count_nonzero(ref == 0.0))
        for m in methods:
            scores[m].add(got[m][idx], ref, fam_max, (j2, j3, m2, m3), js)
    seconds = time.perf_counter() - t0
    return {
        "band": [a, b],
        "families": n_fam,
        "symbols_scored": n_sym,
        "exact_zeros_scored": n_zero,
        "subsampled": cap < 2 * b + 1,
        "seconds": seconds,
        "error": {m: s.as_dict() for m, s in scores.items()},
        "us_per_family": time_per_family(fams),
    }


def main():
    command_line(__doc__)
    wx.wig_table_init(2 * 2000 + 8, 3)
    wx.wig_temp_init(2 * 2000 + 8)
    rng = np.random.default_rng(SEED)
    wigner3j_family(3, 4, 1, -1)  # compile / load the numba cache outside the timings
    result = {
        "what": "max errors of Wigner 3j families against WIGXJPF per degree band max(j1, j2, j3) in (a, b]",
        "relative_error": "|w - w_exact| / |w_exact| over symbols with |w_exact| >= 1e-290 (nonzero, normal)",
        "away_from_nodes": f"the same over symbols with |w_exact| >= {BIG_FRACTION:g} x max|w| of the family",
        "abs_error": "|w - w_exact| / max|w| of the family",
        "sampling": "families with max(j2,j3) in the band, j1 <= b; when a family has more than `cap` such "
                    "symbols: both ends, the smallest local minima of |w| (near-nodes) and random ones",
        "seed": SEED,
        "machine": machine(),
        "bands": [],
    }
    for a, b, n_fam, cap in BANDS:
        band = run_band(rng, a, b, n_fam, cap)
        result["bands"].append(band)
        e = band["error"]
        print(f"l in ({a:4d},{b:4d}]  {band['symbols_scored']:6d} symbols  "
              + "  ".join(f"{m}: rel {e[m]['max_rel']:.2e} abs {e[m]['max_abs_over_family_max']:.2e}" for m in e)
              + f"  | µs/family table {band['us_per_family']['table']:.2f} public {band['us_per_family']['public']:.2f}"
              + f"  ({band['seconds']:.0f} s)", flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
