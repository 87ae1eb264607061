"""Geodesic distances, farthest-point sampling and Voronoi cells."""

import numpy as np
import pytest
import trimesh
from scipy.sparse.csgraph import dijkstra

from conftest import grid_mesh, pinched_spheres
from corrlib.errors import InputError, MeshError, ParameterError
from corrlib.geometry.geodesics import GeodesicSolver, geodesic_diameter
from corrlib.geometry.sampling import farthest_point_sampling, surface_farthest_points, voronoi_cells
from corrlib.shapes import TriMesh


@pytest.fixture(scope="module")
def plane():
    uv, faces = grid_mesh(30, 30)
    return TriMesh(np.column_stack([uv, np.zeros(len(uv))]), faces)


@pytest.fixture(scope="module")
def sphere():
    s = trimesh.creation.icosphere(subdivisions=4)
    return TriMesh(s.vertices / np.linalg.norm(s.vertices, axis=1, keepdims=True), s.faces)


def test_plane_distances_are_euclidean(plane):
    solver = GeodesicSolver(plane)
    rng = np.random.default_rng(0)
    a, b = rng.integers(0, plane.n_vertices, 40), rng.integers(0, plane.n_vertices, 40)
    euclid = np.linalg.norm(plane.vertices[a] - plane.vertices[b], axis=1)
    assert np.allclose(solver.pair_distances(a, b, "exact"), euclid, atol=1e-9)
    graph = solver.pair_distances(a, b, "graph")
    assert np.all(graph >= euclid - 1e-12)
    heat = solver.pair_distances(a, b, "heat")
    far = euclid > 0.2
    rel = np.abs(heat[far] - euclid[far]) / euclid[far]
    assert rel.max() < 0.12 and rel.mean() < 0.03  # the heat method is approximate (a few percent)


def test_distances_to_the_nearest_source_are_the_nearest_of_single_source_distances(plane):
    """One Dijkstra run from several sources equals the smallest of the single-source graph distances, is zero at
    the sources and never below the nearest Euclidean distance on a plane; a repeated source changes nothing,
    and a source outside the mesh is named."""
    solver = GeodesicSolver(plane)
    sources = np.array([5, 300, 777, 300])
    found = solver.distances_to_nearest(sources)
    assert np.allclose(found, solver.distances(sources, method="graph").min(axis=0))
    assert found.shape == (plane.n_vertices,) and np.all(found[sources] == 0.0)
    nearest = np.min(np.linalg.norm(plane.vertices[:, None, :] - plane.vertices[sources][None], axis=2), axis=1)
    assert np.all(found >= nearest - 1e-12)
    assert np.array_equal(found, solver.distances_to_nearest(np.unique(sources)))
    with pytest.raises(InputError):
        solver.distances_to_nearest([plane.n_vertices])


def test_graph_distances_are_computed_in_short_calls(plane, monkeypatch):
    """Many sources give scipy's Dijkstra, row for row, in the order asked; no call takes more than
    ``GRAPH_SOURCES_PER_CALL`` of them (each call holds the interpreter lock, which a studio's drawing needs)."""
    from corrlib.geometry import geodesics

    sources = np.random.default_rng(2).integers(0, plane.n_vertices, 3 * geodesics.GRAPH_SOURCES_PER_CALL + 5)
    expected = dijkstra(plane.adjacency, directed=False, indices=sources)
    calls = []

    def recording(graph, **kwargs):
        calls.append(len(kwargs["indices"]))
        return dijkstra(graph, **kwargs)

    monkeypatch.setattr(geodesics, "dijkstra", recording)
    got = GeodesicSolver(plane).distances(sources, method="graph")
    assert np.array_equal(got, expected)
    assert sum(calls) == sources.size and max(calls) <= geodesics.GRAPH_SOURCES_PER_CALL
    assert np.array_equal(GeodesicSolver(plane).distances(int(sources[0]), method="graph"), expected[0])


