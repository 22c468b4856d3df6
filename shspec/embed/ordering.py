"""A fill-reducing elimination order for sparse matrices on sphere meshes: geometric nested dissection."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidArgumentError

__all__ = ["nested_dissection"]


def nested_dissection(points: np.ndarray, pattern: sp.spmatrix, leaf: int = 64) -> np.ndarray:
    """Fill-reducing elimination order by geometric nested dissection.

    The vertex set is split at the median of its widest coordinate; the vertices of the lower half that are
    coupled (in ``pattern``) to the upper half form the separator, which is eliminated last.  On a sphere mesh each
    cut is a near-great circle of O(√n) vertices, which gives the n log n fill of planar nested dissection.

    Parameters
    ----------
    points : (n, 3) array
        Vertex positions.
    pattern : (n, n) sparse matrix
        Symmetric sparsity pattern of the matrix to factor.
    leaf : int
        Parts of at most this many vertices are not split further.

    Returns
    -------
    (n,) int array
        A permutation: ``order[k]`` is the vertex eliminated k-th.

    Examples
    --------
    >>> import numpy as np
    >>> import scipy.sparse as sp
    >>> from shspec.embed import nested_dissection
    >>> from shspec.mesh import cotan_stiffness, icosphere
    >>> sphere = icosphere(2)
    >>> order = nested_dissection(sphere.vertices, cotan_stiffness(sphere), leaf=16)
    >>> sorted(order.tolist()) == list(range(sphere.nvertices))     # a permutation of the vertices
    True
    """
    points = np.asarray(points, dtype=float)
    P = sp.csr_matrix(pattern)
    n = points.shape[0]
    if P.shape != (n, n):
        raise InvalidArgumentError(f"pattern must be ({n}, {n}), got {P.shape}")
    out: list[np.ndarray] = []
    # Explicit stack of (vertex set, separator to emit after it): the separator must follow both halves.
    stack: list[tuple[str, np.ndarray]] = [("part", np.arange(n))]
    side = np.zeros(n, dtype=np.int8)
    while stack:
        kind, idx = stack.pop()
        if kind == "sep" or idx.size <= leaf:
            out.append(idx)
            continue
        pts = points[idx]
        axis = int(np.argmax(np.ptp(pts, axis=0)))
        upper = pts[:, axis] > np.median(pts[:, axis])
        side[idx] = np.where(upper, 2, 1)
        lower = idx[~upper]
        rows = P[lower]
        touches = np.zeros(lower.size, dtype=bool)
        hit = side[rows.indices] == 2
        np.logical_or.at(touches, np.repeat(np.arange(lower.size), np.diff(rows.indptr)), hit)
        side[idx] = 0
        sep = lower[touches]
        # Push in reverse: the stack pops the lower part first, then the upper, then the separator.
        stack.append(("sep", sep))
        stack.append(("part", idx[upper]))
        stack.append(("part", lower[~touches]))
    return np.concatenate(out)
