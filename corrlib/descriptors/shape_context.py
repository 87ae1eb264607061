"""Inner-distance shape context of a closed outline, and the order-preserving matching of two outlines.

Ling & Jacobs, *Shape Classification Using the Inner-Distance*, IEEE TPAMI 29(2), 2007. The inner distance
between two points of a shape is the length of the shortest path between them **within** the shape. A
bending limb keeps its inner distances (an articulation moves a part about a narrow joint) where their
Euclidean distances change, so the descriptor built on them compares outlines of one kind of shape in
different poses. Every point of an outline sampled at ``n`` points gets a log-polar histogram of the other
points: by their inner distance (``n_distance`` log bins from 1/8 to 2 of the mean inner distance; the
outer bins take the rest) and by their inner angle (``n_angle`` bins: the direction in which the shortest
path leaves the point, against the outline's tangent there). Two outlines are compared by the cheapest
order-preserving alignment of their points, with a start anywhere on the second and a fixed cost for a point
left out (:func:`cyclic_alignment_cost`; the χ² distance of two histograms lies in [0, 1]).

The descriptor is invariant to translation, rotation and scale (inner distances are relative to their
mean; angles are relative to the tangent), not to a reflection: compare the mirror image as well where a
drawing may be seen from either side. The functions take point arrays; an outline's points are
counter-clockwise (:meth:`corrlib.shapes.Contour2D.ccw`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from corrlib.shapes import readonly_view

#: histogram bins (the paper's choice for the MPEG-7 shapes: 5 inner-distance bins, 12 inner-angle bins)
N_DISTANCE_BINS, N_ANGLE_BINS = 5, 12
#: log2 of the innermost and outermost inner-distance bin edges, relative to the mean inner distance
#: (1/8 and 2, Belongie et al.'s shape context)
LOG2_DISTANCE_RANGE = (-3.0, 1.0)
#: cost of leaving one point of either outline unaligned (χ² costs lie in [0, 1]; a point whose histogram
#: agrees with no point of the other outline costs about this much)
GAP_COST = 0.25
#: points an outline is resampled to before its shape context is taken (the paper's 100 for the MPEG-7 shapes)
OUTLINE_POINTS = 100


@njit(cache=True)
def _cross(ox, oy, ax, ay, bx, by):
    """z of ``(a − o) × (b − o)``."""
    return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)


@njit(cache=True)
def _inside(x, y, polygon):
    """Even–odd test of one point against a polygon (a horizontal ray to the right)."""
    n = polygon.shape[0]
    inside = False
    for k in range(n):
        x0, y0 = polygon[k, 0], polygon[k, 1]
        x1, y1 = polygon[(k + 1) % n, 0], polygon[(k + 1) % n, 1]
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            inside = not inside
    return inside


@njit(cache=True)
def _visibility(p, tol):
    n = p.shape[0]
    visible = np.zeros((n, n), dtype=np.bool_)
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):  # an edge of the polygon
                visible[i, j] = visible[j, i] = True
                continue
            ax, ay, bx, by = p[i, 0], p[i, 1], p[j, 0], p[j, 1]
            blocked = False
            for k in range(n):
                cx, cy = p[k, 0], p[k, 1]
                dx, dy = p[(k + 1) % n, 0], p[(k + 1) % n, 1]
                # a proper crossing: each segment's ends strictly on both sides of the other's line
                if _cross(ax, ay, bx, by, cx, cy) * _cross(ax, ay, bx, by, dx, dy) < -tol and \
                        _cross(cx, cy, dx, dy, ax, ay) * _cross(cx, cy, dx, dy, bx, by) < -tol:
                    blocked = True
                    break
            if not blocked and _inside(0.5 * (ax + bx), 0.5 * (ay + by), p):
                visible[i, j] = visible[j, i] = True
    return visible


def visibility(points: np.ndarray) -> np.ndarray:
    """Which chords of a simple polygon lie inside it: ``visible[i, j]`` where the segment ``p_i p_j`` crosses
    no edge of the polygon and its midpoint is inside (the polygon's own edges are visible). O(n³).

    Parameters
    ----------
    points : (n, 2) float
        A simple polygon's vertices, in order.

    Returns
    -------
    (n, n) bool
        Symmetric, False on the diagonal.
    """
    p = readonly_view(points, np.float64)  # one compiled signature for every caller
    scale = float(np.ptp(p, axis=0).max()) ** 2  # cross products are areas: their products scale as length⁴
    return _visibility(p, (1e-12 * scale) ** 2)


def inner_distances(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inner distances between the vertices of a simple polygon, and where each shortest path goes first.

    The shortest path within a polygon between two of its vertices bends only at vertices (a taut string),
    so it is a shortest path in the visibility graph: vertices joined by the chords that lie inside
    (:func:`visibility`), weighted by their length (Ling & Jacobs 2007, §3.1).

    Parameters
    ----------
    points : (n, 2) float
        A simple polygon's vertices, in order.

    Returns
    -------
    distances : (n, n) float
        Inner distances (symmetric, zero diagonal).
    first_step : (n, n) int
        ``first_step[i, j]``: the vertex the shortest path from ``i`` to ``j`` visits after ``i`` (``i`` on the
        diagonal).
    """
    from scipy.sparse.csgraph import shortest_path

    p = np.asarray(points, dtype=np.float64)
    lengths = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2)
    graph = np.where(visibility(p), lengths, 0.0)
    distances, predecessors = shortest_path(graph, method="D", directed=False, return_predecessors=True)
    # the path from j to i ends with (predecessor of i, i): read backwards, that is the first step from i to j
    first_step = predecessors.T.copy()
    np.fill_diagonal(first_step, np.arange(len(p)))
    return distances, first_step


