"""The first k eigenpairs of L v = λ M v by shift-invert block Lanczos on a sparse LU factorization.

Method
------
With a shift σ, the operator OP = (L − σM)⁻¹ M is self-adjoint in the M inner product and its eigenvalues of
largest modulus, μ = 1/(λ − σ), belong to the λ closest to σ.  σ is put inside the wanted interval, at 0.45 times
Weyl's estimate 4πk/A of λ_k: the wanted eigenvalues are then all within about σ of it and the unwanted ones
further away, which separates them far better than a shift below 0 (on icospheres with k = 100, 25 % fewer
vectors).  L − σM is then indefinite, which LU does not mind.  A block Krylov basis Q
(M-orthonormal, full re-orthogonalization done twice) is grown with blocks of b vectors; the projected matrix
T = Qᵀ M OP Q gives Ritz values whose residuals ‖OP y − μ y‖_M are read off T at no cost.  Once enough Ritz pairs
have converged, a last Rayleigh–Ritz step with L itself on the converged vectors gives the eigenvalues (as Rayleigh
quotients) and M-orthonormal eigenvectors.  Blocks make the triangular solves and the re-orthogonalization
matrix-matrix operations, and a block of b vectors finds multiplicities up to b directly, where single-vector
Lanczos (ARPACK) only finds repeated eigenvalues through rounding errors.

The factorization is SciPy's SuperLU (:func:`scipy.sparse.linalg.splu`), the only one required.

Multiplets
----------
The solver keeps iterating until the (k+1)-th eigenvalue has converged too, so that it can tell whether the k-th
one belongs to a group that continues past k.  Eigenvalues within ``multiplet_rtol`` times the largest computed
one of each other count as one degenerate group (the largest of λ₀..λ_k, not of every computed eigenvalue: one
sliver face adds a huge eigenvalue that would merge everything).  A block of b vectors sees at most b copies of a repeated
eigenvalue at first; when a group of b or more shows up, b random vectors are added to the basis and the result is
accepted only once the count of eigenvalues up to the cut stays the same.  :func:`eigenpairs` with ``whole_multiplets=True`` (the default of :func:`mesh_spectrum`)
returns more than k pairs when the k-th eigenvalue's group continues past k, so that no member is dropped; with
``whole_multiplets=False`` (what :class:`~shspec.mesh.model.MeshModel` needs: its interface returns exactly k) it
returns exactly k and emits a ``RuntimeWarning`` when that cuts a group.  Clusters
split by more than ``multiplet_rtol`` (e.g. the l(l+1) multiplets of an icosphere, split by ~1e-3 by the
icosahedral symmetry) are not groups in this sense.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..core.checks import check_int, check_options
from ..errors import ConvergenceError, InvalidArgumentError, MeshError, warn
from ..spectral_model import Spectrum
from ..core.resources import human_bytes
from ..core.threads import reproducible_call
from .cotan import cotan_stiffness, mass_matrix
from .progress import announce, bar, lanczos_estimate, shown
from .triangle_mesh import TriangleMesh
from .validate import ZERO_AREA_RTOL, checked_face_areas

__all__ = ["EigenOptions", "eigenpairs", "mesh_spectrum"]


@dataclass(frozen=True)
class EigenOptions:
    """Options of :func:`eigenpairs`.

    Attributes
    ----------
    sigma : float or None
        Shift σ (units 1/area).  None: σ = 0.45·4πk/A with A = 1ᵀM1 the area (module notes).  Any σ works: the
        solver collects the converged eigenvalues nearest σ until they cover [0, λ_k] and one more.
    tol : float
        Convergence when ‖OP y − μ y‖_M ≤ tol·μ for each wanted Ritz pair.  The eigenvalues, being Rayleigh
        quotients, are then accurate to about tol² relative (tests measure ~1e-13).
    block_size : int
        Block size b.  Multiplicities up to b are found directly, larger ones through the random directions that
        replace exhausted ones; small blocks converge in fewer solves (8 was fastest for k = 100 on icospheres).
    multiplet_rtol : float
        Neighbouring eigenvalues closer than multiplet_rtol × max(|λ₀|, …, |λ_k|) form one degenerate group; being
        relative to the wanted eigenvalues, not to the whole computed spectrum, a sliver face's huge eigenvalue does
        not change the groups, and the zero eigenvalues of several components still group.
    max_dim : int or None
        Largest Krylov basis before :class:`ConvergenceError`; None: min(n, 4k + 50b) (k = 100 needs ~350;
        exact multiplicities above b need more).
    dense_below : int
        Meshes with fewer vertices are solved densely (:func:`scipy.linalg.eigh`), which is faster there; so is
        any k whose Krylov basis is expected to fill the space (2.8k + 60 ≥ n).
    seed : int
        Seed of the random start block, for reproducible eigenvectors.

    Examples
    --------
    >>> from shspec.mesh import EigenOptions, icosphere, mesh_spectrum
    >>> options = EigenOptions(tol=1e-10)
    >>> mesh_spectrum(icosphere(2), 4, options=options).eigenvalues.size
    4
    """

    sigma: float | None = None
    tol: float = 1e-8
    block_size: int = 8
    multiplet_rtol: float = 1e-8
    max_dim: int | None = None
    dense_below: int = 800
    seed: int = 0

    def __post_init__(self):
        if self.sigma is not None and not np.isfinite(self.sigma):
            raise InvalidArgumentError(f"sigma must be finite, got {self.sigma}")
        if not (0 < self.tol < 1):
            raise InvalidArgumentError(f"tol must be in (0, 1), got {self.tol}")
        if not (isinstance(self.block_size, (int, np.integer)) and self.block_size >= 1):
            raise InvalidArgumentError(f"block_size must be a positive integer, got {self.block_size!r}")
        if not (0 <= self.multiplet_rtol < 1):
            raise InvalidArgumentError(f"multiplet_rtol must be in [0, 1), got {self.multiplet_rtol}")
        if self.max_dim is not None and not (isinstance(self.max_dim, (int, np.integer)) and self.max_dim >= 2):
            raise InvalidArgumentError(f"max_dim must be an integer >= 2, got {self.max_dim!r}")
        if not isinstance(self.dense_below, (int, np.integer)) or self.dense_below < 0:
            raise InvalidArgumentError(f"dense_below must be a non-negative integer, got {self.dense_below!r}")


def _check_pencil(L, M, k):
    if not (sp.issparse(L) and sp.issparse(M)):
        raise InvalidArgumentError("L and M must be scipy.sparse matrices")
    n = L.shape[0]
    if L.shape != (n, n) or M.shape != (n, n):
        raise InvalidArgumentError(f"L and M must be square and of one size, got {L.shape} and {M.shape}")
    k = check_int(k, "k", minimum=None)
    if not 1 <= k < n:
        raise InvalidArgumentError(f"k must be in 1..{n - 1} for {n} vertices, got {k}")
    return n, int(k)


def _scale(lam: np.ndarray, k: int) -> float:
    """The size of the wanted part of a spectrum, max |λ_0..λ_k|, that degenerate-group tolerances are relative to.

    Not the largest computed eigenvalue: one sliver face gives a mesh an eigenvalue many orders of magnitude above
    the rest, which would merge every wanted eigenvalue into one group.
    """
    return max(float(np.abs(lam[:k + 1]).max()) if lam.size else 0.0, np.finfo(float).tiny)


def _group_end(lam: np.ndarray, k: int, rtol: float) -> int:
    """Smallest j ≥ k such that lam[j] is not within rtol·max|lam[:k+1]| of lam[k-1] (len(lam) if all are)."""
    tol = rtol * _scale(lam, k)
    j = k
    while j < lam.size and abs(lam[j] - lam[k - 1]) <= tol:
        j += 1
    return j


def _largest_group(lam: np.ndarray, rtol: float) -> int:
    """Size of the largest run of ascending eigenvalues whose neighbours are within rtol·max|lam| of each other."""
    if lam.size == 0:
        return 0
    tol = rtol * _scale(lam, lam.size)
    bounds = np.concatenate([[0], np.flatnonzero(np.diff(lam) > tol) + 1, [lam.size]])
    return int(np.diff(bounds).max())


def _finish(L, M, Y, k, rtol, whole):
    """Rayleigh–Ritz with L on the columns of Y; returns the first k pairs, or the whole cut group if asked."""
    H = Y.T @ (L @ Y)
    G = Y.T @ (M @ Y)
    lam, S = sla.eigh(0.5 * (H + H.T), 0.5 * (G + G.T))
    return _select(lam, Y @ S, k, rtol, whole)


def _select(lam, V, k, rtol, whole):
    """The first k pairs, completed to the end of the k-th one's degenerate group if ``whole``, else with a warning."""
    # λ₀ of a semi-definite L is 0 up to rounding (~1e-15 relative); anything clearly below is a broken pencil
    if lam.size and lam[0] < -1e-8 * _scale(lam, k):
        raise InvalidArgumentError(
            f"the pencil has a negative eigenvalue {lam[0]:.6g}: L is not positive semi-definite or M is not positive "
            "definite (a mesh with degenerate faces? see shspec.mesh.validate_mesh)")
    end = _group_end(lam, k, rtol)
    if end > k and not whole:
        warn(f"eigenvalues {k - 1}..{end - 1} form one degenerate group (within {rtol:g}); only the first {k} are "
             "returned, so the group is cut and its members' eigenvectors are arbitrary", RuntimeWarning)
    end = end if whole else k
    if end == lam.size and whole and end > k and lam.size < V.shape[0]:
        # The group fills every computed pair: the caller must ask for more, we cannot tell where it ends (when
        # every pair of the pencil was computed, it ends there: the group is whole).
        raise ConvergenceError(f"eigenvalues {k - 1}..{end - 1} form one degenerate group reaching the end of the "
                               "computed pairs; ask for more eigenpairs")
    return Spectrum(lam[:end].copy(), V[:, :end].copy())


