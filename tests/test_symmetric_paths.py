"""Sided closed curves of symmetric outlines: the outline's halves, the surface's curve of symmetry, forbidden
product nodes (brute force), the outline's reflection — against analytic cases."""

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh
from scipy.sparse.csgraph import dijkstra

from corrlib.descriptors.side_view import intrinsic_asymmetry, mirror_shift
from corrlib.errors import InputError
from corrlib.geometry.cyclic_paths import ProductGraph, branch_and_bound
from corrlib.geometry.symmetric_paths import outline_half, sided_cost, symmetry_curve_vertices
from corrlib.progress import run
from corrlib.shapes import Contour2D


@pytest.mark.parametrize("m", [8, 9, 200])
@pytest.mark.parametrize("shift", [0, 1, 5, 6])
def test_an_outline_half_runs_between_the_reflections_crossings(m, shift):
    half = outline_half(m, shift)
    points = np.arange(m)
    image = (shift - points) % m
    # every point is in the half or the mirror image of a point in it, and the half is one run of the outline
    assert np.all(half | half[image])
    assert np.count_nonzero(np.diff(half.astype(int), append=half[0])) == 2
    # fixed points of the reflection (2 i = shift mod m) are the half's ends
    fixed = np.flatnonzero((2 * points - shift) % m == 0)
    assert np.all(half[fixed])
    assert half.sum() <= m // 2 + 1
    with pytest.raises(InputError):
        outline_half(3, 0)


def sphere_edges(subdivisions=3):
    ico = trimesh.creation.icosphere(subdivisions=subdivisions)
    edges = ico.edges_unique
    adjacency = sp.coo_matrix((np.ones(len(edges)), tuple(edges.T)), shape=(len(ico.vertices),) * 2)
    return ico.vertices, edges, adjacency


def test_the_curve_of_symmetry_is_where_the_odd_function_changes_sign():
    """The reflection x -> -x of a sphere: odd function x; flagged vertices are exactly the ends of edges
    crossing x = 0 (or on it), so they lie within one edge of the plane and include every vertex on it."""
    vertices, edges, adjacency = sphere_edges()
    odd = vertices[:, 0].copy()
    odd[np.abs(odd) < 1e-12] = 0.0
    on_curve = symmetry_curve_vertices(adjacency, odd)
    crossing = np.sign(odd[edges[:, 0]]) != np.sign(odd[edges[:, 1]])
    expected = np.zeros(len(vertices), dtype=bool)
    expected[edges[crossing].ravel()] = True
    expected |= odd == 0
    assert np.array_equal(on_curve, expected)
    longest = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1).max()
    assert np.all(np.abs(vertices[on_curve, 0]) <= longest)
    assert on_curve[odd == 0].all() and on_curve.any()
    # the flagged vertices form one closed band round the sphere: connected along the mesh edges
    sub = sp.csr_matrix(adjacency)[on_curve][:, on_curve]
    n_parts = sp.csgraph.connected_components(sub, directed=False)[0]
    assert n_parts == 1


def test_the_sided_cost_forbids_the_wrong_half_for_each_half_of_the_outline():
    rng = np.random.default_rng(0)
    m, n = 10, 12
    cost = rng.random((m, n))
    odd = np.linspace(-1, 1, n)
    odd[5] = 0.0
    on_curve = np.abs(odd) < 0.2
    for sign in (1, -1):
        sided = sided_cost(cost, 4, odd, on_curve, sign)
        half = outline_half(m, 4)
        for i in range(m):
            allowed = on_curve | ((sign * odd > 0) if half[i] else (sign * odd < 0))
            assert np.array_equal(np.isfinite(sided[i]), allowed)
            assert np.array_equal(sided[i, allowed], cost[i, allowed])
    with pytest.raises(InputError):
        sided_cost(cost, 4, odd[:5], on_curve, 1)
    with pytest.raises(InputError):
        sided_cost(cost, 4, odd, on_curve, 0.5)


def explicit_optimum_with_forbidden_nodes(graph: ProductGraph) -> float:
    """min over s of d((0, s), (m, s)) on the explicit product graph, an edge at a forbidden node dropped."""
    m, n = graph.m, graph.n
    adj = graph.adjacency.tocoo()
    rows, cols, w = [], [], []
    for i in range(m + 1):
        for j, k, length in zip(adj.row, adj.col, adj.data):
            rows.append(i * n + j), cols.append(i * n + k)
            w.append(0.5 * (graph.cost[i, j] + graph.cost[i, k]) * length)
            if i < m:
                a = np.sqrt(graph.step2[i])
                rows.append(i * n + j), cols.append((i + 1) * n + k)
                w.append(0.5 * (graph.cost[i, j] + graph.cost[i + 1, k]) * max(length, a))
        if i < m:
            for j in range(n):
                rows.append(i * n + j), cols.append((i + 1) * n + j)
                w.append(0.5 * (graph.cost[i, j] + graph.cost[i + 1, j]) * np.sqrt(graph.step2[i]))
    rows, cols, w = np.array(rows), np.array(cols), np.array(w)
    keep = np.isfinite(w)
    product = sp.coo_matrix((w[keep], (rows[keep], cols[keep])), shape=((m + 1) * n,) * 2).tocsr()
    dist = dijkstra(product, directed=True, indices=np.arange(n))
    return float(min(dist[s, m * n + s] for s in range(n)))


