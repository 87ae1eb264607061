"""Contour-to-contour matching on the product torus: brute force, a known warp, torus geometry."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from _data import SILHOUETTES
from corrlib.geometry.cyclic_paths import ProductGraph, branch_and_bound
from corrlib.geometry.torus import arclength_angles, path_angles, torus_embedding, torus_grid
from corrlib.io import load_contour
from corrlib.methods import solve
from corrlib.methods.contour2d import forward_path_adjacency
from corrlib.progress import run
from corrlib.shapes import Contour2D
from test_contour3d import explicit_product_optimum


@pytest.mark.parametrize("seed", range(4))
def test_unrolled_torus_branch_and_bound_equals_brute_force(seed):
    rng = np.random.default_rng(seed)
    m, n = 7, 9
    ta, tb = np.sort(rng.uniform(0, 2 * np.pi, m)), np.sort(rng.uniform(0, 2 * np.pi, n))
    a = np.column_stack([np.cos(ta), np.sin(ta)])
    b = np.column_stack([1.5 * np.cos(tb), np.sin(tb)])
    cost = rng.random((m, n))
    graph = ProductGraph(np.hstack([cost, cost]), a, np.vstack([b, b]), forward_path_adjacency(2 * n),
                         directed=True, closing_shift=n, n_starts=n)
    exact = explicit_product_optimum(graph)
    result = run(branch_and_bound(graph))
    assert result.energy == pytest.approx(exact, rel=1e-12)
    steps = np.diff(result.path.vertices)
    assert set(np.unique(steps)) <= {0, 1} and result.path.vertices[-1] - result.path.vertices[0] == n


def test_warped_contour_is_recovered():
    """A smooth non-rigid warp of the dog, resampled at another density from another start point.

    Ground truth: the warp of each point. Measured median error 0.014 √area (0.2 % of the perimeter) and
    every point within 2 % of the perimeter; thresholds 0.03 and 95 %.
    """
    a = load_contour(SILHOUETTES / "mpeg7" / "dog-1.gif", 400)
    p = a.points / np.sqrt(a.area)
    warped = p + 0.08 * np.column_stack([np.sin(2.0 * p[:, 1]), np.cos(1.5 * p[:, 0])])
    shift = 37
    b_full = Contour2D(np.roll(warped, -shift, axis=0))
    result = solve("contour2d", a, b_full.resample(300))
    resampled_a = a.resample(120)
    original = cKDTree(a.points).query(resampled_a.points)[1]
    truth = b_full.points[(original - shift) % 400]
    predicted = result.path.target_points[result.map_xy]
    err = np.linalg.norm(predicted - truth, axis=1) / np.sqrt(b_full.area)
    perimeter = b_full.length / np.sqrt(b_full.area)
    assert np.median(err) < 0.03 and np.mean(err < 0.02 * perimeter) > 0.95
    # an orientation-preserving bijection: the map runs once around B
    descents = np.sum(np.diff(result.map_xy) < 0) + (result.map_xy[0] < result.map_xy[-1])
    assert descents <= 2 and np.all(result.map_yx >= 0)


def test_dissimilar_contours_do_not_collapse():
    a = load_contour(SILHOUETTES / "mpeg7" / "dog-1.gif")
    b = load_contour(SILHOUETTES / "mpeg7" / "horse-1.gif")
    result = solve("contour2d", a, b, n_source=60, n_target=60)
    assert np.unique(result.map_xy).size > 40  # spread over B, not a few points


def test_torus_geometry():
    u = np.linspace(0, 1, 8, endpoint=False)
    v = np.linspace(0, 1, 6, endpoint=False)
    verts, faces, index = torus_grid(u, v)
    assert verts.shape == (48, 3) and faces.shape == (2 * 48, 3) and np.array_equal(index, np.arange(48))
    radius = np.linalg.norm(verts[:, :2], axis=1)
    assert np.allclose((radius - 1.0) ** 2 + verts[:, 2] ** 2, 0.4 ** 2)  # on the ring torus
    flat_v, flat_f, flat_i = torus_grid(u, v, flat=True)
    assert flat_v.shape == (63, 3) and flat_f.shape == (2 * 48, 3) and flat_i.max() == 47
    square = np.array([[0, 0], [2, 0], [2, 1], [0, 1]], float)
    assert np.allclose(arclength_angles(square), [0, 1 / 3, 0.5, 5 / 6])
    uv = path_angles(np.array([0, 1, 2, 3]), np.array([4, 5, 0, 1]), np.linspace(0, 1, 3, endpoint=False),
                     np.linspace(0, 1, 6, endpoint=False))
    assert np.all(np.diff(uv[:, 1]) > 0)  # unwrapped across the seam
    assert np.allclose(torus_embedding(0.0, 0.0), [1.4, 0, 0])
