"""2D-to-3D elastic matching: brute force on tiny graphs, path validity, real shapes, invariance, bad input."""

import numba
import numpy as np
import pytest
import scipy.sparse as sp
import trimesh
from scipy.sparse.csgraph import dijkstra, johnson

from _data import SUMNER, TOSCA
from corrlib.errors import Cancelled, ContourError, InputError, ParameterError
from corrlib.geometry.cyclic_paths import (GraphTopology, ProductGraph, Relaxation, branch_and_bound,
                                           minimum_ratio_union)
from corrlib.geometry.elastic_paths import ElasticProductGraph
from corrlib.geometry.geodesics import GeodesicSolver
from corrlib.geometry.sections import plane_section, rendered_view, rim_vertices
from corrlib.io import load_mesh
from corrlib.methods import solve
from corrlib.methods.contour3d import feature_distances, mean_feature_distance, node_costs
from corrlib.progress import CancelToken, run
from corrlib.retrieval import average_precision, class_of, mean_average_precision, retrieval_params, retrieve
from corrlib.shapes import Contour2D, TriMesh


def explicit_product_matrix(graph: ProductGraph, gain: float = 0.0) -> sp.csr_matrix:
    """The product graph built explicitly: ((m + 1) n, (m + 1) n) edge costs, node ``(i, j)`` at ``i n + j``."""
    m, n = graph.m, graph.n
    node = lambda i, j: i * n + j  # noqa: E731
    adj = graph.adjacency.tocoo()
    # the directed edge penalties (times length) as given to the graph, looked up per edge
    extra = sp.csr_matrix((graph.extra, graph.indices, graph.indptr), shape=(n, n)).todense()
    rows, cols, w = [], [], []
    for i in range(m + 1):
        for j, k, length in zip(adj.row, adj.col, adj.data):
            rows.append(node(i, j)), cols.append(node(i, k))
            w.append(0.5 * (graph.cost[i, j] + graph.cost[i, k]) * length + extra[j, k])
            if i < m:
                a = np.sqrt(graph.step2[i])
                rows.append(node(i, j)), cols.append(node(i + 1, k))
                step = max(length, a) if graph.metric == "max" else np.hypot(length, a)
                w.append(0.5 * (graph.cost[i, j] + graph.cost[i + 1, k]) * step - gain * min(a, length)
                         + extra[j, k])
        if i < m:
            for j in range(n):
                rows.append(node(i, j)), cols.append(node(i + 1, j))
                w.append(0.5 * (graph.cost[i, j] + graph.cost[i + 1, j]) * np.sqrt(graph.step2[i]))
    return sp.coo_matrix((w, (rows, cols)), shape=((m + 1) * n,) * 2).tocsr()


def explicit_product_optimum(graph: ProductGraph, gain: float = 0.0) -> float:
    """All-sources shortest paths on the explicitly built product graph: min over s of d((0,s), (m,s)).

    ``gain`` > 0: the ratio energy's parametric problem ``E - gain * D``, every edge advancing along curve and
    graph credited ``min(a, b)``, independently of the layered kernel (Johnson's algorithm, as those edges may
    be negative; the edges within a layer are not, so there is no negative cycle)."""
    m, n = graph.m, graph.n
    node = lambda i, j: i * n + j  # noqa: E731
    product = explicit_product_matrix(graph, gain)
    shortest = dijkstra if gain == 0 else johnson
    dist = shortest(product, directed=True, indices=np.arange(graph.n_starts))
    return float(min(dist[s, node(m, s + graph.closing_shift)] for s in range(graph.n_starts)))


def tiny_instance(seed, m=7, subdivisions=1):
    """Random node costs (m, n), an ellipse of m points and an icosphere: inputs of a tiny product graph."""
    rng = np.random.default_rng(seed)
    ico = trimesh.creation.icosphere(subdivisions=subdivisions)
    t = np.sort(rng.uniform(0, 2 * np.pi, m))
    curve = np.column_stack([np.cos(t), 0.6 * np.sin(t)])
    adj = sp.coo_matrix((np.ones(len(ico.edges_unique)), tuple(ico.edges_unique.T)), shape=(len(ico.vertices),) * 2)
    cost = rng.random((m, len(ico.vertices))) ** 2
    return cost, curve, ico.vertices, adj


def tiny_graph(seed, m=7, subdivisions=1):
    return ProductGraph(*tiny_instance(seed, m, subdivisions))


@pytest.mark.parametrize("seed", range(4))
def test_closing_detour_is_a_closed_path_whose_energy_is_recomputed_edge_by_edge(seed):
    """The upper bound from an open path: walk back to its start in the closing layer. The path is closed,
    its stated energy equals the edge-by-edge energy, it is at least the open path's energy and at least
    the optimum; a stretching weight is paid on the walk too."""
    for stretch in (0.0, 0.7):
        node_cost, curve, points, adjacency = tiny_instance(seed, 7, 1)
        graph = ProductGraph(node_cost, curve, points, adjacency, stretch=stretch)
        everything = np.ones(graph.n, dtype=bool)
        cost, s, t = graph.shortest(everything, everything)
        open_path = graph.backtrack(t)
        energy, closed = graph.close_by_detour(open_path)
        assert closed.vertices[0] == closed.vertices[-1] == s
        assert energy == pytest.approx(graph.path_energy(closed), rel=1e-12)
        assert energy >= cost - 1e-12
        if stretch == 0:  # the explicit product graph has the paper's edge costs
            assert energy >= explicit_product_optimum(graph) - 1e-12
        if s == t:
            assert energy == pytest.approx(cost, rel=1e-12)
        # the second-order graph has no such walk (its turns would need its own energy)
        elastic = ElasticProductGraph(node_cost, curve, points, adjacency, stretch=stretch, bending=1.0)
        assert elastic.close_by_detour(open_path) == (np.inf, None)
        # the same open path read off the backward search of the heuristic (walked forwards)
        graph.compute_heuristic()
        root = graph.root_path
        assert root.layers[0] == 0 and root.layers[-1] == graph.m and np.all(np.diff(root.layers) >= 0)
        assert root.energy == pytest.approx(cost, rel=1e-12)
        assert graph.path_energy(root) == pytest.approx(root.energy, rel=1e-12)


def test_a_shared_topology_gives_the_same_graph_and_is_checked():
    """Readings built on one GraphTopology search exactly as graphs that build their own; a topology of another
    graph, or of the other kind (directed or not), is a named error."""
    node_cost, curve, points, adjacency = tiny_instance(3, 7, 1)
    penalty = directed_penalties(3, adjacency)
    topology = GraphTopology.of(points, adjacency)
    everything = np.ones(points.shape[0], dtype=bool)
    own = ProductGraph(node_cost, curve, points, adjacency, edge_penalty=penalty)
    shared = ProductGraph(node_cost, curve, points, adjacency, edge_penalty=penalty, topology=topology)
    assert own.shortest(everything, everything) == shared.shortest(everything, everything)
    own.compute_heuristic(), shared.compute_heuristic()
    np.testing.assert_array_equal(own.heuristic, shared.heuristic)
    with pytest.raises(InputError, match="topology"):
        ProductGraph(node_cost, curve, points, adjacency, directed=True, topology=topology)
    with pytest.raises(InputError, match="topology"):
        ProductGraph(node_cost[:, :10], curve, points[:10], adjacency.tocsr()[:10, :10], topology=topology)


def test_mean_feature_distance_equals_the_mean_of_the_distance_matrix():
    """The sorted-sums mean against the full L1 matrix, with repeated values (ties in the sort) and on
    features of unequal counts."""
    rng = np.random.default_rng(5)
    a = rng.random((37, 6))
    b = rng.random((150, 6))
    b[:20] = b[20:40]  # repeated rows
    a[:5, :] = b[:5, :]  # values equal to the mesh's
    assert mean_feature_distance(a, b) == pytest.approx(feature_distances(a, b).mean(), rel=1e-12)
    assert mean_feature_distance(b, a) == pytest.approx(feature_distances(b, a).mean(), rel=1e-12)
    with pytest.raises(InputError, match="feature dimensions"):
        mean_feature_distance(a, b[:, :4])