def eigenpairs(L, M, k: int, options: EigenOptions | None = None, *, whole_multiplets: bool = False) -> Spectrum:
    """First k eigenpairs of the symmetric pencil L v = λ M v (L semi-definite, M definite).

    Parameters
    ----------
    L : (n, n) sparse matrix
        Stiffness, symmetric positive semi-definite (e.g. :func:`~shspec.mesh.cotan.cotan_stiffness`).
    M : (n, n) sparse matrix
        Mass, symmetric positive definite, diagonal or not.
    k : int
        Number of eigenpairs, 1 ≤ k < n.
    options : EigenOptions, optional
    whole_multiplets : bool, default False
        Return more than k pairs rather than cut a degenerate group at k (see the module notes).

    Returns
    -------
    Spectrum
        Eigenvalues (k,) ascending (λ₀ ≈ 0 for a closed surface), in 1/area; eigenvectors (n, k), ``VᵀMV = I``.

    Raises
    ------
    InvalidArgumentError
        Bad shapes, k out of range.
    ConvergenceError
        If the Krylov basis reaches ``max_dim`` before k + 1 pairs converge.

    Examples
    --------
    >>> from shspec.mesh import cotan_stiffness, eigenpairs, icosphere, mass_matrix
    >>> sphere = icosphere(2)
    >>> abs(eigenpairs(cotan_stiffness(sphere), mass_matrix(sphere), 4).eigenvalues.round(2))  # l(l+1), nearly
    array([0., 2., 2., 2.])
    """
    n, k = _check_pencil(L, M, k)
    opt = check_options(options, EigenOptions)
    L = sp.csr_matrix(L, dtype=float)
    M = sp.csr_matrix(M, dtype=float)
    if n < opt.dense_below or k + 2 >= n // 2 or lanczos_estimate(n, k, n)[0] >= n:
        # A Krylov basis expected to fill the space costs more than the dense solve, and need not converge before it
        # is full: near the top of a mesh's spectrum Weyl's estimate, which places σ, is far too high (σ = 463 for
        # λ_1100 = 652 of a 2562-vertex mesh), and the pairs around σ cover [0, λ_k] only with many more than k.
        lam, V = sla.eigh(L.toarray(), M.toarray())
        return _select(lam, V, k, opt.multiplet_rtol, whole_multiplets)
    return _lanczos(L, M, k, opt, whole_multiplets)