def inner_shape_context(points: np.ndarray, n_distance: int = N_DISTANCE_BINS,
                        n_angle: int = N_ANGLE_BINS) -> np.ndarray:
    """The inner-distance shape context of every vertex of a closed outline (Ling & Jacobs 2007, §3.2).

    Parameters
    ----------
    points : (n, 2) float
        A simple polygon's vertices, counter-clockwise, roughly evenly spaced.
    n_distance, n_angle : int
        Log inner-distance bins and inner-angle bins.

    Returns
    -------
    (n, n_distance · n_angle) float
        Histograms of the other ``n − 1`` vertices, each summing to 1 (distance-major).
    """
    p = np.asarray(points, dtype=np.float64)
    n = len(p)
    distances, first_step = inner_distances(p)
    off_diagonal = ~np.eye(n, dtype=bool)
    log_distance = np.log2(np.maximum(distances / distances[off_diagonal].mean(), 1e-12))
    low, high = LOG2_DISTANCE_RANGE
    distance_bin = np.clip(np.floor((log_distance - low) / (high - low) * n_distance), 0, n_distance - 1)
    step = p[first_step] - p[:, None, :]
    tangent = np.roll(p, -1, axis=0) - np.roll(p, 1, axis=0)
    angle = np.arctan2(step[..., 1], step[..., 0]) - np.arctan2(tangent[:, 1], tangent[:, 0])[:, None]
    angle_bin = np.minimum(np.floor(np.mod(angle, 2 * np.pi) / (2 * np.pi) * n_angle), n_angle - 1)
    bins = (distance_bin * n_angle + angle_bin).astype(np.int64)
    rows = np.broadcast_to(np.arange(n)[:, None], (n, n))
    histograms = np.zeros((n, n_distance * n_angle))
    np.add.at(histograms, (rows[off_diagonal], bins[off_diagonal]), 1.0)
    return histograms / (n - 1)


def chi2_costs(histograms_a: np.ndarray, histograms_b: np.ndarray) -> np.ndarray:
    """χ² distances ``½ Σ_k (a_k − b_k)² / (a_k + b_k)`` between every pair of histograms (in [0, 1] for
    histograms summing to 1; empty bins of both count nothing).

    Parameters
    ----------
    histograms_a : (m, d) float
    histograms_b : (n, d) float

    Returns
    -------
    (m, n) float
    """
    return _chi2_costs(np.ascontiguousarray(histograms_a, dtype=np.float64),
                       np.ascontiguousarray(histograms_b, dtype=np.float64))


@njit(cache=True)
def _chi2_costs(a, b):
    costs = np.zeros((a.shape[0], b.shape[0]))
    for i in range(a.shape[0]):
        for j in range(b.shape[0]):
            total = 0.0
            for k in range(a.shape[1]):
                both = a[i, k] + b[j, k]
                if both > 0.0:
                    total += (a[i, k] - b[j, k]) ** 2 / both
            costs[i, j] = 0.5 * total
    return costs


@njit(cache=True)
def cyclic_alignment_cost(costs: np.ndarray, gap: float) -> float:
    """Cheapest order-preserving alignment of two closed sequences, per point of the first.

    Aligns point ``i`` of the first sequence (in order, from its point 0) with points of the second in order,
    starting at any of its points ``s``; a pair ``(i, (s + j) mod n)`` costs ``costs[i, (s + j) mod n]``, a
    point of either sequence left out costs ``gap``. Every point of both is either paired or left out
    (edit distance; Ling & Jacobs 2007 §4 align with a dynamic programme over the start points). O(m n²).

    Parameters
    ----------
    costs : (m, n) float
    gap : float

    Returns
    -------
    float
        The minimum over the starts ``s`` of the alignment's total cost, divided by ``m``.
    """
    m, n = costs.shape
    doubled = np.empty((m, 2 * n))  # column start + j of the doubled matrix is column (start + j) mod n
    doubled[:, :n] = costs
    doubled[:, n:] = costs
    best = np.inf
    row = np.empty(n + 1)
    previous = np.empty(n + 1)
    for start in range(n):
        for j in range(n + 1):
            previous[j] = j * gap
        for i in range(1, m + 1):
            pair_costs = doubled[i - 1, start:start + n]
            left = i * gap
            row[0] = left
            for j in range(1, n + 1):
                value = previous[j - 1] + pair_costs[j - 1]
                skip = min(previous[j], left) + gap
                left = value if value < skip else skip
                row[j] = left
            previous, row = row, previous
        if previous[n] < best:
            best = previous[n]
    return best / m


def outline_dissimilarity(context_a: np.ndarray, context_b: np.ndarray, gap: float = GAP_COST) -> float:
    """Mean cost per point of the best cyclic alignment of two outlines' shape contexts
    (:func:`chi2_costs`, :func:`cyclic_alignment_cost`); 0 for the same outline from any start point.

    Parameters
    ----------
    context_a : (m, d) float
    context_b : (n, d) float
        :func:`inner_shape_context` of two outlines, both counter-clockwise.
    """
    return float(cyclic_alignment_cost(chi2_costs(context_a, context_b), float(gap)))


def outline_context(outline, n_points: int = OUTLINE_POINTS) -> np.ndarray:
    """(n_points, d) float: :func:`inner_shape_context` of an outline (a :class:`~corrlib.shapes.Contour2D`)
    resampled by arc length to ``n_points``, counter-clockwise (as :func:`outline_dissimilarity` compares
    them)."""
    return inner_shape_context(outline.resample(n_points).ccw().points)