def test_exact_distances_on_a_pinched_vertex_are_refused_by_name():
    """geometry-central's edge flips refuse a vertex whose faces form separate fans: a named MeshError, not its
    RuntimeError; the heat and graph distances still pass through the pinch."""
    mesh, pinch = pinched_spheres()
    solver = GeodesicSolver(mesh)
    a, b = np.array([0, 5]), np.array([mesh.n_vertices - 1, mesh.n_vertices - 7])
    with pytest.raises(MeshError, match="pinched.off: no exact geodesics on this mesh .*not manifold"):
        solver.pair_distances(a, b, "exact")
    for method in ("heat", "graph"):
        across = solver.pair_distances(a, b, method)
        assert np.all(np.isfinite(across)) and np.all(across > 1.0)  # through the pinch, from sphere to sphere
    assert np.all(across <= solver.distances(pinch, "graph")[a] + solver.distances(pinch, "graph")[b] + 1e-9)


def test_sphere_great_circle(sphere):
    solver = GeodesicSolver(sphere)
    rng = np.random.default_rng(1)
    a, b = rng.integers(0, sphere.n_vertices, 30), rng.integers(0, sphere.n_vertices, 30)
    exact = np.arccos(np.clip(np.einsum("ij,ij->i", sphere.vertices[a], sphere.vertices[b]), -1, 1))
    got = solver.pair_distances(a, b, "exact")
    ok = exact < 2.5  # avoid near-antipodal pairs where the shortest path is not unique
    assert np.allclose(got[ok], exact[ok], rtol=0.01, atol=1e-3)
    d0 = solver.distances(0, method="heat")
    true0 = np.arccos(np.clip(sphere.vertices @ sphere.vertices[0], -1, 1))
    assert np.mean(np.abs(d0 - true0)) < 0.02
    assert geodesic_diameter(sphere) == pytest.approx(np.pi, rel=0.02)


def test_pair_distance_bookkeeping(plane):
    solver = GeodesicSolver(plane)
    d = solver.pair_distances(np.array([5, 7, 5, 9]), np.array([7, 5, 5, 9]))
    assert d[0] == pytest.approx(d[1]) and d[2] == 0 and d[3] == 0
    with pytest.raises(InputError, match="out of range"):
        solver.pair_distances(np.array([0]), np.array([plane.n_vertices]))
    with pytest.raises(ParameterError, match="unknown geodesic method"):
        solver.pair_distances(np.array([0]), np.array([1]), "magic")
    with pytest.raises(InputError, match="integer"):
        solver.distances(np.array([0.5]))


def test_farthest_point_sampling(wolf_pair):
    wolf = wolf_pair[0]
    samples = farthest_point_sampling(wolf.vertices, 200)
    assert np.unique(samples).size == 200 and samples[0] == 0
    # greedy property: each new sample is the farthest from the previous ones
    for i in (1, 50, 199):
        dist = np.min(np.linalg.norm(wolf.vertices[:, None] - wolf.vertices[samples[:i]][None], axis=2), axis=1)
        assert dist[samples[i]] == pytest.approx(dist.max())
    geo = farthest_point_sampling(wolf.vertices, 100, metric="geodesic", mesh=wolf)
    full = dijkstra(wolf.adjacency, directed=False, indices=geo[:60])
    cover = full.min(axis=0)
    assert cover[geo[60]] == pytest.approx(cover.max())
    with pytest.raises(ParameterError, match="cannot draw"):
        farthest_point_sampling(wolf.vertices, wolf.n_vertices + 1)
    with pytest.raises(InputError, match="needs the mesh"):
        farthest_point_sampling(wolf.vertices, 3, metric="geodesic")


def test_farthest_points_in_two_dimensions_equal_a_brute_force_greedy():
    points = np.random.default_rng(3).random((700, 2))
    samples = farthest_point_sampling(points, 120, start=5)
    cover = np.linalg.norm(points - points[5], axis=1)
    for i in range(1, 120):
        assert samples[i] == np.argmax(cover)  # first maximum, as np.argmax
        cover = np.minimum(cover, np.linalg.norm(points - points[samples[i]], axis=1))