def _lanczos(L, M, k: int, opt: EigenOptions, whole: bool) -> Spectrum:
    """The first k pairs by shift-invert block Lanczos, the basis grown until they and the next one have converged."""
    n = L.shape[0]
    area = float(M.sum())
    sigma = opt.sigma if opt.sigma is not None else 0.45 * 4 * np.pi * k / area
    b = int(opt.block_size)
    max_dim = min(n, opt.max_dim or 4 * k + 50 * b)
    expected, memory, seconds = lanczos_estimate(n, k, max_dim + 2 * b)
    if shown(n):
        announce(f"cotan eigenpairs of a {n}-vertex mesh: K = {k}, a Krylov basis of about {expected} vectors "
                 f"({human_bytes(memory)} allocated), roughly {seconds:.0f} s on one core", memory)
    lu, sigma = _shift_factor(L, M, sigma)
    krylov = _Krylov(lu, _mass_product(M), n, b, max_dim, np.random.default_rng(opt.seed))
    # The basis needed was 2.4k + 60 to 3.3k on icospheres and blob (k = 10..200); Ritz checks cost an m-by-m
    # eigendecomposition each, so they start just below that, at 2.2k + 40, and are spaced by 15 % growth.
    next_check = int(2.2 * k) + 40
    nconv, reach = 0, 0.0
    verified_count = -1
    with bar(n, expected, "eigenpairs (Krylov basis)", "vectors") as shown_bar:
        while True:
            if krylov.m_next + b > max_dim:
                raise ConvergenceError(_not_converged(nconv, reach, sigma, k, krylov.m))
            shown_bar.update(krylov.extend())
            m = krylov.m
            if m < next_check and krylov.m_next + b <= max_dim:  # the last basis before max_dim is always checked
                continue
            next_check = int(1.15 * m)
            mu, S, nconv = krylov.ritz(opt.tol)
            if nconv == 0:
                continue
            # The converged pairs are the eigenvalues within D = 1/|μ| of σ; when D ≥ σ they are all of [0, σ + D].
            reach = 1.0 / abs(mu[nconv - 1])
            if reach < sigma:
                continue
            lam = sigma + 1.0 / mu[:nconv]
            ascending = np.argsort(lam)
            # Done when the eigenvalue after the k-th one's group has converged too: then the group is known whole.
            end = _group_end(lam[ascending], k, opt.multiplet_rtol) if nconv > k else nconv
            if end < nconv:
                # A group of b or more equal eigenvalues may have more members than a block of b vectors has found
                # so far: add b random vectors and accept only when the count below the cut stays the same.
                if _largest_group(lam[ascending][:end + 1], opt.multiplet_rtol) >= b and end != verified_count:
                    verified_count, krylov.inject = end, True
                    continue
                return _finish(L, M, krylov.Q[:, :m] @ S[:, ascending], k, opt.multiplet_rtol, whole)


