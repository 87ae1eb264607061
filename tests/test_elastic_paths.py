"""The elastic (second-order) product graph: brute force on tiny graphs, path validity, bounds."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra, johnson
from test_contour3d import tiny_instance

from corrlib.errors import ParameterError
from corrlib.geometry.cyclic_paths import ProductGraph, branch_and_bound, minimum_ratio_union
from corrlib.geometry.elastic_paths import ElasticProductGraph
from corrlib.progress import run


def tiny(seed, m=6, stretch=0.7, bending=0.4, subdivisions=1):
    return ElasticProductGraph(*tiny_instance(seed, m, subdivisions), stretch=stretch, bending=bending)


def explicit_optimum(g: ElasticProductGraph, gain: float = 0.0) -> float:
    """Every state and move built explicitly; per start vertex a Dijkstra (SciPy).

    States: (layer, directed edge u -> j: at j, last graph move from u) and (layer, vertex v: no graph move
    yet). Moves as in the module docstring; bending only after a first graph move. ``gain`` credits every
    move advancing along curve and graph with ``-gain * min(a, b)`` (the ratio energy's parametric problem;
    Johnson's algorithm then, as some edges are negative).
    """
    m, n_edges, n = g.m, len(g.indices), g.n
    pts = g.graph_points
    n_states = n_edges + n
    node = lambda i, e: i * n_states + e  # noqa: E731
    head = np.r_[g.indices, np.arange(n)]
    tail = np.r_[g.tail, -np.ones(n, dtype=np.int64)]
    rows, cols, w = [], [], []
    for i in range(m + 1):
        a = np.sqrt(g.step2[i]) if i < m else 0.0
        for e in range(n_states):
            j, u = head[e], tail[e]
            for q in np.flatnonzero(g.tail == j):
                k = g.indices[q]
                if k == u:
                    continue
                b = np.linalg.norm(pts[k] - pts[j])
                bend = 0.0
                if u >= 0:
                    into, out = pts[j] - pts[u], pts[k] - pts[j]
                    bend = g.bending * (1.0 - into @ out / (np.linalg.norm(into) * b))
                rows.append(node(i, e)), cols.append(node(i, q))
                w.append(0.5 * (g.cost[i, j] + g.cost[i, k]) * b + g.stretch * b + bend)
                if i < m:
                    rows.append(node(i, e)), cols.append(node(i + 1, q))
                    w.append(0.5 * (g.cost[i, j] + g.cost[i + 1, k]) * np.hypot(a, b) + g.stretch * abs(b - a) + bend
                             - gain * min(a, b))
            if i < m:
                rows.append(node(i, e)), cols.append(node(i + 1, e))
                w.append((0.5 * (g.cost[i, j] + g.cost[i + 1, j]) + g.stretch) * a)
    graph = sp.coo_matrix((w, (rows, cols)), shape=((m + 1) * n_states,) * 2).tocsr()
    best = np.inf
    shortest = dijkstra if gain == 0 else johnson
    for s in range(n):
        dist = shortest(graph, directed=True, indices=node(0, n_edges + s))
        ends = [node(m, e) for e in range(n_states) if head[e] == s]
        best = min(best, dist[ends].min())
    return float(best)


@pytest.mark.parametrize("seed", range(4))
def test_branch_and_bound_equals_brute_force(seed):
    g = tiny(seed)
    exact = explicit_optimum(g)
    result = run(branch_and_bound(g))
    assert result.energy == pytest.approx(exact, rel=1e-9)
    assert result.lower_bound == pytest.approx(exact, rel=1e-9)
    assert g.path_energy(result.path) == pytest.approx(result.energy, rel=1e-9)
    approx = run(branch_and_bound(tiny(seed), eps=0.2))
    assert exact - 1e-12 <= approx.energy <= 1.2 * exact + 1e-12


@pytest.mark.parametrize("seed", range(3))
def test_minimum_ratio_on_the_second_order_graph_is_optimal_on_the_explicit_state_graph(seed):
    """Dinkelbach over the elastic graph: no closed path of the explicit state graph has E - ratio * D < 0 (so
    none has a lower ratio), and the returned path attains the ratio, recomputed step by step."""
    g = tiny(seed, m=5, subdivisions=0)
    result = run(minimum_ratio_union([g]))
    assert explicit_optimum(g, gain=result.energy) == pytest.approx(0.0, abs=1e-9)
    assert explicit_optimum(g, gain=result.energy * 1.001) < 0  # a larger ratio is beaten
    assert g.path_energy(result.path) / g.credited_length(result.path) == pytest.approx(result.energy, rel=1e-12)
    assert result.lower_bound == result.upper_bound


def test_no_immediate_reversal_and_valid_closed_path():
    g = tiny(3, m=8, subdivisions=2)
    path = run(branch_and_bound(g)).path
    assert path.vertices[0] == path.vertices[-1] and path.layers[0] == 0 and path.layers[-1] == g.m
    moves = [(a, b) for a, b in zip(path.vertices[:-1], path.vertices[1:]) if a != b]
    assert all(g.adjacency[a, b] > 0 for a, b in moves)
    assert all(m1[0] != m2[1] for m1, m2 in zip(moves[:-1], moves[1:]))  # never straight back


def test_reduces_to_the_first_order_energy_without_elastic_terms_and_bounds_it():
    for seed in range(3):
        elastic = tiny(seed, stretch=0.0, bending=0.0)
        first = ProductGraph(elastic.cost[:-1], np.zeros((elastic.m, 2)), elastic.graph_points, elastic.adjacency)
        first.step2 = elastic.step2
        e1, e2 = run(branch_and_bound(first)).energy, run(branch_and_bound(elastic)).energy
        # the rule against reversals can only make the optimum dearer
        assert e2 >= e1 - 1e-12
        stretched = tiny(seed, stretch=0.7, bending=0.4)
        relaxed = ProductGraph(stretched.cost[:-1], np.zeros((stretched.m, 2)), stretched.graph_points,
                               stretched.adjacency, stretch=0.7)
        relaxed.step2 = stretched.step2
        assert run(branch_and_bound(stretched)).energy >= run(branch_and_bound(relaxed)).energy - 1e-12


def test_reversing_a_closed_path_keeps_its_energy():
    g = tiny(5, m=7, subdivisions=2)
    path = run(branch_and_bound(g)).path
    # the same closed curve traversed backwards, on the reversed curve (layer i -> m - i)
    back = type(path)(path.vertices[::-1].copy(), (g.m - path.layers[::-1]).copy(), 0.0)
    reversed_graph = ElasticProductGraph(g.cost[:-1][np.r_[0, g.m - 1:0:-1]], np.zeros((g.m, 2)),
                                         g.graph_points, g.adjacency, stretch=g.stretch, bending=g.bending)
    reversed_graph.step2 = g.step2[::-1].copy()
    reversed_graph.step = np.sqrt(reversed_graph.step2)
    assert reversed_graph.path_energy(back) == pytest.approx(g.path_energy(path), rel=1e-12)


def test_parameter_errors():
    with pytest.raises(ParameterError, match="bending"):
        tiny(0, bending=-1.0)
    with pytest.raises(ParameterError, match="stretch"):
        tiny(0, stretch=float("nan"))
