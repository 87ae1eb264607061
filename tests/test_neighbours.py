"""Nearest rows (corrlib.neighbours) against brute force."""

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from corrlib.neighbours import KD_TREE_MAX_DIMENSION, nearest_rows


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