def _mass_product(M):
    """X ↦ M X, by the diagonal alone when M is diagonal."""
    diag = M.diagonal() if M.nnz == np.count_nonzero(M.diagonal()) else None

    def mmul(X):
        return diag[:, None] * X if diag is not None else M @ X

    return mmul


def _shift_factor(L, M, sigma: float) -> tuple:
    """The sparse LU factors of L − σM and the σ they are of."""
    try:
        return splu(sp.csc_matrix(L - sigma * M)), sigma
    except RuntimeError:
        # σ hit an eigenvalue to rounding (SuperLU: "factor is exactly singular"); any nearby σ does as well.
        sigma *= 1.0 + 1e-3
        return splu(sp.csc_matrix(L - sigma * M)), sigma


class _Krylov:
    """The M-orthonormal block Krylov basis Q[:, :m_next] of OP = (L − σM)⁻¹M, grown a block at a time with full
    re-orthogonalization, and T, the matrix of OP on it."""

    def __init__(self, lu, mmul, n: int, b: int, max_dim: int, rng):
        self.lu, self.mmul, self.rng, self.b = lu, mmul, rng, b
        # Room for one block past max_dim, plus b random vectors injected to test a large multiplet (see extend).
        self.Q = np.empty((n, max_dim + 2 * b))
        self.T = np.zeros((max_dim + 2 * b, max_dim + 2 * b))
        X = rng.standard_normal((n, b))
        X[:, 0] = 1.0  # the constants span the λ₀ = 0 eigenspace of a closed surface: give it to Lanczos for free
        X = lu.solve(mmul(X))
        first = _orthonormal_block(self.Q[:, :0], X, mmul, rng, scale=1.0)[0]
        self.prev, self.m, self.m_next = 0, 0, first.shape[1]
        self.Q[:, :self.m_next] = first
        #: Set to add b fresh random directions with the next block.
        self.inject = False

    def extend(self) -> int:
        """Add the next block, OP applied to the newest one Q[:, m:m_next] and orthogonalized; returns its width."""
        Q, mmul, prev, m, m_next = self.Q, self.mmul, self.prev, self.m, self.m_next
        # Orthogonalize first against the previous two blocks (the block three-term recurrence, which removes almost
        # everything), then once against the whole basis (full re-orthogonalization, which removes the rounding
        # errors that make plain Lanczos lose orthogonality).  The coefficients of both passes form the column of T.
        W = self.lu.solve(mmul(Q[:, m:m_next]))
        local = Q[:, prev:m_next]
        C = np.zeros((m_next, m_next - m))
        C[prev:] = local.T @ mmul(W)
        W -= local @ C[prev:]
        basis = Q[:, :m_next]
        W, C2, before = _reorthogonalize(basis, W, mmul)
        width = W.shape[1]
        if self.inject:
            # Fresh random directions, orthogonal to the basis, enter with this block (their row of T is zero).
            extra = self.rng.standard_normal((Q.shape[0], self.b))
            for _ in range(2):
                extra -= basis @ (basis.T @ mmul(extra))
            W = np.hstack([W, extra])
            self.inject = False
        new, coef = _orthonormal_block(basis, W, mmul, self.rng, scale=before.max())
        coef = coef[:, :width]
        nb = new.shape[1]
        self.T[:m_next, m:m_next] = C + C2
        self.T[m_next:m_next + nb, m:m_next] = coef
        Q[:, m_next:m_next + nb] = new
        self.prev, self.m, self.m_next = m, m_next, m_next + nb
        return nb

    def ritz(self, tol: float) -> tuple:
        """Ritz pairs (μ, S) of OP on span Q[:, :m] by decreasing |μ|, and how many of them lead converged."""
        m, T = self.m, self.T
        Tm = 0.5 * (T[:m, :m] + T[:m, :m].T)
        mu, S = sla.eigh(Tm)
        order = np.argsort(-np.abs(mu))
        mu, S = mu[order], S[:, order]
        # residual norms from the coupling block T[m:, :m]
        res = np.linalg.norm(T[m:self.m_next, :m] @ S, axis=0)
        ok = res <= tol * np.abs(mu)
        return mu, S, int(np.argmin(ok)) if not ok.all() else ok.size


