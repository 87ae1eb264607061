"""Nearest rows: both search paths against the plain definition on small random sets."""

import numpy as np
import pytest

from corrlib.neighbours import nearest_rows, nearest_rows_brute


def _definition(query, data):
    return np.array([np.argmin(np.sum((data - q) ** 2, axis=1)) for q in query])


@pytest.mark.parametrize("dimension", [2, 6, 20])
def test_both_paths_find_the_nearest_row_by_definition(dimension):
    rng = np.random.default_rng(dimension)
    data = rng.normal(size=(300, dimension))
    near = data[rng.integers(0, 300, 120)] + 0.01 * rng.normal(size=(120, dimension))
    far = 30.0 * rng.normal(size=(80, dimension))  # far from every row: where a k-d tree prunes badly
    query = np.vstack([near, far])
    expected = _definition(query, data)
    assert np.array_equal(nearest_rows_brute(query, data, chunk=37), expected)
    if dimension <= 8:  # the float32 products above that may break near-ties differently
        assert np.array_equal(nearest_rows(query, data), expected)