def warped_square():
    """The unit square meshed with vertices crowded towards x = 0 (x = u³, 41 × 41 grid)."""
    uv, faces = grid_mesh(40, 40)
    return TriMesh(np.column_stack([uv[:, 0] ** 3, uv[:, 1], np.zeros(len(uv))]), faces, name="warped")


def test_surface_farthest_points_follow_the_area_not_the_vertices():
    mesh = warped_square()
    n = 1300  # 77 % of the vertices
    sample = surface_farthest_points(mesh, n)
    assert len(sample) == n and sample.points.shape == (n, 3)
    assert np.all(sample.barycentric >= 0) and np.allclose(sample.barycentric.sum(axis=1), 1)
    np.testing.assert_allclose(sample.interpolate(mesh, mesh.vertices), sample.points, atol=1e-12)
    corners = sample.nearest_corners(mesh)
    assert np.all(np.isin(corners, mesh.faces[sample.faces]))
    # 78 % of the vertices lie in the left half; a vertex sample of this size follows them (measured: 72 %),
    # the surface sample follows the area (52 %)
    vertex_sample = farthest_point_sampling(mesh.vertices, n)
    assert np.mean(mesh.vertices[vertex_sample, 0] < 0.5) > 0.65
    assert abs(np.mean(sample.points[:, 0] < 0.5) - 0.5) < 0.05
    # well spread: no two samples closer than half the spacing of a uniform sample, no point of the square
    # farther than 1.2 spacings from the sample
    spacing = np.sqrt(mesh.area / n)
    gaps = np.linalg.norm(sample.points[:, None] - sample.points[None], axis=2) + np.eye(n)
    assert gaps.min() > 0.5 * spacing
    probes = np.column_stack([np.random.default_rng(0).random((4000, 2)), np.zeros(4000)])
    assert np.linalg.norm(probes[:, None] - sample.points[None], axis=2).min(axis=1).max() < 1.2 * spacing


def test_surface_farthest_points_do_not_depend_on_the_element_order():
    mesh = warped_square()
    rng = np.random.default_rng(1)
    perm = rng.permutation(mesh.n_vertices)
    inv = np.argsort(perm)
    faces = inv[mesh.faces][rng.permutation(mesh.n_faces)]
    faces = np.roll(faces, 1, axis=1)  # other first corners, same orientation
    shuffled = TriMesh(mesh.vertices[perm], faces, name="shuffled")
    a, b = surface_farthest_points(mesh, 300), surface_farthest_points(shuffled, 300)
    np.testing.assert_allclose(a.points, b.points, atol=1e-9)
    np.testing.assert_allclose(b.interpolate(shuffled, shuffled.vertices[:, :2]), a.points[:, :2], atol=1e-9)
    with pytest.raises(ParameterError, match="positive integer"):
        surface_farthest_points(mesh, 0)
    with pytest.raises(ParameterError, match="oversample"):
        surface_farthest_points(mesh, 10, oversample=0.5)


def test_voronoi_cells_match_brute_force(wolf_pair):
    wolf = wolf_pair[0]
    seeds = farthest_point_sampling(wolf.vertices, 30)
    labels, dist = voronoi_cells(wolf, seeds)
    full = dijkstra(wolf.adjacency, directed=False, indices=seeds)
    assert np.allclose(dist, full.min(axis=0))
    assert np.allclose(full[labels, np.arange(wolf.n_vertices)], full.min(axis=0))
    assert np.array_equal(labels[seeds], np.arange(30))
    with pytest.raises(InputError, match="distinct"):
        voronoi_cells(wolf, [1, 1])