def _reorthogonalize(basis, W, mmul) -> tuple:
    """W orthogonalized against ``basis`` (twice if the first pass cancels heavily), the coefficients removed, and
    the M-norms of W's columns before."""
    before = np.sqrt(np.einsum("ij,ij->j", W, mmul(W)))
    C2 = basis.T @ mmul(W)
    W -= basis @ C2
    after = np.sqrt(np.einsum("ij,ij->j", W, mmul(W)))
    if np.any(after < 0.5 * before):
        # Heavy cancellation: what is left may still lean on the basis; "twice is enough" (Kahan, Parlett).
        C3 = basis.T @ mmul(W)
        W -= basis @ C3
        C2 += C3
    return W, C2, before


def _not_converged(nconv: int, reach: float, sigma: float, k: int, m: int) -> str:
    """Why the Krylov basis of ``m`` vectors is not enough: too few converged pairs, or converged pairs (all the
    eigenvalues within ``reach`` of the shift) that do not reach down to λ₀ yet."""
    if reach >= sigma or nconv == 0:
        found = f"{nconv} eigenpairs converged, and {k + 1} are needed"
    else:
        found = (f"the {nconv} eigenpairs that converged are those within {reach:.4g} of the shift {sigma:.4g}, "
                 "which do not reach down to the lowest ones yet")
    return (f"shift-invert Lanczos did not converge with a Krylov basis of {m} vectors: {found}; raise "
            "EigenOptions.max_dim, or move the shift (EigenOptions.sigma) nearer the middle of the wanted eigenvalues")