@pytest.mark.parametrize("metric", ["euclidean", "max"])
@pytest.mark.parametrize("seed", range(4))
def test_layered_dijkstra_distances_equal_dijkstra_on_the_explicit_graph(seed, metric):
    """Every node's distance from a set of starts, as SciPy's Dijkstra finds it on the explicit product graph
    (directed penalties included); with an exact heuristic and a bound, every node on a path below the bound
    keeps its exact distance and the rest are never below theirs (the pruning loses no path that matters)."""
    node_cost, curve, points, adjacency = tiny_instance(seed, 9, 1)
    rng = np.random.default_rng(300 + seed)
    node_cost[rng.random(node_cost.shape) < 0.05] = np.inf  # forbidden nodes
    graph = ProductGraph(node_cost, curve, points, adjacency, metric=metric,
                         edge_penalty=directed_penalties(seed, adjacency))
    m, n = graph.m, graph.n
    sources = rng.random(n) < 0.3
    sources[rng.integers(n)] = True
    everything = np.ones(n, dtype=bool)
    explicit = dijkstra(explicit_product_matrix(graph), directed=True, indices=np.flatnonzero(sources)).min(axis=0)
    explicit = explicit.reshape(m + 1, n)
    cost, start, end = graph.shortest(sources, everything)
    np.testing.assert_allclose(graph.dist, explicit, rtol=1e-12, atol=1e-12)
    assert cost == pytest.approx(explicit[m].min(), rel=1e-12) and sources[start]
    # pruned: the exact cost-to-go as heuristic, a bound a little above the optimum
    graph.compute_heuristic()
    to_go = graph.heuristic.copy()
    upper = 1.05 * cost
    pruned_cost, _, _ = graph.shortest(sources, everything, upper)
    assert pruned_cost == pytest.approx(cost, rel=1e-12)
    needed = explicit + to_go < upper
    assert needed.sum() > m  # the bound leaves more than one path's worth of nodes
    np.testing.assert_allclose(graph.dist[needed], explicit[needed], rtol=1e-12, atol=1e-12)
    assert np.all(graph.dist[~needed] >= explicit[~needed] - 1e-12)


@pytest.mark.parametrize("metric", ["euclidean", "max"])
@pytest.mark.parametrize("seed", range(6))
def test_branch_and_bound_equals_brute_force(seed, metric):
    graph = ProductGraph(*tiny_instance(seed), metric=metric)
    exact = explicit_product_optimum(graph)
    result = run(branch_and_bound(graph))
    assert result.energy == pytest.approx(exact, rel=1e-12)
    assert result.lower_bound == pytest.approx(exact, rel=1e-12)
    assert graph.path_energy(result.path) == pytest.approx(result.energy, rel=1e-12)
    for eps in (0.05, 0.3):
        approx = run(branch_and_bound(ProductGraph(*tiny_instance(seed), metric=metric), eps=eps))
        assert exact <= approx.energy <= (1 + eps) * exact + 1e-12
        assert approx.lower_bound <= exact + 1e-12


@pytest.mark.parametrize("seed", range(3))
def test_the_certificate_says_what_the_search_proves(seed):
    """Optimal, within the ε bound, or stopped at the iteration cap: the last was reported as "within the ε
    bound" (with ε = 0), so a capped search passed for an answer (brute force says which it is)."""
    from corrlib.methods.base import SearchCertificate

    exact = explicit_product_optimum(ProductGraph(*tiny_instance(seed)))
    full = SearchCertificate.of(run(branch_and_bound(ProductGraph(*tiny_instance(seed)))))
    assert full.optimal and full.within_bound and full.describe() == "proven optimal"
    eps = 0.3
    approx = SearchCertificate.of(run(branch_and_bound(ProductGraph(*tiny_instance(seed)), eps=eps)), eps)
    assert approx.within_bound and approx.upper_bound <= (1 + eps) * exact + 1e-12
    assert approx.optimal or "within the ε = 0.3 bound" in approx.describe()
    capped = SearchCertificate.of(run(branch_and_bound(ProductGraph(*tiny_instance(seed)), max_iterations=1)))
    assert capped.lower_bound <= exact + 1e-12 <= capped.upper_bound + 2e-12  # valid bounds
    assert capped.within_bound == capped.optimal == (capped.lower_bound >= capped.upper_bound)  # ε = 0
    assert ("NOT proven optimal" in capped.describe()) == (not capped.within_bound)
    if seed < 2:  # on these instances one iteration finds the optimum but cannot prove it
        assert not capped.within_bound


def test_a_capped_search_is_reported_as_not_proven(capsys, tmp_path):
    """Through the CLI, a contour matched with too few iterations is said to be not proven optimal."""
    from _data import SKETCH2D
    from corrlib.cli import main

    argv = ["match-contour", SKETCH2D / "human_sketch_a_contour.txt", TOSCA / "wolf0.off", "--param",
            "max_iterations=1", "-o", tmp_path / "r", "-q"]
    assert main(list(map(str, argv))) == 0
    out = capsys.readouterr().out
    assert "NOT proven optimal: the search stopped at its iteration cap" in out


def directed_penalties(seed, adjacency) -> sp.csr_matrix:
    """Random non-negative penalties per unit length, different for j -> k and k -> j (half of them zero)."""
    rng = np.random.default_rng(100 + seed)
    pattern = sp.csr_matrix(adjacency)
    pattern = (pattern + pattern.T).tocoo()
    values = rng.random(pattern.nnz) * (rng.random(pattern.nnz) < 0.5)
    return sp.csr_matrix((values, (pattern.row, pattern.col)), shape=pattern.shape)


