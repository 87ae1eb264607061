"""Nearest neighbours between two sets of feature vectors (rows), the trivial assignment."""

from __future__ import annotations

import numba
import numpy as np
from scipy.spatial import cKDTree

#: above this dimension a k-d tree degrades to brute force, so brute force is done directly (in float32)
KD_TREE_MAX_DIMENSION = 8


def nearest_rows(query: np.ndarray, data: np.ndarray, chunk: int = 512) -> np.ndarray:
    """(q,) int: index of the nearest row of ``data`` (L2) for every row of ``query``.

    Parameters
    ----------
    query : (q, d) float
    data : (p, d) float
    chunk : int
        Query rows per block of the brute-force products (bounds the memory to ``chunk × p``; a block that
        stays in the processor's cache is faster than a large one).

    Notes
    -----
    A k-d tree for up to :data:`KD_TREE_MAX_DIMENSION` dimensions; above that,
    chunked ``argmin_j ||d_j||² - 2 q·d_j`` products in float32 (the factor
    −2 taken into the query and the norms added in place: one block in
    memory), which is exact up to float32 ties.
    """
    query = np.asarray(query, dtype=np.float64)
    data = np.asarray(data, dtype=np.float64)
    if data.shape[1] <= KD_TREE_MAX_DIMENSION:
        return cKDTree(data).query(query, k=1, workers=-1)[1].astype(np.int64)
    data32 = data.astype(np.float32)
    sq = np.einsum("ij,ij->i", data32, data32)
    minus_two_query = (-2.0 * query).astype(np.float32)
    out = np.empty(query.shape[0], dtype=np.int64)
    for start in range(0, query.shape[0], chunk):
        block = minus_two_query[start:start + chunk] @ data32.T
        block += sq[None, :]
        out[start:start + chunk] = np.argmin(block, axis=1)
    return out


def descended_nearest_rows(query: np.ndarray, data: np.ndarray, start: np.ndarray, indptr: np.ndarray,
                           indices: np.ndarray) -> np.ndarray:
    """(q,) int: for every row of ``query``, the row of ``data`` reached by steepest descent of the L2
    distance over a graph on ``data``'s rows, from ``start``.

    From ``start[i]`` the walk moves to the nearest of the current row's graph neighbours while that one is
    nearer ``query[i]`` than the current row, and stops at a local minimum of the distance on the graph.
    Where the distance has one minimum in the start's neighbourhood this is :func:`nearest_rows` at the cost
    of a few neighbourhoods instead of all of ``data``. Rows with ``start[i] < 0`` stay -1.

    Parameters
    ----------
    query : (q, d) float
    data : (p, d) float
    start : (q,) int
        A row of ``data`` for each query row, or -1.
    indptr, indices : int arrays
        The graph on ``data``'s rows in CSR form (e.g. a mesh's vertex adjacency).
    """
    query = np.ascontiguousarray(query, dtype=np.float64)
    data = np.ascontiguousarray(data, dtype=np.float64)
    start, indptr, indices = (np.asarray(a, dtype=np.int64) for a in (start, indptr, indices))
    # the compiled walk does not check bounds: a bad index would read outside the arrays
    n = data.shape[0]
    if (query.shape[1] != data.shape[1] or start.shape != (query.shape[0],) or indptr.shape != (n + 1,)
            or (start.size and start.max() >= n) or (indices.size and (indices.min() < 0 or indices.max() >= n))
            or indptr[-1] > indices.size):
        raise ValueError(f"descended_nearest_rows: query {query.shape}, data {data.shape}, start {start.shape} "
                         f"and a graph with {indptr.size - 1} rows and {indices.size} entries do not fit")
    return _descend(query, data, start, indptr, indices)


@numba.njit(cache=True, nogil=True)
def _squared_distance_below(a, b, bound):
    """``|a − b|²``, or a value ≥ ``bound`` as soon as the partial sum reaches it."""
    total = 0.0
    for c in range(a.shape[0]):
        t = a[c] - b[c]
        total += t * t
        if total >= bound:
            break
    return total


@numba.njit(cache=True, nogil=True)
def _descend(query, data, start, indptr, indices):
    out = start.copy()
    for i in range(query.shape[0]):
        here = start[i]
        if here < 0:
            continue
        best = _squared_distance_below(query[i], data[here], np.inf)
        while True:
            nearer = -1
            for e in range(indptr[here], indptr[here + 1]):
                j = indices[e]
                d = _squared_distance_below(query[i], data[j], best)
                if d < best:
                    best, nearer = d, j
            if nearer < 0:
                break
            here = nearer
        out[i] = here
    return out


def reverse_map(map_xy: np.ndarray, target_vertices: np.ndarray) -> np.ndarray:
    """(n_y,) int: for every target vertex, the source vertex whose image under ``map_xy`` is nearest to it.

    A map given one way only (a file, another tool) has no target-to-source map; this one is what colour and
    texture transfer onto the target need. Target vertices that no image reaches take the source vertex of the
    nearest image. All -1 where ``map_xy`` matches no source vertex.

    Parameters
    ----------
    map_xy : (n_x,) int
        Target vertex of every source vertex, -1 where unmatched.
    target_vertices : (n_y, 3) float
    """
    map_xy = np.asarray(map_xy)
    matched = np.flatnonzero(map_xy >= 0)
    if matched.size == 0:
        return np.full(len(target_vertices), -1, dtype=np.int64)
    images = np.asarray(target_vertices, dtype=np.float64)[map_xy[matched]]
    return matched[nearest_rows(target_vertices, images)]