def _orthonormal_block(basis, W, mmul, rng, scale):
    """M-orthonormalize the columns of W (already orthogonal to ``basis``); returns (new block, R).

    R = newᵀ M W, the coefficients of W in the new block.  Directions of W shorter than 1e-10·scale (``scale``:
    the size of W before orthogonalization) are rounding noise; they are replaced by random directions orthogonal
    to everything, so that the basis keeps growing (deflation of an exhausted Krylov space).
    """
    G = W.T @ mmul(W)
    s, U = np.linalg.eigh(0.5 * (G + G.T))
    keep = s > (1e-10 * scale) ** 2
    new = W @ (U[:, keep] / np.sqrt(s[keep]))
    lost = int((~keep).sum())
    if lost:
        extra = rng.standard_normal((W.shape[0], lost))
        for _ in range(2):
            for part in (basis, new):
                extra -= part @ (part.T @ mmul(extra))
        Ge = extra.T @ mmul(extra)
        extra = extra @ np.linalg.inv(np.linalg.cholesky(Ge)).T
        new = np.hstack([new, extra])
    return new, new.T @ mmul(W)


@reproducible_call
def mesh_spectrum(mesh: TriangleMesh, k: int, mass: str = "lumped", *, whole_multiplets: bool = True,
                  options: EigenOptions | None = None) -> Spectrum:
    """First k cotan Laplace–Beltrami eigenpairs of a triangle mesh.

    Parameters
    ----------
    mesh : TriangleMesh
        n vertices; should be valid (see :func:`~shspec.mesh.validate.validate_mesh`).
    k : int
        Number of eigenpairs, 1 ≤ k < n.
    mass : {"lumped", "consistent"}
        Mass matrix (:func:`~shspec.mesh.cotan.mass_matrix`).  The lumped (diagonal, barycentric) mass is the
        study's and the one every fit of shspec uses; LaPy's ``TriaMesh`` solver and many FEM codes use the
        consistent mass, whose eigenvalues lie above the lumped ones (on the 642-vertex ``pebble``: 0.5 % at λ₁,
        3.5 % at λ₁₀, 9.4 % at λ₃₀; less on finer meshes, as both converge to the surface's spectrum).  Compare
        with LaPy with ``mass="consistent"``.
    whole_multiplets : bool, default True
        Return more than k pairs rather than cut a degenerate group (eigenvalues within
        ``options.multiplet_rtol``) at k.
    options : EigenOptions, optional

    Returns
    -------
    Spectrum
        Eigenvalues ascending in 1/(length unit)², eigenvectors (n, k') M-orthonormal, k' ≥ k.

    Examples
    --------
    >>> from shspec.mesh import load_mesh, mesh_spectrum
    >>> pebble = load_mesh("pebble")
    >>> lumped = mesh_spectrum(pebble, 10).eigenvalues
    >>> consistent = mesh_spectrum(pebble, 10, "consistent").eigenvalues
    >>> bool((consistent[1:10] > lumped[1:10]).all()), round(float(consistent[9] / lumped[9] - 1), 3)
    (True, 0.035)

    Raises
    ------
    MeshError
        A coordinate that is not finite or too large for its squares (:func:`~shspec.mesh.validate.checked_face_areas`),
        or a face of zero area (below :data:`~shspec.mesh.validate.ZERO_AREA_RTOL` of the mean): its cotangents are
        not defined and the pencil loses definiteness, which would give negative eigenvalues.
    """
    if not isinstance(mesh, TriangleMesh):
        raise InvalidArgumentError(f"expected a TriangleMesh, got {type(mesh).__name__}")
    areas = checked_face_areas(mesh)  # NaN or overflowing areas would be counted as zero below
    zero = np.flatnonzero(~(areas > ZERO_AREA_RTOL * areas.mean()))
    if zero.size:
        raise MeshError(f"{zero.size} faces have zero area (first: face {zero[0]} = {mesh.faces[zero[0]].tolist()}, "
                        f"area {areas[zero[0]]:.3g}); the cotan Laplacian is undefined there")
    return eigenpairs(cotan_stiffness(mesh), mass_matrix(mesh, mass), k, options, whole_multiplets=whole_multiplets)