def relaxed_family(seed, scales=(1.0, 1.0, 3.0, 3.0), metric="euclidean"):
    """Graphs on one curve and graph (a union's readings): node costs scaled and perturbed per reading, pairs
    of readings (0, 1), (2, 3) sharing node costs and differing by their directed penalties, as the two
    halves of a side view do; and a tree of relaxations over them, one per pair below one for all."""
    node_cost, curve, points, adjacency = tiny_instance(seed, 7, 1)
    rng = np.random.default_rng(200 + seed)
    graphs = []
    for pair in range(len(scales) // 2):
        cost = scales[2 * pair] * (node_cost + 0.3 * rng.random(node_cost.shape))
        for half in range(2):
            penalty = directed_penalties(seed + 10 * pair + half, adjacency)
            graphs.append(ProductGraph(cost, curve, points, adjacency, edge_penalty=penalty, metric=metric))
    pairs = [Relaxation(ProductGraph.relaxation(graphs[k:k + 2]), [k, k + 1]) for k in range(0, len(graphs), 2)]
    return graphs, [Relaxation(ProductGraph.relaxation(graphs), pairs)]


@pytest.mark.parametrize("metric", ["euclidean", "max"])
@pytest.mark.parametrize("seed", range(4))
def test_a_tree_of_relaxations_finds_the_same_optimum_with_fewer_backward_searches(seed, metric):
    """Branch-and-bound over a union with relaxations: the optimum of the explicit product graphs, the same as
    without them, certified; a relaxation's costs and heuristic are below each graph's; a pair of readings
    that cannot win (costs 3x) is never searched."""
    from corrlib.geometry.cyclic_paths import branch_and_bound_union

    graphs, tree = relaxed_family(seed, metric=metric)
    assert tree[0].graph.metric == metric
    exact = [explicit_product_optimum(g) for g in graphs]
    relaxed = tree[0].graph
    for graph in graphs:
        assert np.all(relaxed.cost <= graph.cost) and np.all(relaxed.extra == 0)
        graph.compute_heuristic()
    relaxed.compute_heuristic()
    assert all(np.all(relaxed.heuristic <= g.heuristic + 1e-12) for g in graphs)
    graphs, tree = relaxed_family(seed, metric=metric)
    result = run(branch_and_bound_union(graphs, relaxations=tree))
    assert result.energy == pytest.approx(min(exact), rel=1e-12)
    assert result.lower_bound == pytest.approx(result.energy, rel=1e-12)
    assert graphs[result.graph_index].path_energy(result.path) == pytest.approx(result.energy, rel=1e-12)
    plain = run(branch_and_bound_union(relaxed_family(seed, metric=metric)[0]))
    assert plain.energy == pytest.approx(result.energy, rel=1e-12)
    assert result.graph_index in (0, 1)
    assert graphs[2].runs == graphs[3].runs == 0, "a pair whose bound exceeds the optimum was searched"
    threads = numba.get_num_threads()
    try:  # one search at a time: the round's backward searches one after the other, the same optimum
        numba.set_num_threads(1)
        graphs, tree = relaxed_family(seed, metric=metric)
        assert run(branch_and_bound_union(graphs, relaxations=tree)).energy == pytest.approx(min(exact), rel=1e-12)
    finally:
        numba.set_num_threads(threads)
    for eps in (0.05, 0.3):
        graphs, tree = relaxed_family(seed, metric=metric)
        approx = run(branch_and_bound_union(graphs, relaxations=tree, eps=eps))
        assert min(exact) <= approx.energy <= (1 + eps) * min(exact) + 1e-12
    graphs, tree = relaxed_family(seed, metric=metric)
    ratio = run(minimum_ratio_union(graphs, relaxations=tree))
    assert ratio.energy == pytest.approx(run(minimum_ratio_union(relaxed_family(seed, metric=metric)[0])).energy, rel=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_a_backward_search_bounded_by_a_relaxations_forward_distances_is_exact_where_it_matters(seed):
    """Below an upper bound U, with a relaxation's forward distances f: every node's pruned heuristic equals
    the complete one, except where no path through the node beats U (f + h >= U), where it is inf; and some
    nodes are skipped."""
    graphs, tree = relaxed_family(seed)
    relaxed, graph = tree[0].graph, graphs[1]
    graph.compute_heuristic()
    complete = graph.heuristic.copy()
    relaxed.compute_heuristic()
    everything = np.ones(relaxed.n, dtype=bool)
    optimum = explicit_product_optimum(graph)
    upper = 1.05 * optimum
    relaxed.shortest(everything, everything, upper)
    forward = relaxed.dist.copy()
    graph.compute_heuristic(upper=upper, cost_to_come=forward)
    pruned = graph.heuristic
    kept = np.isfinite(pruned)
    assert np.allclose(pruned[kept], complete[kept], rtol=1e-12)
    assert np.all(forward[~kept] + complete[~kept] >= upper - 1e-9)
    assert 0 < kept.sum() < kept.size
    assert float(np.min(pruned[0])) == pytest.approx(float(np.min(complete[0])), rel=1e-12)


def test_relaxations_must_cover_each_graph_once_and_share_the_product():
    from corrlib.geometry.cyclic_paths import branch_and_bound_union

    graphs, tree = relaxed_family(0)
    with pytest.raises(ParameterError, match="at most one relaxation"):
        run(branch_and_bound_union(graphs, relaxations=tree + [Relaxation(tree[0].graph, [0])]))
    with pytest.raises(ParameterError, match="at most one relaxation"):
        run(branch_and_bound_union(graphs, relaxations=[Relaxation(tree[0].graph, [0, 7])]))
    with pytest.raises(InputError, match="share the curve"):
        ProductGraph.relaxation([graphs[0], tiny_graph(1, m=8)])


@pytest.mark.parametrize("seed", range(4))
def test_directed_edge_penalties_keep_the_search_exact(seed):
    """Penalties that depend on the direction of a graph edge (the side view's wrong-way cost): the
    branch-and-bound optimum equals the explicit product graph's, the heuristic's backward search stays
    admissible (it walks each edge with its forward penalty), the energy recomputed edge by edge agrees,
    and the closing detour pays the penalties too."""
    node_cost, curve, points, adjacency = tiny_instance(seed, 7, 1)
    penalty = directed_penalties(seed, adjacency)
    graph = ProductGraph(node_cost, curve, points, adjacency, edge_penalty=penalty)
    assert np.any(graph.extra > 0)
    exact = explicit_product_optimum(graph)
    result = run(branch_and_bound(graph))
    assert result.energy == pytest.approx(exact, rel=1e-12)
    assert graph.path_energy(result.path) == pytest.approx(result.energy, rel=1e-12)
    plain = ProductGraph(node_cost, curve, points, adjacency)
    assert exact >= explicit_product_optimum(plain) - 1e-12  # penalties only add
    # the same penalties walked the other way round are a different problem: reversing the curve and the
    # penalties' direction together gives back the same optimum
    reversed_graph = ProductGraph(node_cost[np.r_[0, 6:0:-1]], curve[np.r_[0, 6:0:-1]], points, adjacency,
                                  edge_penalty=penalty.T)
    assert run(branch_and_bound(reversed_graph)).energy == pytest.approx(exact, rel=1e-12)
    everything = np.ones(graph.n, dtype=bool)
    _, _, t = graph.shortest(everything, everything)
    energy, closed = graph.close_by_detour(graph.backtrack(t))
    assert energy == pytest.approx(graph.path_energy(closed), rel=1e-12)
    ratio = run(minimum_ratio_union([ProductGraph(node_cost, curve, points, adjacency, edge_penalty=penalty)]))
    assert explicit_product_optimum(graph, ratio.energy) == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(InputError, match="non-negative"):
        ProductGraph(node_cost, curve, points, adjacency, edge_penalty=-penalty)


@pytest.mark.parametrize("seed", range(4))
def test_minimum_ratio_equals_bisection_on_the_explicit_graph(seed):
    """The Dinkelbach search against a bisection of the ratio on the explicit graph (the optimal ratio is
    the gain at which the best closed path of E - gain * D costs zero)."""
    graph = tiny_graph(seed)
    result = run(minimum_ratio_union([graph]))
    low, high = 0.0, 100.0
    for _ in range(60):
        middle = 0.5 * (low + high)
        low, high = (low, middle) if explicit_product_optimum(graph, middle) < 0 else (middle, high)
    assert result.energy == pytest.approx(0.5 * (low + high), rel=1e-9)
    assert result.lower_bound == result.upper_bound == result.energy
    # the path attains the ratio: energy and credited length recomputed edge by edge
    assert graph.gain == 0.0
    path = result.path
    assert graph.path_energy(path) / graph.credited_length(path) == pytest.approx(result.energy, rel=1e-12)
    assert path.vertices[0] == path.vertices[-1] and path.layers[0] == 0 and path.layers[-1] == graph.m
    # a (1 + eps)-approximation stays within its factor and its bound holds
    approx = run(minimum_ratio_union([tiny_graph(seed)], eps=0.3))
    assert result.energy - 1e-12 <= approx.energy <= 1.3 * result.energy
    assert approx.lower_bound <= result.energy + 1e-12
    with pytest.raises(ParameterError, match="eps"):
        run(minimum_ratio_union([tiny_graph(seed)], eps=1.5))
    with pytest.raises(ParameterError, match="at least one product graph"):
        run(minimum_ratio_union([]))


def test_ratio_does_not_collapse_where_the_paper_energy_must():
    """Analytic case: constant node cost c, a regular 12-gon of side a against a ring graph of the same edge
    length. The paper's optimum stays on one vertex (energy c L, every move costs c a sqrt 2 instead of c a);
    it is credited no length. The ratio's optimum moves on every step (b = a): ratio c sqrt 2."""
    m, n, c = 12, 10, 0.7
    side = 0.3
    t = 2 * np.pi * np.arange(m) / m
    curve = side / (2 * np.sin(np.pi / m)) * np.column_stack([np.cos(t), np.sin(t)])
    u = 2 * np.pi * np.arange(n) / n
    ring = side / (2 * np.sin(np.pi / n)) * np.column_stack([np.cos(u), np.sin(u), np.zeros(n)])
    adjacency = sp.coo_matrix((np.ones(n), (np.arange(n), (np.arange(n) + 1) % n)), shape=(n, n))
    paper = run(branch_and_bound(ProductGraph(np.full((m, n), c), curve, ring, adjacency)))
    assert paper.energy == pytest.approx(c * m * side, rel=1e-12)
    assert len(np.unique(paper.path.vertices)) == 1
    graph = ProductGraph(np.full((m, n), c), curve, ring, adjacency)
    ratio = run(minimum_ratio_union([graph]))
    assert ratio.energy == pytest.approx(c * np.sqrt(2), rel=1e-12)
    assert graph.credited_length(ratio.path) == pytest.approx(m * side, rel=1e-12)


def test_the_max_metric_follows_a_curve_that_the_euclidean_metric_collapses():
    """Analytic case: a regular 12-gon against a ring of 12 vertices with the same edge length, node cost c
    everywhere but (1 - δ) c on the diagonal (point i on vertex i). Keeping pace along the diagonal costs
    (1 - δ) c a per step under the max metric, the least any step can cost, so it is the optimum; under the
    paper's Euclidean metric it costs (1 - δ) c a √2 > c a, and the optimum stands still on one vertex."""
    m, c, delta, side = 12, 0.7, 0.2, 0.3
    t = 2 * np.pi * np.arange(m) / m
    radius = side / (2 * np.sin(np.pi / m))
    curve = radius * np.column_stack([np.cos(t), np.sin(t)])
    ring = radius * np.column_stack([np.cos(t), np.sin(t), np.zeros(m)])
    adjacency = sp.coo_matrix((np.ones(m), (np.arange(m), (np.arange(m) + 1) % m)), shape=(m, m))
    cost = np.full((m, m), c)
    cost[np.arange(m), np.arange(m)] = (1 - delta) * c
    follows = run(branch_and_bound(ProductGraph(cost, curve, ring, adjacency, metric="max")))
    assert follows.energy == pytest.approx((1 - delta) * c * m * side, rel=1e-12)
    assert np.array_equal(np.sort(np.unique(follows.path.vertices)), np.arange(m))
    collapsed = run(branch_and_bound(ProductGraph(cost, curve, ring, adjacency)))
    assert len(np.unique(collapsed.path.vertices)) == 1
    assert collapsed.energy == pytest.approx(c * m * side - delta * c * side, rel=1e-12)
    with pytest.raises(ParameterError, match="metric"):
        ProductGraph(cost, curve, ring, adjacency, metric="manhattan")


def test_branch_and_bound_splits_regions():
    # costs that make the cheapest open path end elsewhere than it starts force real branching
    graph = tiny_graph(11, m=9, subdivisions=2)
    graph.cost[:] = np.random.default_rng(5).random(graph.cost.shape) ** 4
    graph.cost[-1] = graph.cost[0]
    exact = explicit_product_optimum(graph)
    result = run(branch_and_bound(graph))
    assert result.energy == pytest.approx(exact, rel=1e-12)
    assert result.dijkstra_runs >= 1


def test_parameter_and_cancel_errors():
    graph = tiny_graph(0)
    with pytest.raises(ParameterError, match="eps"):
        run(branch_and_bound(graph, eps=1.5))
    token = CancelToken()
    token.cancel()
    with pytest.raises(Cancelled):
        run(branch_and_bound(graph, token=token))
    with pytest.raises(InputError, match="non-negative"):
        ProductGraph(-np.ones((3, 42)), np.eye(3)[:, :2], np.zeros((42, 3)), sp.eye(42))


def silhouette_with_ground_truth(mesh, resolution=400):
    """Side view silhouette (projection onto the plane of the two longest principal axes) and the projection
    of the vertices that gives its ground truth (:func:`rim_vertices`: a silhouette cannot tell the near side
    from the far side, so both the nearest and the farthest rim vertex count)."""
    centred = mesh.vertices - mesh.vertices.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    view, up = vt[2], vt[1]
    return rendered_view(mesh, view, resolution, up=up)


@pytest.fixture(scope="module")
def wolf_silhouette_match(wolf_pair):
    wolf0, wolf1 = wolf_pair
    contour, projection = silhouette_with_ground_truth(wolf0)
    result = solve("contour3d", contour, wolf1, n_contour=120)
    return contour, projection, result


def test_path_is_a_valid_closed_matching(wolf_silhouette_match, wolf_pair):
    """On the mesh as given, the path walks along its edges (remeshed, the default, the path is on the
    remeshed mesh's edges and reported on the nearest input vertices)."""
    contour, _, _ = wolf_silhouette_match
    wolf1 = wolf_pair[1]
    result = solve("contour3d", contour, wolf1, n_contour=120, mesh_vertices=0)
    verts, layers = result.path.vertices, result.path.layers
    m = 120
    assert verts[0] == verts[-1] and layers[0] == 0 and layers[-1] == m
    steps = np.diff(layers)
    assert set(np.unique(steps)) <= {0, 1}
    assert set(layers) == set(range(m + 1))
    adj = wolf1.adjacency
    moved = verts[1:] != verts[:-1]
    assert all(adj[a, b] > 0 for a, b in zip(verts[:-1][moved], verts[1:][moved]))
    assert result.map_xy.shape == (m,) and result.map_xy.min() >= 0
    assert result.search.optimal and result.energy == pytest.approx(result.search.lower_bound)


def test_silhouette_matches_its_shape_in_another_pose(wolf_silhouette_match, wolf_pair):
    """Ground truth by projection: the silhouette of wolf0 matched to wolf1 (same vertex order).

    The query is the outline of wolf0's projection onto the plane of its two longest principal axes; its
    ground truth are the rim vertices that project onto each outline point. Thresholds: measured median
    0.09, mean 0.11 and 58 % of points within 0.1 (errors / sqrt(area), the nearer of the near-side and
    far-side rim vertex); random vertices are ~0.5 away. A silhouette outline carries no left/right information and
    the paper's intrinsic features are blind to it, so the symmetric error is the meaningful one; legs
    that overlap in the projection keep a tail of large errors.
    """
    contour, projection, result = wolf_silhouette_match
    wolf1 = wolf_pair[1]
    points = contour.ccw().resample(120).points
    near, far = rim_vertices(points, projection).T
    solver = GeodesicSolver(wolf1)
    err = np.minimum(solver.pair_distances(result.map_xy, near), solver.pair_distances(result.map_xy, far))
    err /= np.sqrt(wolf1.area)
    assert np.median(err) < 0.15, np.median(err)
    assert err.mean() < 0.2, err.mean()
    assert np.mean(err < 0.1) > 0.4, np.mean(err < 0.1)
    # far better than chance: random vertices are ~0.5 away
    random_err = solver.pair_distances(np.random.default_rng(0).integers(0, wolf1.n_vertices, 120), near)
    assert np.median(err) < 0.4 * np.median(random_err / np.sqrt(wolf1.area))


def test_result_is_invariant_to_similarity_transforms(wolf_pair):
    wolf0, wolf1 = wolf_pair
    contour, _ = silhouette_with_ground_truth(wolf0, resolution=200)
    base = solve("contour3d", contour, wolf1, n_contour=60, eps=0.0, mesh_vertices=0)
    moved_contour = contour.transformed(scale=0.013, rotation=1.1, translation=(40.0, -7.0))
    rot = trimesh.transformations.random_rotation_matrix(np.random.default_rng(2).random(3))[:3, :3]
    moved_mesh = TriMesh(3.7 * wolf1.vertices @ rot.T + [1, 2, 3], wolf1.faces, name="moved")
    other = solve("contour3d", moved_contour, moved_mesh, n_contour=60, eps=0.0, mesh_vertices=0)
    # the even eigenpairs and the side view's symmetry-curve cost come from a reflection estimated by least
    # squares on each mesh: equal to ~1e-5
    assert other.energy == pytest.approx(base.energy, rel=2e-5)
    assert np.mean(other.map_xy == base.map_xy) > 0.95
    # remeshed (the default), the two are triangulated differently: the collapse's order follows the vertices'
    # positions. The energy moves by the triangulation's share (measured 2 %), not more.
    remeshed_base = solve("contour3d", contour, wolf1, n_contour=60, eps=0.0)
    remeshed_other = solve("contour3d", moved_contour, moved_mesh, n_contour=60, eps=0.0)
    assert remeshed_other.energy == pytest.approx(remeshed_base.energy, rel=0.05)


def test_result_is_invariant_to_a_mirrored_and_reordered_mesh(wolf_pair):
    """A mirror image of the mesh with shuffled vertices has the same intrinsic geometry: the eigenfunctions
    change sign and order only (the axis may come out reversed, and both readings are searched), so the
    optimal energy is the same and the matched vertices are the images of the same vertices."""
    wolf0, wolf1 = wolf_pair
    contour, _ = silhouette_with_ground_truth(wolf0, resolution=200)
    base = solve("contour3d", contour, wolf1, n_contour=60, mesh_vertices=0)
    perm = np.random.default_rng(4).permutation(wolf1.n_vertices)
    inverse = np.argsort(perm)
    mirrored = TriMesh(wolf1.vertices[perm] * [-1.0, 1.0, 1.0], inverse[wolf1.faces][:, ::-1], name="mirrored")
    other = solve("contour3d", contour, mirrored, n_contour=60, mesh_vertices=0)
    # the even eigenpairs come from a reflection estimated by least squares on each mesh: equal to ~1e-6
    assert other.energy == pytest.approx(base.energy, rel=1e-5)
    assert np.mean(perm[other.map_xy] == base.map_xy) > 0.95


@pytest.mark.slow
def test_energy_is_comparable_across_resolutions(wolf_pair):
    """Retrieval ranks meshes by energy, so another mesh of the same shape must not change the energy much.

    On the product graph a contour step longer than the mesh's edges pays the rest of its way within a layer
    (max metric), so a finer graph costs more: matched as given (60 points), wolf1 subdivided at its edge
    midpoints costs 13 % more, Loop-subdivided twice 22 % more, and quadric-decimated to half 6 % less,
    a spread of 1.30, while cat1 costs 21 % more than wolf1. Every mesh is therefore matched remeshed to
    ``mesh_vertices`` (5,000): measured spread 1.05, cat1 15 % above the dearest; the curve is reported on
    the input mesh.
    """
    import fast_simplification

    from corrlib.geometry.remeshing import without_degenerate_faces

    wolf0, wolf1 = wolf_pair
    contour, _ = silhouette_with_ground_truth(wolf0, resolution=200)
    fine = trimesh.Trimesh(wolf1.vertices, wolf1.faces, process=False).subdivide()  # flat: the collapse's hard case
    smooth = trimesh.remesh.subdivide_loop(wolf1.vertices, wolf1.faces, iterations=2)
    half = fast_simplification.simplify(np.array(wolf1.vertices), np.array(wolf1.faces, dtype=np.int32),
                                        target_count=wolf1.n_faces // 2)
    meshes = {"wolf1": wolf1, "fine": TriMesh(fine.vertices, fine.faces, name="fine"),
              "smooth": TriMesh(*smooth, name="smooth"),
              "half": TriMesh(*without_degenerate_faces(half[0], half[1].astype(np.int64)), name="half"),
              "cat1": load_mesh(TOSCA / "cat1.off")}
    results = {name: solve("contour3d", contour, mesh, n_contour=60, eps=0.05) for name, mesh in meshes.items()}
    energies = {name: result.energy for name, result in results.items()}
    wolves = [energies[name] for name in ("wolf1", "fine", "smooth", "half")]
    assert max(wolves) / min(wolves) < 1.1, energies
    assert max(wolves) < 0.95 * energies["cat1"], energies
    for name, mesh in meshes.items():  # matched remeshed, reported on the input mesh
        result = results[name]
        assert 4950 <= result.extras["matched_vertices"] <= 5050 and result.extras["input_vertices"] == mesh.n_vertices
        assert result.map_xy.max() < mesh.n_vertices and result.path.vertices.max() < mesh.n_vertices
        assert "remeshed from" in result.energy_meaning
    assert results["fine"].path.vertices.max() >= 5000  # input indices, not the remeshed mesh's
    # what the remeshing removes: 1.20 measured over these three (1.30 with the smooth copy, left out here: its
    # 70k vertices matched as given took most of this test's time)
    as_given = [solve("contour3d", contour, meshes[name], n_contour=60, eps=0.05, mesh_vertices=0).energy
                for name in ("wolf1", "fine", "half")]
    assert max(as_given) / min(as_given) > 1.15, as_given


@pytest.mark.slow
def test_a_remeshed_match_does_not_depend_on_the_vertex_order(wolf_pair):
    """Quadric collapse breaks ties of equal cost by the input's order, and a flat subdivision has many; the
    surface is put in a canonical order first, so a shuffled copy gives the same match exactly."""
    wolf0, wolf1 = wolf_pair
    contour, _ = silhouette_with_ground_truth(wolf0, resolution=200)
    flat = trimesh.Trimesh(wolf1.vertices, wolf1.faces, process=False).subdivide()
    fine = TriMesh(flat.vertices, flat.faces, name="fine")
    perm = np.random.default_rng(5).permutation(fine.n_vertices)
    shuffled = TriMesh(fine.vertices[perm], np.argsort(perm)[fine.faces], name="shuffled")
    base = solve("contour3d", contour, fine, n_contour=60)
    other = solve("contour3d", contour, shuffled, n_contour=60)
    assert other.energy == base.energy
    assert np.array_equal(perm[other.map_xy], base.map_xy)


@pytest.mark.slow
def test_a_remeshed_match_does_not_depend_on_units_or_position(wolf_pair):
    """The collapse runs at unit area about the mesh's centre (the package's thresholds are absolute: before,
    the same 20k cat in metres and in micrometres was decimated differently, 92.8 against 89.6). Equal up to
    rounding, which can flip the order of two collapses of equal cost."""
    wolf0, wolf1 = wolf_pair
    contour, _ = silhouette_with_ground_truth(wolf0, resolution=200)
    fine = trimesh.remesh.subdivide_loop(wolf1.vertices, wolf1.faces, iterations=1)
    energies = [solve("contour3d", contour, TriMesh(fine[0] * scale + offset, fine[1], name="fine"),
                      n_contour=60).energy for scale, offset in ((1.0, 0.0), (1e-6, 0.0), (1e3, 1e8))]
    assert np.allclose(energies, energies[0], rtol=2e-3), energies


def test_a_mesh_that_cannot_be_remeshed_is_matched_as_given(wolf_pair, monkeypatch):
    import corrlib.methods.contour3d as contour3d
    from corrlib.errors import MeshError

    def refuse(mesh, mesh_vertices):
        raise MeshError(f"{mesh.name}: remeshing gave an invalid mesh (test)")

    wolf0, wolf1 = wolf_pair
    contour, _ = silhouette_with_ground_truth(wolf0, resolution=200)
    base = solve("contour3d", contour, wolf1, n_contour=60, mesh_vertices=0)
    monkeypatch.setattr(contour3d, "remeshed", refuse)
    result = solve("contour3d", contour, wolf1, n_contour=60, mesh_vertices=1000)
    assert "invalid mesh (test)" in result.extras["remeshing_failed"]
    assert result.energy == base.energy and np.array_equal(result.map_xy, base.map_xy)


def test_the_vertex_budget_is_checked():
    from corrlib.methods.base import make_params
    from corrlib.methods.contour3d import Contour3DParams

    for bad in (1, 100, 499, -1):
        with pytest.raises(ParameterError, match="mesh_vertices"):
            make_params(Contour3DParams, mesh_vertices=bad)
    assert make_params(Contour3DParams, mesh_vertices=0).mesh_vertices == 0
    assert make_params(Contour3DParams, mesh_vertices=500).mesh_vertices == 500


def test_part_labels_add_tau():
    feats_c = np.zeros((3, 2))
    feats_m = np.array([[0.0, 0.0], [1.0, 2.0]])
    cost = node_costs(feats_c, feats_m, np.array([0, 1, 2]), np.array([1, 2]), tau=100.0)
    assert np.allclose(cost, [[0, 3], [0, 103], [100, 3]])


def test_part_labels_constrain_the_match(wolf_pair):
    wolf0, wolf1 = wolf_pair
    contour, _ = silhouette_with_ground_truth(wolf0, resolution=200)
    c = contour.ccw().resample(80)
    # label the front and back halves on both shapes (along the longest axis)
    axis = np.linalg.svd(wolf1.vertices - wolf1.vertices.mean(0), full_matrices=False)[2][0]
    mesh_labels = np.where((wolf1.vertices - wolf1.vertices.mean(0)) @ axis > 0, 1, 2)
    x = c.points[:, 0] - c.points[:, 0].mean()
    labelled = Contour2D(c.points, labels=np.where(x > 0, 1, 2))
    for flip in (False, True):
        lab = mesh_labels if not flip else 3 - mesh_labels
        result = solve("contour3d", labelled, wolf1.with_labels(lab), n_contour=80, eps=0.05)
        agree = np.mean(lab[result.map_xy] == labelled.labels)
        assert agree > 0.9, (flip, agree)


def test_plane_section_loops(wolf_pair):
    wolf0 = wolf_pair[0]
    centre = wolf0.vertices.mean(axis=0)
    normal = np.linalg.svd(wolf0.vertices - centre, full_matrices=False)[2][2]
    loops = plane_section(wolf0, centre, normal)
    assert loops
    lp = loops[0]
    # points lie in the plane and on their edges
    assert np.allclose((lp.points - centre) @ (normal / np.linalg.norm(normal)), 0, atol=1e-9)
    v = wolf0.vertices
    assert np.allclose(lp.points, (1 - lp.weights)[:, None] * v[lp.edges[:, 0]] + lp.weights[:, None] * v[lp.edges[:, 1]])
    assert np.all((lp.weights >= 0) & (lp.weights <= 1))
    Contour2D(lp.points_2d)  # a valid simple closed contour


@pytest.mark.slow
def test_retrieval_ranks_the_class_first():
    meshes = [TOSCA / "cat0.off", TOSCA / "cat1.off", TOSCA / "wolf0.off", TOSCA / "wolf1.off",
              SUMNER / "lion-00.off"]
    rankings = []
    for query_mesh, jobs in (("wolf0", 2), ("cat0", 1)):
        contour, _ = silhouette_with_ground_truth(load_mesh(TOSCA / f"{query_mesh}.off"), resolution=300)
        progress = []
        hits = run(retrieve(contour, meshes, jobs=jobs), callback=progress.append)
        assert len(progress) >= len(meshes)
        labels = [h.label for h in hits]
        assert labels[:2] == [class_of(query_mesh)] * 2, [(h.path.name, h.energy) for h in hits]
        assert all(h.error == "" and np.isfinite(h.energy) for h in hits)
        rankings.append((class_of(query_mesh), labels))
    assert mean_average_precision(rankings) == pytest.approx(1.0)


def test_retrieval_reports_broken_meshes(tmp_path):
    (tmp_path / "broken3.off").write_text("OFF\n3 1 0\n0 0 0\n")
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    hits = run(retrieve(Contour2D(np.column_stack([np.cos(t), np.sin(t)])),
                        [tmp_path / "broken3.off", TOSCA / "wolf0.off"], jobs=1))
    assert hits[0].path.name == "wolf0.off" and np.isinf(hits[1].energy) and "broken3.off" in hits[1].error


def test_retrieval_takes_a_folder_files_or_loaded_meshes_alike(tmp_path):
    """A script's collection can be a folder (its meshes and subfolders, named within it), a list of files or
    meshes already loaded (named by their ``name``): the same scores in the same order. A loaded mesh was taken
    for a file name and failed as "file not found" at the end of the ranking."""
    import shutil

    (tmp_path / "wolves").mkdir()
    for name in ("wolf0.off", "wolf1.off"):
        shutil.copy(TOSCA / name, tmp_path / "wolves" / name)
    shutil.copy(TOSCA / "cat0.off", tmp_path / "cat0.off")
    files = [tmp_path / "cat0.off", tmp_path / "wolves" / "wolf0.off", tmp_path / "wolves" / "wolf1.off"]
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    query = Contour2D(np.column_stack([np.cos(t), 0.4 * np.sin(t)]))
    params = retrieval_params(n_contour=40, mesh_vertices=2000)
    by_folder = run(retrieve(query, tmp_path, params, jobs=1, ranking="energy"))
    by_files = run(retrieve(query, files, params, jobs=1, ranking="energy"))
    loaded = run(retrieve(query, [load_mesh(f) for f in files], params, jobs=1, ranking="energy"))
    assert [hit.name for hit in by_folder] == [f"wolves/{h.path.name}" if "wolf" in h.path.name else h.path.name
                                               for h in by_files]
    assert [hit.label for hit in by_folder if "wolf" in hit.name] == ["wolves", "wolves"]
    assert all(hit.error == "" for hit in loaded)
    for hits in (by_folder, loaded):
        assert [h.path.name for h in hits] == [h.path.name for h in by_files]
        assert [h.energy for h in hits] == pytest.approx([h.energy for h in by_files], rel=1e-9)
    assert "path_vertices" not in repr(loaded[0])  # a hit prints in a line, not its arrays


def test_retrieval_does_not_rank_flat_sketches(tmp_path):
    """A flat triangulated sketch in a collection is a drawing, not a 3D shape: it is left out of the ranking with
    its reason in the progress, also when its plane is turned away from the coordinate axes; a collection of
    flat meshes alone is refused by name."""
    from corrlib.io import save_mesh
    from corrlib.resources import resource
    from corrlib.retrieval import FLAT_CANDIDATE

    sketch = load_mesh(resource("data/sketch2d/human_sketch_a.off"))
    turn = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]
    save_mesh(tmp_path / "turned_sketch.off", sketch.vertices @ turn.T, sketch.faces)
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    query = Contour2D(np.column_stack([np.cos(t), 0.4 * np.sin(t)]))
    flat = [resource("data/sketch2d/human_sketch_a.off"), tmp_path / "turned_sketch.off"]
    said = []
    hits = run(retrieve(query, [*flat, TOSCA / "wolf0.off"], jobs=1, ranking="energy"), callback=said.append)
    assert [hit.path.name for hit in hits] == ["wolf0.off"] and np.isfinite(hits[0].energy)
    for path in flat:
        assert any(f"{path.name}: left out, {FLAT_CANDIDATE}" in report.message for report in said)
    with pytest.raises(InputError, match="no 3D mesh to rank"):
        run(retrieve(query, flat, jobs=1))


def test_average_precision_by_hand():
    assert class_of("cat0.off") == "cat" and class_of("lion-00.off") == "lion" and class_of("x/dog_12.ply") == "dog"
    assert average_precision(["a", "b", "a"], "a") == pytest.approx((1 + 2 / 3) / 2)
    assert average_precision(["b", "b"], "a") == 0.0


def test_the_princeton_measures_by_hand_and_against_their_definitions():
    """Nearest neighbour, first and second tier, E-measure and DCG (Shilane et al. 2004): one ranking worked by
    hand, the limits, and random rankings against a direct reading of each definition."""
    from corrlib.retrieval import ranking_measures

    # a b a a b for class a: C = 3; r(3) = 2, r(5) = 3; k = 5; DCG (1 + 1/log2 3 + 1/2) / (1 + 1 + 1/log2 3)
    measured = ranking_measures(list("abaab"), "a")
    dcg = (1 + 1 / np.log2(3) + 0.5) / (2 + 1 / np.log2(3))
    assert measured == pytest.approx({"nn": 1.0, "first_tier": 2 / 3, "second_tier": 1.0, "e_measure": 0.75,
                                      "dcg": dcg})
    assert ranking_measures(list("aabbb"), "a")["dcg"] == pytest.approx(1.0)
    assert ranking_measures(list("bbbaa"), "a")["nn"] == 0.0
    assert all(np.isnan(v) for v in ranking_measures(list("bbb"), "a").values())
    rng = np.random.default_rng(5)
    for _ in range(200):
        labels = list(rng.choice(["a", "b", "c"], size=int(rng.integers(1, 60))))
        if "a" not in labels:
            continue
        c = labels.count("a")
        got = ranking_measures(labels, "a")
        assert got["nn"] == (labels[0] == "a")
        assert got["first_tier"] == pytest.approx(labels[:c].count("a") / c)
        assert got["second_tier"] == pytest.approx(labels[:2 * c].count("a") / c)
        k = min(32, len(labels))
        hits = labels[:k].count("a")
        assert got["e_measure"] == pytest.approx(0.0 if hits == 0 else 2 / (k / hits + c / hits))
        dcg = sum((label == "a") / (np.log2(i) if i > 1 else 1.0) for i, label in enumerate(labels, 1))
        ideal = sum(1 / (np.log2(i) if i > 1 else 1.0) for i in range(1, c + 1))
        assert got["dcg"] == pytest.approx(dcg / ideal)


def test_the_interpolated_precision_by_hand_and_against_its_definition():
    """Interpolated precision at the 11 recall levels: a ranking worked by hand, a perfect one, and random
    rankings against the definition read directly (the highest precision at any rank whose recall reaches the
    level)."""
    from corrlib.retrieval import RECALL_LEVELS, interpolated_precision

    # a b a a b: precision 1, 1/2, 2/3, 3/4, 3/5 at recall 1/3, 1/3, 2/3, 1, 1
    assert interpolated_precision(list("abaab"), "a") == pytest.approx([1.0] * 4 + [0.75] * 7)
    assert interpolated_precision(list("aab"), "a") == pytest.approx([1.0] * 11)
    assert np.all(np.isnan(interpolated_precision(list("bb"), "a")))
    rng = np.random.default_rng(8)
    for _ in range(200):
        labels = list(rng.choice(["a", "b"], size=int(rng.integers(1, 40))))
        if "a" not in labels:
            continue
        c = labels.count("a")
        points = [(labels[:k].count("a") / c, labels[:k].count("a") / k) for k in range(1, len(labels) + 1)]
        expected = [max(p for r, p in points if r >= level - 1e-12) for level in RECALL_LEVELS]
        got = interpolated_precision(labels, "a")
        assert got == pytest.approx(expected) and np.all(np.diff(got) <= 1e-12)


def test_a_collection_is_read_with_its_subfolders_and_a_subfolder_names_the_class(tmp_path):
    """``collection/cat/0.off`` is class ``cat`` (class-per-folder benchmarks), ``collection/wolf3.off`` class
    ``wolf``; hidden folders and links to folders are left out; the names are relative to the collection."""
    from corrlib.retrieval import collection_name, mesh_files

    for name in ("cat/0.off", "cat/1.OBJ", "dog/deep/a.ply", "wolf3.off", ".trash/x.off", "cat/notes.txt"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("")
    (tmp_path / "again").symlink_to(tmp_path / "cat", target_is_directory=True)
    files = mesh_files(tmp_path)
    assert [collection_name(f, tmp_path) for f in files] == ["cat/0.off", "cat/1.OBJ", "dog/deep/a.ply", "wolf3.off"]
    assert [class_of(f, tmp_path) for f in files] == ["cat", "cat", "dog", "wolf"]
    assert class_of(tmp_path / "cat" / "0.off") == "0"  # without the collection's folder: the file name alone
    assert collection_name(TOSCA / "cat0.off", tmp_path) == "cat0.off"  # outside the collection
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no mesh files .* in it or its subfolders"):
        mesh_files(tmp_path / "empty")


def test_map_interval_against_the_exact_bootstrap_distribution():
    """The percentile bootstrap of a mean over two queries has an exact distribution: with APs 0 and 1 the
    resampled mean is Binomial(q, 1/2) / q."""
    from scipy.stats import binom

    from corrlib.retrieval import map_interval

    aps = [0.0, 1.0] * 5  # q = 10: the mean of a resample is k / 10, k ~ Binomial(10, 1/2)
    low, high = map_interval(aps, resamples=20000)
    assert (low, high) == (binom.ppf(0.025, 10, 0.5) / 10, binom.ppf(0.975, 10, 0.5) / 10)
    assert map_interval([0.7] * 6) == (pytest.approx(0.7), pytest.approx(0.7))  # no spread, no interval
    assert map_interval([0.2, 0.9, 0.5]) == map_interval([0.2, 0.9, 0.5])  # deterministic
    with pytest.raises(InputError, match="one finite AP"):
        map_interval([0.5, float("nan")])
    with pytest.raises(ParameterError, match="level"):
        map_interval([0.5], level=1.0)


def test_class_margin_by_hand():
    from corrlib.retrieval import class_margin

    labels = ["cat", "wolf", "cat", "human"]
    assert class_margin(labels, [100.0, 110.0, 120.0, 130.0], "cat") == pytest.approx(10 / 105)
    assert class_margin(labels, [100.0, 110.0, 120.0, 130.0], "wolf") == pytest.approx(-10 / 105)
    # a mesh that could not be matched (infinite energy) does not count; no matched mesh of a side: NaN
    assert class_margin(labels, [np.inf, 110.0, 120.0, 130.0], "cat") == pytest.approx(-10 / 115)
    assert np.isnan(class_margin(labels, [100.0, np.inf, 120.0, np.inf], "cat"))
    assert np.isnan(class_margin(["cat", "cat"], [1.0, 2.0], "cat"))


def test_bad_inputs(wolf_pair):
    wolf1 = wolf_pair[1]
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    with pytest.raises(ContourError, match="open contour"):
        Contour2D.from_open_points(np.column_stack([np.cos(t), np.sin(t)])[:25])
    with pytest.raises(ContourError, match="intersects itself"):
        Contour2D(np.column_stack([np.sin(t), np.sin(t) * np.cos(t)]))
    with pytest.raises(ContourError, match="at least 10"):
        Contour2D(np.column_stack([np.cos(t), np.sin(t)])[::5])
    with pytest.raises(ParameterError, match="n_contour"):
        solve("contour3d", Contour2D(np.column_stack([np.cos(t), np.sin(t)])), wolf1, n_contour=5)
    two = trimesh.util.concatenate([trimesh.creation.icosphere(2), trimesh.creation.box().apply_translation([4, 0, 0])])
    broken = TriMesh(two.vertices, two.faces, validate=False, name="two-parts")
    with pytest.raises(InputError, match="two-parts.*disconnected"):
        solve("contour3d", Contour2D(np.column_stack([np.cos(t), np.sin(t)])), broken, n_contour=20)


@pytest.mark.parametrize("energy", ["paper", "ratio"])
def test_energy_is_invariant_to_the_mirror_image_and_orientation_of_the_sketch(wolf_pair, energy):
    """A silhouette has no front and back: the mirrored sketch matches the same closed curve, traversed the
    other way, with the same energy (the features are intrinsic and the edge costs and credits symmetric), so
    trying both is unnecessary; the orientation of the input is irrelevant (it is made counter-clockwise)."""
    wolf0, wolf1 = wolf_pair
    contour, _ = silhouette_with_ground_truth(wolf0, resolution=200)
    base = solve("contour3d", contour, wolf1, n_contour=60, energy=energy)
    mirrored = solve("contour3d", Contour2D(contour.points * [-1.0, 1.0]), wolf1, n_contour=60, energy=energy)
    assert mirrored.energy == pytest.approx(base.energy, rel=1e-9)
    assert set(mirrored.path.vertices) == set(base.path.vertices)
    order = np.r_[0, np.arange(contour.n_points - 1, 0, -1)]  # clockwise, same first point
    reversed_ = solve("contour3d", Contour2D(contour.points[order]), wolf1, n_contour=60, energy=energy)
    assert reversed_.energy == base.energy and np.array_equal(reversed_.map_xy, base.map_xy)


def test_too_few_eigenpairs_is_a_named_error():
    """On a mesh as given (``mesh_vertices=0``); remeshed (the default), a coarse mesh is subdivided first."""
    t = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    circle = Contour2D(np.column_stack([np.cos(t), np.sin(t)]), name="tiny-circle")
    ico = trimesh.creation.icosphere(0)
    with pytest.raises(InputError, match="ico12: 12 vertices are too few for k=25"):
        solve("contour3d", circle, TriMesh(ico.vertices, ico.faces, name="ico12"), n_contour=40, mesh_vertices=0)
    sphere = trimesh.creation.icosphere(3)
    with pytest.raises(ContourError, match="tiny-circle: the filled silhouette has .* too few for k=25"):
        solve("contour3d", circle, TriMesh(sphere.vertices, sphere.faces), n_contour=10, mesh_vertices=0)
    # with fewer eigenpairs both are accepted
    result = solve("contour3d", circle, TriMesh(sphere.vertices, sphere.faces), n_contour=10, k=8, mesh_vertices=0)
    assert np.isfinite(result.energy)
    # the half-shape model needs about three times as many eigenpairs of the mesh as k
    small = trimesh.creation.icosphere(2)  # 162 vertices
    with pytest.raises(InputError, match=r"ico162: 162 vertices are too few for the 165 eigenpairs .*model='whole'"):
        solve("contour3d", circle, TriMesh(small.vertices, small.faces, name="ico162"), n_contour=40, k=55,
              model="half", mesh_vertices=0)
    # model=auto (the default) falls back to the whole model there
    fallback = solve("contour3d", circle, TriMesh(small.vertices, small.faces), n_contour=40, k=55, mesh_vertices=0)
    assert fallback.extras["model"] == "whole" and np.isfinite(fallback.energy)
    whole = solve("contour3d", circle, TriMesh(small.vertices, small.faces), n_contour=40, k=20, model="whole",
                  mesh_vertices=0)
    assert whole.extras["model"] == "whole" and np.isfinite(whole.energy)
    # an icosahedron stretched into an ellipsoid: a sphere's remeshed copy has near-repeated eigenvalues, whose
    # reflection searches every sign candidate (ten seconds for an answer that means nothing)
    ellipsoid = TriMesh(ico.vertices * [1.0, 0.8, 0.6], ico.faces, name="ico12")
    remeshed = solve("contour3d", circle, ellipsoid, n_contour=40, k=8)
    assert remeshed.extras["input_vertices"] == 12 and remeshed.extras["matched_vertices"] > 4900
    assert remeshed.map_xy.max() < 12 and np.isfinite(remeshed.energy)


@pytest.mark.slow
def test_elastic_energy_does_not_collapse_where_the_paper_energy_does():
    """The lion's main section matched back to the lion with the paper's Euclidean product metric: the paper's
    optimum runs over 6 vertices (coverage 0.17, mean error 0.49); the elastic optimum follows a curve of about
    the section's length (measured: coverage 0.98, 48 vertices, error 0.35). Both are global optima. The ratio
    energy (the paper's energy per contour length matched to a moving curve) gives no short curve either
    (measured: coverage 1.30) but, with these features, a curve running back and forth over 16 vertices at the
    paper's error (0.51): the ratio removes the reward for a short curve, not the features' ambiguity. (The
    elastic ratio, 27 s here, is checked against the explicit state graph in ``test_elastic_paths.py``.)"""
    from corrlib.contour_bench import cut_query, score_curve

    lion = load_mesh(SUMNER / "lion-00.off")
    query = cut_query(lion, "main")
    scores = {}
    for energy in ("paper", "elastic"):
        # the paper's node cost (no axis, no side-view terms), so that only the path energy differs
        result = solve("contour3d", query.contour, lion, n_contour=60, energy=energy, features="paper", axis_weight=0,
                       model="flat", view="front", metric="euclidean")
        assert result.search.optimal
        gt = query.ground_truth(result.path.contour_points, lion.vertices)
        scores[energy] = score_curve(result.map_xy, result.path.vertices, gt, lion, query.length_3d)
        assert energy in result.energy_meaning
    assert scores["paper"]["coverage"] < 0.3 and scores["paper"]["distinct_vertices"] < 20
    assert scores["elastic"]["coverage"] > 0.6 and scores["elastic"]["distinct_vertices"] > 40
    assert scores["elastic"]["mean_error"] < scores["paper"]["mean_error"] - 0.05
    result = solve("contour3d", query.contour, lion, n_contour=60, energy="ratio", features="paper",
                   axis_weight=0, model="flat", view="front", metric="euclidean")
    assert result.search.optimal and "per contour length" in result.energy_meaning
    gt = query.ground_truth(result.path.contour_points, lion.vertices)
    assert score_curve(result.map_xy, result.path.vertices, gt, lion, query.length_3d)["coverage"] > 0.9


def test_side_view_without_a_usable_reflection_goes_on_without_the_terms(monkeypatch, wolf_pair):
    """A mesh whose reflection gives no odd eigenfunction (or fixes every vertex) cannot carry the side-view
    terms: the match goes on without them and says so instead of failing."""
    import corrlib.methods.contour3d as c3

    def no_odd_function(spectrum, mirror):
        raise ParameterError("only 0 of 75 eigenfunctions are odd")

    monkeypatch.setattr(c3, "odd_eigenfunction", no_odd_function)
    wolf0, _ = wolf_pair
    from corrlib.contour_bench import cut_query

    result = solve("contour3d", cut_query(wolf0, "main").contour, wolf0, n_contour=40, view="side")
    assert result.extras["view"] == "front" and np.isfinite(result.energy)
    assert "side view" not in result.energy_meaning



def test_a_side_view_is_read_as_the_half_model_only():
    """An outline seen across the plane of symmetry is one half of the surface: with ``model=auto`` a side view
    searches the half model's readings alone (the whole model would be a front view's reading with the side
    view's terms); a front view still searches both. The outline is the bundled drawn wolf (a query of
    ``scripts/retrieval_set.py``), which the lion used to take through a whole-model reading."""
    from corrlib.io import load_contour
    from corrlib.methods.contour3d import _view_models
    from corrlib.resources import resource

    assert _view_models({"whole": 0, "half": 0}, True) == ["half"]
    assert _view_models({"whole": 0, "half": 0}, False) == ["whole", "half"]
    assert _view_models({"whole": 0}, True) == ["whole"]  # a mesh without the half model keeps the whole one
    drawn_wolf = load_contour(resource("data/silhouettes/drawn/wolf.txt"))
    lion = load_mesh(SUMNER / "lion-00.off")
    side = solve("contour3d", drawn_wolf, lion, n_contour=100)
    assert side.extras["view"] == "side" and side.extras["model"] == "half"
    whole = solve("contour3d", drawn_wolf, lion, n_contour=100, model="whole")
    assert whole.extras["model"] == "whole" and whole.energy < side.energy  # what auto took before
    front = solve("contour3d", drawn_wolf, lion, n_contour=100, view="front")
    front_whole = solve("contour3d", drawn_wolf, lion, n_contour=100, view="front", model="whole")
    # the front view's search includes the whole model's readings, in the same unit
    assert front.extras["view"] == "front" and front.energy <= front_whole.energy * (1 + 1e-12)


def test_a_mesh_too_small_for_a_spectrum_is_refused_by_name(tmp_path):
    """A tetrahedron was remeshed, matched, and the curve reported on its four vertices: every contour point
    on one vertex, and the studio's product view then failed to draw a curve without length."""
    from corrlib.methods.contour3d import match_prepared, prepare_query

    tetrahedron = TriMesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]),
                          np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]), name="tet.off")
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    blob = Contour2D(np.column_stack([np.cos(t) * (1 + 0.3 * np.cos(3 * t)), np.sin(t)]), name="blob")
    with pytest.raises(InputError, match="tet.off: a mesh of 4 vertices is too small for 2D-to-3D matching"):
        solve("contour3d", blob, tetrahedron)
    from corrlib.methods.contour3d import Contour3DParams

    params = Contour3DParams()
    with pytest.raises(InputError, match="too small for 2D-to-3D matching"):
        run(match_prepared(prepare_query(blob, params), tetrahedron, params, CancelToken()))


