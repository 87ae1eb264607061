"""Nearest rows (corrlib.neighbours) against brute force."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial.distance import cdist

from corrlib.neighbours import KD_TREE_MAX_DIMENSION, descended_nearest_rows, nearest_rows


@pytest.mark.parametrize("dim", [3, KD_TREE_MAX_DIMENSION, KD_TREE_MAX_DIMENSION + 1, 60])
@pytest.mark.parametrize("chunk", [7, 512])
def test_nearest_rows_is_the_brute_force_argmin(dim, chunk):
    rng = np.random.default_rng(dim)
    query, data = rng.standard_normal((300, dim)), rng.standard_normal((200, dim))
    expected = np.argmin(cdist(query, data), axis=1)
    found = nearest_rows(query, data, chunk=chunk)
    assert found.dtype == np.int64 and found.shape == (300,)
    # float32 products (above the k-d tree's dimensions) may only swap near-ties
    gap = np.linalg.norm(query - data[found], axis=1) - np.linalg.norm(query - data[expected], axis=1)
    assert np.all(gap <= 1e-4) and np.mean(found == expected) > 0.99


def test_nearest_rows_of_the_data_itself_is_the_identity():
    data = np.random.default_rng(1).standard_normal((1000, 40)) * 1e3  # far from the unit scale
    assert np.array_equal(nearest_rows(data, data), np.arange(1000))


def _csr(graph):
    graph = sp.csr_matrix(graph)
    return graph.indptr, graph.indices


def test_descent_on_a_complete_graph_is_the_nearest_row():
    rng = np.random.default_rng(3)
    query, data = rng.standard_normal((200, 12)), rng.standard_normal((50, 12))
    complete = np.ones((50, 50)) - np.eye(50)
    start = rng.integers(0, 50, 200)
    found = descended_nearest_rows(query, data, start, *_csr(complete))
    assert np.array_equal(found, np.argmin(cdist(query, data), axis=1))


def test_descent_on_a_grid_of_a_convex_distance_is_the_nearest_row():
    """Points of a plane grid, 4-neighbour graph: the distance to any query has one minimum on the graph."""
    side = 20
    xs, ys = np.meshgrid(np.arange(side), np.arange(side), indexing="ij")
    data = np.column_stack([xs.ravel(), ys.ravel()]).astype(float)
    index = np.arange(side * side).reshape(side, side)
    edges = np.vstack([np.column_stack([index[:-1].ravel(), index[1:].ravel()]),
                       np.column_stack([index[:, :-1].ravel(), index[:, 1:].ravel()])])
    grid = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(side * side,) * 2)
    rng = np.random.default_rng(4)
    query = rng.uniform(0, side - 1, (300, 2)) + 0.01 * rng.standard_normal((300, 2))
    found = descended_nearest_rows(query, data, rng.integers(0, side * side, 300), *_csr(grid + grid.T))
    assert np.array_equal(found, nearest_rows(query, data))


def test_descent_stops_at_a_local_minimum_and_keeps_unmatched_rows():
    """A path graph 0 - 1 - 2 - 3 - 4 over values with minima at rows 1 and 4: a walk from row 0 ends at row 1
    although row 4 is nearer; a walk from row 3 reaches row 4; -1 stays -1."""
    data = np.array([[3.0], [1.0], [2.0], [0.5], [0.0]])
    path = sp.diags([np.ones(4), np.ones(4)], [-1, 1], shape=(5, 5))
    query = np.zeros((3, 1))
    found = descended_nearest_rows(query, data, np.array([0, 3, -1]), *_csr(path))
    assert found.tolist() == [1, 4, -1]


def test_descent_rejects_indices_outside_the_data():
    path = sp.diags([np.ones(4), np.ones(4)], [-1, 1], shape=(5, 5))
    data, query = np.zeros((5, 2)), np.zeros((2, 2))
    with pytest.raises(ValueError, match="do not fit"):
        descended_nearest_rows(query, data, np.array([0, 5]), *_csr(path))
    with pytest.raises(ValueError, match="do not fit"):
        descended_nearest_rows(query, data[:4], np.array([0, 1]), *_csr(path))


def test_reverse_map_is_the_nearest_image_by_brute_force():
    from corrlib.neighbours import reverse_map

    rng = np.random.default_rng(3)
    target = rng.normal(size=(40, 3))
    map_xy = rng.integers(0, 40, size=25)
    map_xy[:5] = -1  # unmatched source vertices take no part
    reverse = reverse_map(map_xy, target)
    matched = np.flatnonzero(map_xy >= 0)
    distances = np.linalg.norm(target[:, None, :] - target[map_xy[matched]][None, :, :], axis=2)
    assert np.allclose(np.linalg.norm(target - target[map_xy[reverse]], axis=1), distances.min(axis=1))
    hit = np.unique(map_xy[matched])
    assert np.array_equal(map_xy[reverse[hit]], hit)  # a target vertex that is an image maps back to a preimage
    assert np.array_equal(reverse_map(np.full(5, -1), target), np.full(40, -1))
