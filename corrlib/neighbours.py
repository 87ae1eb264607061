"""Nearest neighbours between two sets of feature vectors (rows), the trivial assignment."""

from __future__ import annotations

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