def test_the_curve_length_ratio_by_hand():
    """A closed path round a square of side 0.5 against an outline round a square of side 1: 2 / 4; a vertex
    repeated where the curve stays on it adds nothing."""
    from corrlib.methods.contour3d import curve_length_ratio

    corners = 0.5 * np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    outline = 4.0  # a unit square's perimeter
    assert curve_length_ratio(corners, np.array([0, 1, 2, 3]), outline) == pytest.approx(0.5)
    assert curve_length_ratio(corners, np.array([0, 0, 1, 2, 2, 2, 3, 0]), outline) == pytest.approx(0.5)
    assert curve_length_ratio(corners, np.array([0, 1]), outline) == pytest.approx(0.25)  # out and back


def test_a_short_matched_curve_is_reported_as_collapsed(capsys, tmp_path):
    """The MPEG-7 dog on the howling wolf1 is crowded onto a foreleg (a curve 0.4 of the outline's length); on
    the standing wolf0 it runs round the body (0.84) and nothing is said. Through the CLI
    the first is a warning."""
    from _data import SILHOUETTES
    from corrlib.cli import main
    from corrlib.io import load_contour
    from corrlib.methods.contour3d import SHORT_CURVE_RATIO, short_curve_note

    dog = load_contour(SILHOUETTES / "mpeg7" / "dog-1.gif")
    on_wolf0 = solve("contour3d", dog, load_mesh(TOSCA / "wolf0.off"))
    assert on_wolf0.extras["curve_length_ratio"] > 0.6 and short_curve_note(on_wolf0.extras) is None
    argv = ["match-contour", SILHOUETTES / "mpeg7" / "dog-1.gif", TOSCA / "wolf1.off", "-o", tmp_path / "r", "-q"]
    assert main(list(map(str, argv))) == 0
    err = capsys.readouterr().err
    assert "warning: the matched curve is 0." in err and "contour-views" in err
    assert short_curve_note({"curve_length_ratio": SHORT_CURVE_RATIO}) is None and short_curve_note({}) is None
    from corrlib.methods.contour3d import curve_collapsed

    assert curve_collapsed(0.49) and not curve_collapsed(SHORT_CURVE_RATIO)
    assert not curve_collapsed(float("nan")) and not curve_collapsed(None)  # not measured: not called collapsed
    # a ranking says it too, in its progress, in `corr retrieve`'s table (and in the studio's gallery)
    folder = tmp_path / "wolves"
    folder.mkdir()
    for name in ("wolf0.off", "wolf1.off"):
        (folder / name).write_bytes((TOSCA / name).read_bytes())
    assert main(["retrieve", str(SILHOUETTES / "mpeg7" / "dog-1.gif"), str(folder), "--jobs", "1"]) == 0
    out = capsys.readouterr()
    # a ranking matches as one match does: the dog collapses on wolf1 only (at the 100 points retrievals used
    # until the sixty-seventh session it collapsed on both wolves, 0.33 and 0.36 of its length)
    table = {("wolf1" if "wolf1.off" in line else "wolf0"): line for line in out.out.splitlines() if "wolf" in line}
    assert len(table) == 2 and table["wolf0"].endswith("wolf0.off"), out.out  # no note
    assert "wolf1.off  (the matched curve is 0.4" in table["wolf1"] and "probably collapsed" in table["wolf1"]
    assert out.err.count("probably collapsed") == 1  # in the progress lines too
