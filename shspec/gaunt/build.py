"""Building a Gaunt table: every stored family of complex Gaunt coefficients, computed in parallel (numba).

Each family over l3 is the product of the (l1 l2 l3; 0 0 0) family and the family of the order pattern, both by the
3j recursion of :mod:`shspec.gaunt.wigner`; the second stops at La by the forward recursion from its exact first
symbol where that is stable, and falls back to the two-sided family in the upper forbidden region.  The layout
written is the one :mod:`shspec.gaunt.table` reads.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..core.threads import serialized
from .table import GauntTable, _balanced_rows, _block_families, _block_offsets, check_limits
from .wigner import factorial_table, family_into, family_upto_into

__all__ = ["build_table"]

_INV_4PI = 1.0 / (4.0 * math.pi)


@nb.njit(cache=True, nogil=True)
def _fill_row(l1, lmax, lmax_factor, off, values, w0, w, wfull, fh, fl, fe):
    for l2 in range(l1, min(lmax, l1 + lmax_factor) + 1):
        pos = off[l1, l2]
        jmin0 = family_into(l1, l2, 0, 0, w0)[0]
        fa, fmu2, fl3, fcnt = _block_families(l1, l2, lmax_factor)
        for f in range(fa.size):
            cnt = fcnt[f]
            if cnt == 0:
                continue
            # only l3 <= La is stored: the forward recursion runs up to there, or up to where the family (not La)
            # makes it unstable (see shspec.gaunt.wigner), and the values past that point come from the two-sided
            # family.  Which path a value takes depends on its l3 only, so every table holds the same bits for it.
            top = fl3[f] + 2 * (cnt - 1)
            jmin, n, ok = family_upto_into(l1, l2, fa[f], fmu2[f], top, w, fh, fl, fe)
            if not ok:
                family_into(l1, l2, fa[f], fmu2[f], wfull)
            for t in range(cnt):
                l3 = fl3[f] + 2 * t
                pref = math.sqrt((2.0 * l1 + 1.0) * (2.0 * l2 + 1.0) * (2.0 * l3 + 1.0) * _INV_4PI)
                k = l3 - jmin
                values[pos + t] = pref * w0[l3 - jmin0] * (w[k] if k < n else wfull[k])
            pos += cnt


@serialized
@nb.njit(cache=True, parallel=True)
def _fill_rows(rows, lmax, lmax_factor, off, values, fh, fl, fe):
    for r in nb.prange(rows.size):
        w0 = np.empty(2 * lmax + 1)
        w = np.empty(2 * lmax + 1)
        wfull = np.empty(2 * lmax + 1)
        _fill_row(rows[r], lmax, lmax_factor, off, values, w0, w, wfull, fh, fl, fe)




def build_table(lmax: int, lmax_factor: int, *, progress: bool = False) -> "GauntTable":
    """Compute the Gaunt table for the basis band limit ``lmax`` (Lb) and the factor band limit ``lmax_factor`` (La).

    Parameters
    ----------
    lmax : int
        Basis band limit Lb; the basis has (Lb+1)**2 functions.
    lmax_factor : int
        Band limit La of the conformal factor ρ, 0 <= La <= 2·Lb.
    progress : bool
        Show a tqdm progress bar (over degrees l1, weighted by their number of values).

    Returns
    -------
    GauntTable

    Examples
    --------
    >>> from shspec.gaunt import build_table, table_size
    >>> table = build_table(4, 2)          # in memory; get_table caches it
    >>> table.lmax, table.lmax_factor, table_size(4, 2)
    (4, 2, 99)
    """
    lmax, lmax_factor = check_limits(lmax, lmax_factor)
    off = _block_offsets(lmax, lmax_factor)
    total = int(off[lmax, lmax + 1])
    values = np.empty(total)
    rows = _balanced_rows(off, lmax)
    fact = factorial_table(4 * lmax + 2)
    if not progress:
        _fill_rows(rows, lmax, lmax_factor, off, values, *fact)
    else:
        from tqdm.auto import tqdm

        work = np.diff(np.concatenate([[0], off[:, lmax + 1]]))
        nchunks = min(rows.size, 20)
        with tqdm(total=total, unit="val", unit_scale=True, desc=f"Gaunt table ({lmax},{lmax_factor})") as bar:
            for chunk in np.array_split(rows, nchunks):
                _fill_rows(chunk, lmax, lmax_factor, off, values, *fact)
                bar.update(int(work[chunk].sum()))
    return GauntTable(lmax, lmax_factor, values)