def test_astar_paths_equal_dijkstra_and_exact_equals_potpourri(wolf_pair):
    import potpourri3d as pp3d

    from corrlib.geometry.geodesics import _astar_paths

    mesh = wolf_pair[1]
    adj = mesh.adjacency
    rng = np.random.default_rng(4)
    a, b = rng.integers(0, mesh.n_vertices, 60), rng.integers(0, mesh.n_vertices, 60)
    lengths, offsets, flat = _astar_paths(mesh.vertices.astype(np.float64), adj.indptr.astype(np.int64),
                                          adj.indices.astype(np.int64), adj.data, a, b)
    # independent implementation: scipy's Dijkstra
    assert np.allclose(lengths, dijkstra(adj, directed=False, indices=a)[np.arange(60), b], rtol=1e-12)
    for i in range(60):  # each path is a chain of mesh edges from a to b whose edge lengths sum to its length
        path = flat[offsets[i]:offsets[i + 1]]
        assert path[0] == a[i] and path[-1] == b[i]
        steps = np.asarray(adj[path[:-1], path[1:]]).ravel()
        assert np.all(steps > 0) and steps.sum() == pytest.approx(lengths[i], rel=1e-12)
    flip = pp3d.EdgeFlipGeodesicSolver(mesh.vertices, mesh.faces)
    reference = np.array([0.0 if x == y else np.linalg.norm(np.diff(flip.find_geodesic_path(int(x), int(y)), axis=0),
                                                             axis=1).sum() for x, y in zip(a, b)])
    assert np.allclose(GeodesicSolver(mesh).pair_distances(a, b, "exact"), reference, rtol=1e-9)


def test_voronoi_bands_follow_their_definition(wolf_pair):
    from corrlib.geometry.sampling import voronoi_bands

    wolf = wolf_pair[0]
    seeds = farthest_point_sampling(wolf.vertices, 9)
    dist = dijkstra(wolf.adjacency, directed=False, indices=seeds)
    margin = 0.05 * np.sqrt(wolf.area)
    labels, members = voronoi_bands(wolf, seeds, margin)
    np.testing.assert_array_equal(labels, voronoi_cells(wolf, seeds)[0])
    for c in range(seeds.size):
        expected = np.flatnonzero(dist[c] <= dist.min(axis=0) + margin)
        np.testing.assert_array_equal(members[c], expected)
        assert np.all(np.isin(np.flatnonzero(labels == c), members[c]))  # a band contains its Voronoi cell
    assert sum(m.size for m in members) > wolf.n_vertices  # the cells overlap
    _, plain = voronoi_bands(wolf, seeds, 0.0)
    assert sum(m.size for m in plain) == wolf.n_vertices
    with pytest.raises(InputError, match="margin"):
        voronoi_bands(wolf, seeds, -1.0)


def test_distances_and_volume_of_a_mesh_far_from_the_origin(wolf_pair):
    """The same wolf moved by 1e9 (a shape of size ~100 in coordinates of a far-away scene): the exact and heat
    geodesics and the enclosed volume are those of the wolf at the origin (computed about its own centre, not
    lost to cancellation: at 1e7 the exact distances were 8 % off, the volume came out negative)."""
    from corrlib.geometry.geodesics import GeodesicSolver
    from corrlib.shapes import TriMesh, signed_volume

    wolf = wolf_pair[0]
    far = TriMesh(wolf.vertices + 1e9, wolf.faces, name="far-wolf")
    rng = np.random.default_rng(0)
    a, b = rng.integers(0, wolf.n_vertices, 50), rng.integers(0, wolf.n_vertices, 50)
    near_solver, far_solver = GeodesicSolver(wolf), GeodesicSolver(far)
    assert np.allclose(far_solver.pair_distances(a, b), near_solver.pair_distances(a, b), rtol=1e-6, atol=1e-6)
    assert np.allclose(far_solver.distances(a[:3]), near_solver.distances(a[:3]), rtol=1e-5, atol=1e-4)
    volume = signed_volume(wolf.vertices, wolf.faces)
    assert volume > 0 and np.isclose(signed_volume(far.vertices, far.faces), volume, rtol=1e-6)
