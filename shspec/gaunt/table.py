"""Gaunt tables: every real Gaunt coefficient G_ijk = ∫ Y_i Y_j Y_k that the Galerkin mass matrix needs.

For a basis band limit Lb (indices i, j) and a factor band limit La (index k) the table stores, for each pair of
degrees l1 <= l2 <= min(Lb, l1 + La) and each pair of absolute orders (a, b) (with a <= b when l1 = l2), one or two
*families* over l3: the complex Gaunt coefficients of the order pattern μ = (a, b, −a−b) ("sum") and, when a, b > 0,
μ = (a, −b, b−a) ("difference"), for l3 = l3min, l3min + 2, …, min(l1 + l2, La).  Each stored value serves up to four
real coefficients (the signs of m1 and m2; see :mod:`shspec.gaunt.real_gaunt`), and only l1 <= l2 is stored, so a table holds
about 1/8 of the structural nonzeros of G: 1.4e8 values for (Lb, La) = (100, 50) instead of 1.1e9.

The layout is implicit: families follow a fixed loop order, so a table is fully described by (Lb, La) and its value
array, and the offsets are recomputed on load.  Assembly, the gradient contraction and the Jacobian walk a *plan*:
one entry per real pair (i <= j) and order m3, giving (i, j, m3, l3min, count, offset, factor); entries are grouped
by the degree of i so that threads write disjoint rows of the upper triangle of M.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba as nb
import numpy as np

from ..core.checks import real_array
from ..errors import BandLimitError, InvalidArgumentError
from ..core.resources import Need
from ..core.threads import REDUCTION_CHUNKS, serialized
from ..sphere.harmonics import check_degree, ncoeffs
from .real_gaunt import order_factor

__all__ = ["GauntTable", "table_size", "check_limits", "plan_bytes", "PLAN_ENTRY_BYTES", "MAX_BASIS_DEGREE",
           "table_need"]


#: Largest basis band limit Lb of a table and of a forward solve (the table and the dense N×N matrices,
#: N = (Lb+1)², must fit in memory: Lb = 400 already needs ~200 GiB).  One constant for the library and the CLI.
MAX_BASIS_DEGREE = 400


def check_limits(lmax, lmax_factor) -> tuple[int, int]:
    """Validate a pair of band limits (Lb for the basis, La for ρ); La may not exceed 2·Lb (G would vanish)."""
    lmax = check_degree(lmax, "lmax (basis band limit Lb)", maximum=MAX_BASIS_DEGREE)
    lmax_factor = check_degree(lmax_factor, "lmax_factor (band limit La of rho)", maximum=MAX_BASIS_DEGREE)
    if lmax_factor > 2 * lmax:
        raise BandLimitError(
            f"lmax_factor = {lmax_factor} > 2*lmax = {2 * lmax}: degrees above 2*Lb cannot couple two basis "
            "functions (the Gaunt coefficients vanish), so such a table would hold nothing more"
        )
    return lmax, lmax_factor


# ---------------------------------------------------------------------------------------------------------------
# layout


@nb.njit(cache=True, nogil=True)
def _family_count(l1, l2, c, lmax_factor):
    l3min = max(l2 - l1, c)
    if (l1 + l2 + l3min) % 2 == 1:
        l3min += 1
    l3max = min(l1 + l2, lmax_factor)
    if l3min > l3max:
        return l3min, 0
    return l3min, (l3max - l3min) // 2 + 1


@nb.njit(cache=True, nogil=True)
def _block_families(l1, l2, lmax_factor):
    """The families of the (l1, l2) block in storage order: arrays a, μ2, l3min, count (count may be 0).

    The order (a, then b, then sum before difference) does not depend on La, so the same family has the same
    rank in the blocks of two tables with different La.
    """
    n = 0
    for a in range(l1 + 1):
        for b in range(a if l1 == l2 else 0, l2 + 1):
            n += 2 if a > 0 and b > 0 else 1
    fa = np.empty(n, dtype=np.int64)
    fmu2 = np.empty(n, dtype=np.int64)
    fl3 = np.empty(n, dtype=np.int64)
    fcnt = np.empty(n, dtype=np.int64)
    f = 0
    for a in range(l1 + 1):
        for b in range(a if l1 == l2 else 0, l2 + 1):
            for choice in range(2 if a > 0 and b > 0 else 1):
                mu2 = b if choice == 0 else -b
                fa[f] = a
                fmu2[f] = mu2
                fl3[f], fcnt[f] = _family_count(l1, l2, abs(a + mu2), lmax_factor)
                f += 1
    return fa, fmu2, fl3, fcnt


@nb.njit(cache=True)
def _block_offsets(lmax, lmax_factor):
    """Offsets (Lb+1, Lb+2) of the (l1, l2) blocks in the value array; row l1 ends at [l1, Lb+1]."""
    off = np.zeros((lmax + 1, lmax + 2), dtype=np.int64)
    pos = 0
    for l1 in range(lmax + 1):
        for l2 in range(l1, min(lmax, l1 + lmax_factor) + 1):
            off[l1, l2] = pos
            pos += _block_families(l1, l2, lmax_factor)[3].sum()
        off[l1, lmax + 1] = pos
    return off


def table_size(lmax: int, lmax_factor: int) -> int:
    """Number of stored values of the table (Lb, La).

    Examples
    --------
    >>> from shspec.gaunt import table_size
    >>> table_size(4, 2)                   # nonzero real Gaunt coefficients of the table (Lb, La)
    99
    """
    lmax, lmax_factor = check_limits(lmax, lmax_factor)
    return int(_block_offsets(lmax, lmax_factor)[lmax, lmax + 1])


def _balanced_rows(off: np.ndarray, lmax: int) -> np.ndarray:
    """Degrees l1 ordered so that consecutive chunks of a parallel loop get similar amounts of work."""
    work = np.diff(np.concatenate([[0], off[:, lmax + 1]]))
    return np.argsort(-work, kind="stable").astype(np.int64)


# ---------------------------------------------------------------------------------------------------------------
# the plan: one entry per real pair (i <= j) and order m3


@nb.njit(cache=True)
def _plan_row(l1, lmax, lmax_factor, off, fill, ei, ej, em3, el3, ecnt, eoff, efac, start):
    """Count (fill=False) or write (fill=True) the plan entries of row degree l1 from position ``start``."""
    n = start
    for l2 in range(l1, min(lmax, l1 + lmax_factor) + 1):
        pos = off[l1, l2]
        fa, fmu2, fl3, fcnt = _block_families(l1, l2, lmax_factor)
        for f in range(fa.size):
            cnt = fcnt[f]
            if cnt == 0:
                continue
            a = fa[f]
            b = abs(fmu2[f])
            mu3 = -(a + fmu2[f])
            c = abs(mu3)
            for s1 in range(2 if a > 0 else 1):
                m1 = a if s1 == 0 else -a
                for s2 in range(2 if b > 0 else 1):
                    m2 = b if s2 == 0 else -b
                    for s3 in range(2 if c > 0 else 1):
                        m3 = c if s3 == 0 else -c
                        fac = order_factor(m1, m2, m3, a, fmu2[f], mu3)
                        if abs(fac) < 0.25:
                            continue
                        i = l1 * l1 + l1 + m1
                        j = l2 * l2 + l2 + m2
                        if i > j:
                            if l1 == l2 and a == b:
                                continue  # its mirror (j, i) is in this same family
                            i, j = j, i
                        if fill:
                            ei[n] = i
                            ej[n] = j
                            em3[n] = m3
                            el3[n] = fl3[f]
                            ecnt[n] = cnt
                            eoff[n] = pos
                            efac[n] = fac
                        n += 1
            pos += cnt
    return n


@nb.njit(cache=True)
def _make_plan(lmax, lmax_factor, off):
    starts = np.zeros(lmax + 2, dtype=np.int64)
    dummy_i = np.empty(0, dtype=np.int32)
    dummy_f = np.empty(0)
    dummy_o = np.empty(0, dtype=np.int64)
    for l1 in range(lmax + 1):
        starts[l1 + 1] = _plan_row(l1, lmax, lmax_factor, off, False, dummy_i, dummy_i, dummy_i, dummy_i, dummy_i,
                                   dummy_o, dummy_f, starts[l1])
    n = starts[lmax + 1]
    ei = np.empty(n, dtype=np.int32)
    ej = np.empty(n, dtype=np.int32)
    em3 = np.empty(n, dtype=np.int32)
    el3 = np.empty(n, dtype=np.int32)
    ecnt = np.empty(n, dtype=np.int32)
    eoff = np.empty(n, dtype=np.int64)
    efac = np.empty(n)
    for l1 in range(lmax + 1):
        _plan_row(l1, lmax, lmax_factor, off, True, ei, ej, em3, el3, ecnt, eoff, efac, starts[l1])
    return starts, ei, ej, em3, el3, ecnt, eoff, efac


@dataclass(frozen=True)
class _Plan:
    starts: np.ndarray  # (Lb+2,) int64, entries of row degree l1 are starts[l1]:starts[l1+1]
    i: np.ndarray  # (E,) int32
    j: np.ndarray  # (E,) int32, i <= j
    m3: np.ndarray  # (E,) int32
    l3min: np.ndarray  # (E,) int32
    count: np.ndarray  # (E,) int32
    offset: np.ndarray  # (E,) int64 into the value array
    factor: np.ndarray  # (E,) float64

    @property
    def arrays(self):
        return (self.starts, self.i, self.j, self.m3, self.l3min, self.count, self.offset, self.factor)


# ---------------------------------------------------------------------------------------------------------------
# kernels


@serialized
@nb.njit(cache=True, parallel=True)
def _assemble_upper(rows, starts, ei, ej, em3, el3, ecnt, eoff, efac, values, coef, out):
    for r in nb.prange(rows.size):
        l1 = rows[r]
        for e in range(starts[l1], starts[l1 + 1]):
            m3 = em3[e]
            l3 = el3[e]
            base = eoff[e]
            acc = 0.0
            for t in range(ecnt[e]):
                acc += values[base + t] * coef[l3 * l3 + l3 + m3]
                l3 += 2
            out[ei[e], ej[e]] += efac[e] * acc


@serialized
@nb.njit(cache=True, parallel=True)
def _contract(rows, starts, ei, ej, em3, el3, ecnt, eoff, efac, values, bmat, nfactor, nchunks):
    # one partial sum per chunk of rows (chunks interleave the rows, which come sorted by work, to balance them)
    part = np.zeros((nchunks, nfactor))
    for c in nb.prange(nchunks):
        g = part[c]
        for r in range(c, rows.size, nchunks):
            l1 = rows[r]
            for e in range(starts[l1], starts[l1 + 1]):
                i = ei[e]
                j = ej[e]
                bij = bmat[i, j] if i == j else bmat[i, j] + bmat[j, i]
                w = efac[e] * bij
                m3 = em3[e]
                l3 = el3[e]
                base = eoff[e]
                for t in range(ecnt[e]):
                    g[l3 * l3 + l3 + m3] += w * values[base + t]
                    l3 += 2
    return part.sum(axis=0)


@serialized
@nb.njit(cache=True, parallel=True)
def _quad_forms(rows, starts, ei, ej, em3, el3, ecnt, eoff, efac, values, vecs, nfactor, nchunks):
    # out[k, q] = v_qᵀ G_k v_q for each column q of vecs; rows of vecs are basis indices
    nq = vecs.shape[1]
    part = np.zeros((nchunks, nfactor, nq))
    for c in nb.prange(nchunks):
        p = np.empty(nq)
        for r in range(c, rows.size, nchunks):
            l1 = rows[r]
            for e in range(starts[l1], starts[l1 + 1]):
                i = ei[e]
                j = ej[e]
                w = efac[e] if i == j else 2.0 * efac[e]
                for q in range(nq):
                    p[q] = w * vecs[i, q] * vecs[j, q]
                m3 = em3[e]
                l3 = el3[e]
                base = eoff[e]
                for t in range(ecnt[e]):
                    row = part[c, l3 * l3 + l3 + m3]
                    v = values[base + t]
                    for q in range(nq):
                        row[q] += v * p[q]
                    l3 += 2
    return part.sum(axis=0)


@serialized
@nb.njit(cache=True, parallel=True)
def _mirror_upper(out):
    # copy the strict upper triangle into the lower one; each thread writes whole rows
    n = out.shape[0]
    for i in nb.prange(n):
        for j in range(i):
            out[i, j] = out[j, i]


@serialized
@nb.njit(cache=True, parallel=True)
def _restrict(rows, lmax, lmax_factor, off_small, big_factor, off_big, big_values, out):
    for r in nb.prange(rows.size):
        l1 = rows[r]
        for l2 in range(l1, min(lmax, l1 + lmax_factor) + 1):
            ps = off_small[l1, l2]
            pb = off_big[l1, l2]
            n_small = _block_families(l1, l2, lmax_factor)[3]
            n_big = _block_families(l1, l2, big_factor)[3]
            for f in range(n_small.size):
                # a family of the small table is the start of the same family of the big one
                for t in range(n_small[f]):
                    out[ps + t] = big_values[pb + t]
                ps += n_small[f]
                pb += n_big[f]


# ---------------------------------------------------------------------------------------------------------------


@dataclass(eq=False)
class GauntTable:
    """Real Gaunt coefficients for a basis band limit Lb and a factor band limit La.

    Attributes
    ----------
    lmax : int
        Lb: the basis holds the (Lb+1)**2 real harmonics of degree <= Lb (indices i, j).
    lmax_factor : int
        La: the conformal factor holds (La+1)**2 coefficients (index k).
    values : (table_size(Lb, La),) float64 array
        The stored families (see the module docstring for the layout).
    path : pathlib.Path or None
        File the table was loaded from, if any.
    metadata : dict
        Provenance (creation time, library version, checksum) when loaded from or saved to a file.

    Examples
    --------
    >>> from shspec import get_table
    >>> table = get_table(4, 2)            # built once, then read from the cache
    >>> type(table).__name__, table.lmax, table.lmax_factor
    ('GauntTable', 4, 2)
    """

    lmax: int
    lmax_factor: int
    values: np.ndarray
    path: object = None
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        self.lmax, self.lmax_factor = check_limits(self.lmax, self.lmax_factor)
        self.offsets = _block_offsets(self.lmax, self.lmax_factor)
        expected = int(self.offsets[self.lmax, self.lmax + 1])
        self.values = real_array(self.values, "a Gaunt table's values")
        if self.values.shape != (expected,):
            raise InvalidArgumentError(
                f"a ({self.lmax},{self.lmax_factor}) Gaunt table holds {expected} values, got shape {self.values.shape}"
            )
        self._plan = None
        self._rows = _balanced_rows(self.offsets, self.lmax)
        # restrictions are kept: a solver asking a larger cached table for the same smaller limits again (every
        # call of shspec.spectrum, every stage of a fit) then reuses the values and the plan built for them
        self._restricted: dict[tuple[int, int], GauntTable] = {}

    def __repr__(self) -> str:
        return (f"GauntTable(lmax={self.lmax}, lmax_factor={self.lmax_factor}, values={self.values.size}, "
                f"{self.values.nbytes / 2**20:.1f} MiB)")

    @property
    def nbasis(self) -> int:
        """Number of basis functions N = (Lb+1)**2."""
        return ncoeffs(self.lmax)

    @property
    def nfactor(self) -> int:
        """Number of factor coefficients (La+1)**2."""
        return ncoeffs(self.lmax_factor)

    @property
    def plan(self) -> _Plan:
        """The entry list the kernels walk; built on first use (about 30 bytes per real (i<=j, m3) pair)."""
        if self._plan is None:
            self._plan = _Plan(*_make_plan(self.lmax, self.lmax_factor, self.offsets))
        return self._plan

    def covers(self, lmax: int, lmax_factor: int) -> bool:
        """True when this table can serve the limits (Lb, La), i.e. holds at least as much."""
        return lmax <= self.lmax and lmax_factor <= self.lmax_factor

    def restrict(self, lmax: int, lmax_factor: int, *, keep: bool = True) -> "GauntTable":
        """The table for smaller limits (Lb, La), extracted from this one without recomputation; ``keep``: remember
        it, so that asking again returns the same table (False for one-off probes)."""
        lmax, lmax_factor = check_limits(lmax, lmax_factor)
        if not self.covers(lmax, lmax_factor):
            raise BandLimitError(
                f"a ({self.lmax},{self.lmax_factor}) table cannot serve ({lmax},{lmax_factor})")
        if (lmax, lmax_factor) == (self.lmax, self.lmax_factor):
            return self
        if (lmax, lmax_factor) in self._restricted:
            return self._restricted[(lmax, lmax_factor)]
        off = _block_offsets(lmax, lmax_factor)
        out = np.empty(int(off[lmax, lmax + 1]))
        _restrict(_balanced_rows(off, lmax), lmax, lmax_factor, off, self.lmax_factor, self.offsets, self.values, out)
        out.setflags(write=self.values.flags.writeable)
        table = GauntTable(lmax, lmax_factor, out, metadata={"restricted_from": [self.lmax, self.lmax_factor]})
        if keep:
            self._restricted[(lmax, lmax_factor)] = table
        return table

    def mass_matrix(self, coef: np.ndarray, *, symmetrize: bool = True) -> np.ndarray:
        """M_ij = Σ_k a_k G_ijk for factor coefficients a.

        Parameters
        ----------
        coef : (nfactor,) float array
            Coefficients a_k of ρ in the flat order, up to degree La.
        symmetrize : bool
            When False only the upper triangle (i <= j) is filled, which is all LAPACK's symmetric solvers read.

        Returns
        -------
        (nbasis, nbasis) float array
        """
        coef = self._check_coef(coef)
        out = np.zeros((self.nbasis, self.nbasis))
        _assemble_upper(self._rows, *self.plan.arrays, self.values, coef, out)
        if symmetrize:
            _mirror_upper(out)
        return out

    def contract(self, bmat: np.ndarray) -> np.ndarray:
        """g_k = Σ_ij G_ijk B_ij for a square (nbasis, nbasis) array B; returns (nfactor,)."""
        bmat = np.asarray(bmat, dtype=float)
        if bmat.shape != (self.nbasis, self.nbasis):
            raise InvalidArgumentError(f"B must have shape {(self.nbasis, self.nbasis)}, got {bmat.shape}")
        return _contract(self._rows, *self.plan.arrays, self.values, bmat, self.nfactor, REDUCTION_CHUNKS)

    def quadratic_forms(self, vecs: np.ndarray) -> np.ndarray:
        """Q[k, q] = v_qᵀ G_k v_q for the columns v_q of ``vecs`` (nbasis, nq); returns (nfactor, nq)."""
        vecs = np.asarray(vecs, dtype=float)
        if vecs.ndim != 2 or vecs.shape[0] != self.nbasis:
            raise InvalidArgumentError(f"vectors must have shape ({self.nbasis}, q), got {vecs.shape}")
        return _quad_forms(self._rows, *self.plan.arrays, self.values, np.ascontiguousarray(vecs), self.nfactor,
                           REDUCTION_CHUNKS)

    def _check_coef(self, coef) -> np.ndarray:
        coef = np.asarray(coef, dtype=float)
        if coef.shape != (self.nfactor,):
            raise InvalidArgumentError(
                f"factor coefficients must have shape ({self.nfactor},) for La = {self.lmax_factor}, got {coef.shape}")
        if not np.all(np.isfinite(coef)):
            raise InvalidArgumentError("factor coefficients contain NaN or inf")
        return coef



#: Bytes per plan entry: i, j, m3, l3min, count (int32), offset (int64), factor (float64).
PLAN_ENTRY_BYTES = 5 * 4 + 8 + 8


def plan_bytes(lmax: int, lmax_factor: int) -> int:
    """An upper bound of the memory of the assembly plan of the table (Lb, La), without building it.

    A real pair (i <= j) couples through at most two orders m3 (±(|m_i| + |m_j|) and ±(|m_i| − |m_j|), one sign
    each), and only pairs with |l_i − l_j| <= La have any l3, so the plan has at most
    2 · #{(i <= j) : |l_i − l_j| <= La} entries (the true count is 90-95 % of it at La = Lb = 120).
    """
    lmax, lmax_factor = check_limits(lmax, lmax_factor)
    l = np.arange(lmax + 1)
    w = 2 * l + 1
    close = np.abs(l[:, None] - l[None, :]) <= lmax_factor
    pairs = (np.sum(np.outer(w, w) * close) + np.sum(w)) // 2  # ordered pairs i <= j
    return PLAN_ENTRY_BYTES * 2 * int(pairs)


#: Bytes of a cached table's file besides its values: the HDF5 header and the attributes (6.1 KiB measured at (8,8)
#: and (16,16)).
FILE_OVERHEAD = 8192


def table_need(lmax: int, lmax_factor: int) -> Need:
    """Building and caching the table (Lb, La): its values in memory, and its file on disk."""
    nbytes = 8 * table_size(lmax, lmax_factor)
    return Need(f"the Gaunt table ({lmax},{lmax_factor})", nbytes, nbytes + FILE_OVERHEAD)