@pytest.mark.parametrize("seed", range(5))
def test_branch_and_bound_with_forbidden_nodes_equals_brute_force(seed):
    """inf node costs forbid nodes: the search's optimum is the brute-force optimum of the product graph
    without them, its path avoids them, and a sided cost on a sphere gives a curve whose halves keep to their
    halves of the sphere."""
    rng = np.random.default_rng(seed)
    vertices, _, adjacency = sphere_edges(1)
    m = 8
    t = np.linspace(0, 2 * np.pi, m, endpoint=False)
    curve = np.column_stack([np.cos(t), 0.6 * np.sin(t)])
    cost = rng.random((m, len(vertices))) ** 2
    odd = vertices[:, 0] + 1e-3 * rng.standard_normal(len(vertices))
    on_curve = symmetry_curve_vertices(adjacency, odd)
    for sign in (1, -1):
        sided = sided_cost(cost, 2, odd, on_curve, sign)
        graph = ProductGraph(sided, curve, vertices, adjacency, metric="max")
        result = run(branch_and_bound(graph))
        assert result.energy == pytest.approx(explicit_optimum_with_forbidden_nodes(graph), rel=1e-12)
        assert result.lower_bound == pytest.approx(result.energy, rel=1e-12)
        assert graph.path_energy(result.path) == pytest.approx(result.energy, rel=1e-12)
        assert np.all(np.isfinite(graph.cost[result.path.layers, result.path.vertices]))
        half = outline_half(m, 2)
        layer_points = result.path.layers % m
        first, second = half[layer_points], ~half[layer_points]
        assert np.all((sign * odd[result.path.vertices[first]] > 0) | on_curve[result.path.vertices[first]])
        assert np.all((sign * odd[result.path.vertices[second]] < 0) | on_curve[result.path.vertices[second]])
    with pytest.raises(InputError):
        ProductGraph(np.full((m, len(vertices)), np.inf), curve, vertices, adjacency)
    with pytest.raises(InputError):
        ProductGraph(np.where(cost > 0.5, np.nan, cost), curve, vertices, adjacency)


def test_mirror_shift_finds_the_reflection_of_a_symmetric_outline_wherever_it_starts():
    """An outline symmetric about the x axis, evenly resampled so that point 0 is on the axis: the reflection
    pairs i with -i, and starting the outline k points later shifts it to -2k (mod m)."""
    corners = np.array([[3, 0], [1, 1], [-2, 1.5], [-3, 0.4], [-3, -0.4], [-2, -1.5], [1, -1]], dtype=float)
    outline = Contour2D(corners, validate=False).resample(120).points
    m = len(outline)
    for k in (0, 7, 30, 61):
        points = np.roll(outline, -k, axis=0)
        features = np.column_stack([points[:, 0], np.abs(points[:, 1])])
        assert mirror_shift(features) == (-2 * k) % m
        assert intrinsic_asymmetry(features) < 1e-9


def top_view_match(mesh, query, **params):
    from corrlib.methods import solve

    return solve("contour3d", query.contour, mesh, model="whole", front_curve="sided", **params)


@pytest.mark.slow
def test_a_sided_top_view_keeps_its_halves_on_the_two_flanks_of_a_cat():
    """cat0 seen from above, matched to cat0 and to a mirrored, vertex-shuffled copy as the whole surface with
    sided curves: every matched step of the outline's first half lies on the half of the surface the result
    names (or next to the curve of symmetry) and every step of the second half on the other, the energy is
    the global optimum, and the matched curve follows the rim (mean error <= 0.1; the free closed curve runs
    down one flank and back up the same flank, 0.13)."""
    from _data import TOSCA
    from corrlib.contour_bench import silhouette_query
    from corrlib.geometry.geodesics import GeodesicSolver
    from corrlib.io import load_mesh
    from corrlib.methods.contour3d import Contour3DParams, mesh_symmetry, prepare_query
    from corrlib.shapes import TriMesh

    cat = load_mesh(TOSCA / "cat0.off")
    query = silhouette_query(cat, view="top")
    perm = np.random.default_rng(5).permutation(cat.n_vertices)
    inverse = np.argsort(perm)
    mirrored = TriMesh(cat.vertices[perm] * [-1.0, 1.0, 1.0], inverse[cat.faces][:, ::-1], name="mirrored")
    params = Contour3DParams(model="whole", front_curve="sided")
    shift = prepare_query(query.contour, params).reflection_shift
    energies = []
    for target, to_target in ((cat, np.arange(cat.n_vertices)), (mirrored, inverse)):
        result = top_view_match(target, query, mesh_vertices=0)  # as given: the halves are the target's
        assert result.extras["sided"] and result.search.optimal
        energies.append(result.energy)
        halves = mesh_symmetry(target, params)
        sign = result.extras["near_half"]
        first = outline_half(len(result.map_xy), shift)[result.path.contour_index]
        side = sign * halves.odd[result.path.vertices]
        on_curve = halves.on_curve[result.path.vertices]
        assert np.all((side[first] >= 0) | on_curve[first]) and np.all((side[~first] <= 0) | on_curve[~first])
        assert (side[first] > 0).mean() > 0.5 and (side[~first] < 0).mean() > 0.5
        truth = to_target[query.ground_truth(result.path.contour_points, cat.vertices)]  # near and far rim
        solver = GeodesicSolver(target)
        errors = np.min([solver.pair_distances(result.map_xy, column) for column in truth.T], axis=0)
        errors /= np.sqrt(target.area)
        assert errors.mean() <= 0.1, errors.mean()
    assert energies[1] == pytest.approx(energies[0], rel=1e-3)
